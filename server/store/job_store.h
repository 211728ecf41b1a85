// The durable job store's contract: captures, jobs, their progress history and checkpoints.
// Two implementations pass the same conformance tests (tests/server/job_store_conformance_test.cc):
// SqliteJobStore, the embedded single-node default (a file under --data), and PostgresJobStore,
// a PostgreSQL database several servers can share (--store postgresql://..., claiming with
// SELECT ... FOR UPDATE SKIP LOCKED). open_store.h picks one from the server's flags.
//
// Contract shared by every implementation:
//  - Every call is atomic: it commits entirely or not at all. Every state transition is checked
//    against the job's current state inside that transaction (see job.h for the life cycle); an
//    illegal one fails with FailedPrecondition naming the job and its state.
//  - Ids are random (resource_id.h). A malformed id is InvalidArgument, an unknown one NotFound.
//  - `request_id` makes creation idempotent: repeating a create with the same request_id returns
//    the resource created the first time; reusing it with different arguments fails with
//    FailedPrecondition (the API layer reports it as ALREADY_EXISTS). An empty request_id means
//    none.
//  - Safe to call from several threads; calls may block while another process holds the lock.
//  - Timestamps (created_at, leases, ...) come from the store's injected clock, never from the
//    database server's, so that tests can step time and both implementations agree.
#pragma once

#include <chrono>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/common/status.h"
#include "server/store/capture.h"
#include "server/store/job.h"
#include "server/store/progress_event.h"
#include "server/store/start_task.h"

namespace softid::server::store {

struct ListJobsRequest {
  static constexpr int kDefaultPageSize = 50;
  static constexpr int kMaxPageSize = 1000;

  std::optional<JobState> state = std::nullopt;     // only jobs in this state; all when empty
  std::optional<std::string> owner = std::nullopt;  // only this station's jobs; all when empty
  // 0 means kDefaultPageSize; larger than kMaxPageSize is lowered to it (AIP-158); negative is
  // InvalidArgument.
  int page_size = 0;
  std::string page_token =
      "";  // empty for the first page; else a next_page_token from the last call
};

struct ListCapturesRequest {
  std::optional<std::string> owner = std::nullopt;  // only this station's captures; all when empty
  // As ListJobsRequest: 0 means the default, larger is lowered to the maximum, negative is
  // InvalidArgument.
  int page_size = 0;
  std::string page_token = "";  // empty for the first page; else a next_page_token
};

// A capture as a list shows it: with the number of jobs that use it (it can be deleted at 0).
struct CaptureListing {
  Capture capture;
  int64_t num_jobs = 0;
};

// Captures in creation order (created_at, then id).
struct CapturePage {
  std::vector<CaptureListing> captures;
  std::string next_page_token;  // empty on the last page
};

// Jobs in creation order (created_at, then id).
struct JobPage {
  std::vector<Job> jobs;
  std::string next_page_token;  // empty when this is the last page
};

// Which RUNNING jobs RecoverAfterCrash treats as lost.
enum class RecoveryScope {
  // Every RUNNING job. Right at start-up of a single-node server: no worker of this process is
  // running yet, so nothing can still be working on them.
  kAllRunning,
  // Only RUNNING jobs whose lease expired. Right for a periodic sweep, or at start-up when several
  // nodes share the store and other nodes' workers may still be running.
  kExpiredLeasesOnly,
};

struct RecoverySummary {
  int num_requeued = 0;   // back to QUEUED for another attempt
  int num_failed = 0;     // FAILED: they had used up max_attempts
  int num_cancelled = 0;  // CANCELLED: a cancel had been requested before the worker was lost

  int total() const { return num_requeued + num_failed + num_cancelled; }
};

class JobStore {
 public:
  virtual ~JobStore() = default;

  // --- Captures -----------------------------------------------------------------------------

  // Records an uploaded capture whose blobs are already stored (BlobStore::Put returned).
  // InvalidArgument for an invalid manifest (see ValidateManifest).
  // `owner` is the uploading station (empty without authentication). Request ids are per
  // station: another station's use of the same id is unrelated and invisible. `format` is
  // kCaptureFormat or kRecordingFormat (InvalidArgument otherwise).
  virtual Result<Capture> CreateCapture(const std::vector<ManifestEntry>& manifest,
                                        const std::string& request_id,
                                        const std::string& owner = "",
                                        std::string_view format = kCaptureFormat) = 0;
  virtual Result<Capture> GetCapture(const std::string& capture_id) = 0;
  // Deletes a capture no job refers to and returns it (its blobs are the caller's to remove
  // when no other capture lists them). FailedPrecondition naming a job that uses it: as its
  // capture, or as the capture its ingest derived (Job::derived_capture_id).
  virtual Result<Capture> DeleteCapture(const std::string& capture_id) = 0;
  // Captures in creation order, each with its number of jobs (derived ones count); paginated
  // like ListJobs.
  virtual Result<CapturePage> ListCaptures(const ListCapturesRequest& request) = 0;
  // Captures created before `created_before` that no job refers to (retention).
  virtual Result<std::vector<std::string>> ListUnusedCaptures(Timestamp created_before) = 0;
  // Jobs in a terminal state that ended before `finished_before` (retention).
  virtual Result<std::vector<std::string>> ListEndedJobs(Timestamp finished_before) = 0;
  // Bytes of every file of the captures `owner` uploaded (as their manifests declare).
  virtual Result<int64_t> StoredBytes(const std::string& owner) = 0;

  // --- Jobs: API side -------------------------------------------------------------------------

  // A new QUEUED job. NotFound naming the capture if it does not exist; InvalidArgument unless
  // `config` is a JSON object.
  virtual Result<Job> CreateJob(const std::string& capture_id, const nlohmann::json& config,
                                const std::string& request_id, const std::string& owner = "") = 0;
  // CreateJob with a bound on the queue, checked in the same transaction as the insert so that
  // concurrent creates cannot overshoot it: nullopt (and nothing created) when `max_queued`
  // (>= 1) jobs are QUEUED already. A repeated request_id returns its job even then, and an
  // unknown capture is NotFound before the queue is looked at.
  virtual Result<std::optional<Job>> CreateJobBounded(const std::string& capture_id,
                                                      const nlohmann::json& config,
                                                      const std::string& request_id,
                                                      int64_t max_queued,
                                                      const std::string& owner = "") = 0;
  virtual Result<Job> GetJob(const std::string& job_id) = 0;
  // Whether `owner` created a job with `request_id` (non-empty).
  virtual Result<bool> HasJobWithRequestId(const std::string& request_id,
                                           const std::string& owner) = 0;
  virtual Result<JobPage> ListJobs(const ListJobsRequest& request) = 0;
  // Jobs in `state`, or all jobs (of `owner` only, when given); used to bound the queue.
  virtual Result<int64_t> CountJobs(std::optional<JobState> state,
                                    std::optional<std::string> owner = std::nullopt) = 0;
  // QUEUED: CANCELLED at once. RUNNING: sets cancel_requested (the worker stops at its next check
  // and calls MarkCancelled); repeating it is harmless. Terminal: FailedPrecondition.
  // Returns the job after the change.
  virtual Result<Job> RequestCancel(const std::string& job_id) = 0;
  // Deletes the job with its progress and checkpoint. FailedPrecondition while RUNNING (cancel it
  // first). Captures are kept: other jobs may use them.
  virtual Status DeleteJob(const std::string& job_id) = 0;

  // --- Jobs: worker side ----------------------------------------------------------------------

  // Atomically moves the oldest QUEUED job to RUNNING for `worker_id`: attempts + 1, started_at =
  // now, lease until now + `lease`. Two workers never claim the same job. Returns nullopt when no
  // job is queued.
  virtual Result<std::optional<Job>> ClaimNextJob(const std::string& worker_id,
                                                  std::chrono::milliseconds lease) = 0;
  // Extends the lease to now + `lease`. FailedPrecondition when the job is no longer RUNNING or is
  // leased to another worker: the caller has lost the job and must stop working on it.
  virtual Status RenewLease(const std::string& job_id, const std::string& worker_id,
                            std::chrono::milliseconds lease) = 0;
  // Appends to the job's history and returns the event's seq. Iteration events only while
  // RUNNING (FailedPrecondition otherwise); fields the store assigns are ignored (see
  // ProgressEvent).
  virtual Result<int64_t> AppendProgress(const std::string& job_id, const ProgressEvent& event) = 0;
  // Events with iteration >= from_iteration, in the order they were written.
  virtual Result<std::vector<ProgressEvent>> ListProgress(const std::string& job_id,
                                                          int from_iteration) = 0;
  // Replaces the job's checkpoint (whatever the worker needs to resume). Only while RUNNING.
  virtual Status SaveCheckpoint(const std::string& job_id, const nlohmann::json& checkpoint) = 0;
  // The last checkpoint saved, or nullopt when none was.
  virtual Result<std::optional<nlohmann::json>> LoadCheckpoint(const std::string& job_id) = 0;
  // Records the capture a RUNNING job's ingest derived from its recording (the capture exists).
  // FailedPrecondition when the job is not RUNNING or not leased to `worker_id`; NotFound for an
  // unknown capture.
  virtual Status SetDerivedCapture(const std::string& job_id, const std::string& worker_id,
                                   const std::string& capture_id) = 0;
  // RUNNING -> SUCCEEDED with `result`.
  virtual Status CompleteJob(const std::string& job_id, const nlohmann::json& result) = 0;
  // RUNNING -> FAILED with `error` (a failed optimisation, a bad capture, ...).
  virtual Status FailJob(const std::string& job_id, const std::string& error) = 0;
  // True when the worker should stop: a cancel was requested, or the job is already CANCELLED.
  virtual Result<bool> IsCancelRequested(const std::string& job_id) = 0;
  // RUNNING with cancel_requested -> CANCELLED: the worker acknowledges the cancel.
  virtual Status MarkCancelled(const std::string& job_id) = 0;
  // RUNNING (leased to `worker_id`) -> QUEUED, recording `reason` in the history: the worker
  // gives the job back unfinished (a graceful shutdown). The claim stays in `attempts` but also
  // counts in `released_attempts`, so it is not held against max_attempts. With a cancel pending
  // the job becomes CANCELLED instead. FailedPrecondition when the worker no longer holds it.
  virtual Status ReleaseJob(const std::string& job_id, const std::string& worker_id,
                            const std::string& reason) = 0;

  // --- Start tasks (fan-out of a job's starts; start_task.h) -----------------------------------

  // Splits the RUNNING job leased to `worker_id` into QUEUED tasks 0 .. num_tasks - 1 (>= 1).
  // Idempotent: tasks an earlier attempt made are kept as they are (FailedPrecondition when
  // their number differs). FailedPrecondition when the job is not RUNNING or leased to another.
  virtual Status CreateStartTasks(const std::string& job_id, const std::string& worker_id,
                                  int num_tasks) = 0;
  // Adds a batch of tasks named `batch` (CheckBatchName), one per input (>= 1; each task's
  // `input`), to the RUNNING job leased to `worker_id`, at the indexes after the job's existing
  // tasks; returns the first. Idempotent: a batch of that name made before is kept as it is and
  // its first index returned (FailedPrecondition when its size differs). FailedPrecondition when
  // the job is not RUNNING or leased to another.
  virtual Result<int> CreateTaskBatch(const std::string& job_id, const std::string& worker_id,
                                      const std::string& batch,
                                      const std::vector<nlohmann::json>& inputs) = 0;
  // Atomically takes the first claimable task for `worker_id`: a QUEUED one, or a RUNNING one
  // whose lease expired (its worker was lost); attempts + 1, lease until now + `lease`. Only
  // tasks of RUNNING jobs without a cancel request; of `job_id` only when it is not empty, else
  // the oldest job's first. Two workers never hold the same task. nullopt when none is claimable.
  virtual Result<std::optional<StartTask>> ClaimStartTask(const std::string& worker_id,
                                                          std::chrono::milliseconds lease,
                                                          const std::string& job_id = "") = 0;
  // Extends the task's lease. FailedPrecondition when `worker_id` no longer holds it, or its job
  // ended or has a cancel request: the worker stops. (A job requeued meanwhile keeps its tasks
  // running: the next attempt uses their results.)
  virtual Status RenewStartTask(const std::string& job_id, int index, const std::string& worker_id,
                                std::chrono::milliseconds lease) = 0;
  // RUNNING (held by `worker_id`) -> DONE with `result`; FailedPrecondition otherwise, or when
  // the job ended.
  virtual Status CompleteStartTask(const std::string& job_id, int index,
                                   const std::string& worker_id, const nlohmann::json& result) = 0;
  // RUNNING (held by `worker_id`) -> QUEUED: the worker gives it back unfinished (a shutdown).
  virtual Status ReleaseStartTask(const std::string& job_id, int index,
                                  const std::string& worker_id) = 0;
  // The job's tasks of every batch by index (none when it was not split). NotFound for an
  // unknown job.
  virtual Result<std::vector<StartTask>> ListStartTasks(const std::string& job_id) = 0;

  // --- Maintenance --------------------------------------------------------------------------

  // Jobs left RUNNING by lost workers (see RecoveryScope) go back to QUEUED, or to FAILED with an
  // error saying so once they were claimed `max_attempts` times (>= 1; released claims do not
  // count), or to CANCELLED if a cancel was pending.
  virtual Result<RecoverySummary> RecoverAfterCrash(int max_attempts, RecoveryScope scope) = 0;

  // True when some capture's manifest lists a file with this sha256: the blob must be kept. Used
  // to remove the blobs of an upload that failed after they were stored.
  virtual Result<bool> IsBlobReferenced(const std::string& sha256) = 0;
  // The sha256 of every file some capture lists, in one pass (the start-up sweep of orphans).
  virtual Result<std::vector<std::string>> ListReferencedBlobs() = 0;

  // Releases the connection(s). Later calls fail with FailedPrecondition. Idempotent.
  virtual Status Close() = 0;
};

}  // namespace softid::server::store
