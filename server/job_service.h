// The job service behind the API, free of any transport: uploads, job creation and queries,
// cancellation, watching and results, on top of a JobStore and a BlobStore. The gRPC adapter
// (grpc_reconstruction_service.h) only converts protos and forwards here; tests drive it
// directly. Jobs are never run here: CreateJob queues, the WorkerPool runs.
//
// Thread-safe: every call may come from any RPC thread at once.
#pragma once

#include <spdlog/logger.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <shared_mutex>
#include <string>
#include <unordered_set>
#include <vector>

#include "core/inverse/job_resources.h"
#include "server/caller.h"
#include "server/capture_upload.h"
#include "server/job_events.h"
#include "server/job_reports.h"
#include "server/metrics.h"
#include "server/rate_limiter.h"
#include "server/service_status.h"
#include "server/store/blob_store.h"
#include "server/store/job_store.h"

namespace softid::server {

// What one station may use; every limit is answered RESOURCE_EXHAUSTED naming it. Admin tokens
// and the operator of a server without authentication are not limited (the server-wide bounds
// still hold: max_queued_jobs, upload_limits).
struct StationQuotas {
  int64_t max_queued_jobs = 100;                 // its jobs QUEUED at once
  int64_t max_stored_bytes = int64_t{64} << 30;  // bytes of its stored captures
  int max_concurrent_uploads = 4;                // its uploads in progress at once
  double requests_per_second = 50.0;             // sustained call rate; <= 0: unlimited
  double request_burst = 200.0;                  // calls it may make at once
};

struct JobServiceOptions {
  // CreateJob answers RESOURCE_EXHAUSTED once this many jobs are QUEUED: a bound on the work
  // accepted but not started, so a flood of submissions cannot grow the queue without limit.
  int64_t max_queued_jobs = 1000;  // >= 1
  UploadLimits upload_limits;
  // Uploads are staged here (removed on start); must be on the file system of the blobs.
  std::filesystem::path staging_root;
  // How often a watcher re-reads the history without a notification (changes made by another
  // process sharing the database).
  std::chrono::milliseconds watch_poll_interval{1000};
  // Called after a job was queued (wakes an idle worker); may be empty.
  std::function<void()> on_job_queued;
  // CreateJob reads the capture's size here (scratch, inside the data directory) and refuses a
  // job whose estimated needs exceed `job_limits` (inverse::EstimateJobResources).
  std::filesystem::path scratch_root;
  inverse::JobResourceLimits job_limits;
  StationQuotas quotas;
  // Where uploads are counted; may be null.
  Metrics* metrics = nullptr;
  // Held shared from a capture's first blob put to its commit and exclusive while unreferenced
  // blobs are removed; shared with the workers, which store the captures they ingest. Null: the
  // service's own (nothing else puts blobs).
  std::shared_mutex* blob_puts = nullptr;
  // The finished jobs' reports (served by DownloadArtifact, removed with their jobs); null: none.
  const JobReports* reports = nullptr;
};

// What GetResult returns.
struct JobResult {
  std::string job_id;
  nlohmann::json result;                     // result.json
  std::vector<double> cost_history;          // result["cost_history"]
  std::vector<int> cost_history_last_frame;  // result["cost_history_last_frame"]
  // result["ingest"] (the ingest report of a job on a recording); null otherwise.
  nlohmann::json ingest;
  std::vector<ReportFile> artifacts;  // the files of the job's report
};

class JobService {
 public:
  // The stores and `events` must outlive the service. `logger` null means spdlog's default.
  JobService(store::JobStore* jobs, const store::BlobStore* blobs, JobEvents* events,
             JobServiceOptions options, std::shared_ptr<spdlog::logger> logger = nullptr);

  // Uploads: Begin checks the manifest; the caller feeds chunks to the returned upload, then
  // FinishUpload validates the whole capture and stores it (blobs first, then the row).
  // ResourceExhausted while upload_limits.max_concurrent uploads are in progress (an upload
  // counts until its object is destroyed).
  // Every call acts for `caller` (caller.h): what it creates is owned by caller.station, and a
  // capture or job another station owns is NotFound to it, like one that does not exist.
  ServiceResult<std::unique_ptr<CaptureUpload>> BeginUpload(const Caller& caller,
                                                            UploadManifest manifest);
  // Files the upload declared but whose bytes did not come are taken from the blobs of the
  // caller's captures (FindCaptureFiles) before the upload is validated.
  ServiceResult<store::Capture> FinishUpload(const Caller& caller, CaptureUpload& upload);
  // The hashes among `sha256s` that files of the caller's captures have (all captures for an
  // admin). InvalidArgument for more than upload_limits.max_files hashes.
  ServiceResult<std::vector<std::string>> FindCaptureFiles(const Caller& caller,
                                                           const std::vector<std::string>& sha256s);

  // `config_json` empty means "{}". InvalidArgument "config_json: <field> = <value>: <reason>",
  // also for a config that does not fit the capture (frames past its end) or would exceed the
  // job limits ("config_json: cells = 300: the job would need about 41 GiB ...");
  // NotFound for an unknown capture; ResourceExhausted when the queue is full; Unavailable while
  // draining; AlreadyExists for a request_id used before with other arguments.
  ServiceResult<store::Job> CreateJob(const Caller& caller, const std::string& capture_id,
                                      const std::string& config_json,
                                      const std::string& request_id);
  ServiceResult<store::Job> GetJob(const Caller& caller, const std::string& job_id);
  // A station lists its own jobs only (request.owner is set to it); admins list every job.
  ServiceResult<store::JobPage> ListJobs(const Caller& caller, store::ListJobsRequest request);
  // The caller's captures (all for an admin).
  ServiceResult<store::CapturePage> ListCaptures(const Caller& caller,
                                                 store::ListCapturesRequest request);
  ServiceResult<store::Job> CancelJob(const Caller& caller, const std::string& job_id);
  ServiceStatus DeleteJob(const Caller& caller, const std::string& job_id);
  // FailedPrecondition naming the state unless the job SUCCEEDED.
  ServiceResult<JobResult> GetResult(const Caller& caller, const std::string& job_id);

  // Calls `send` for every event of the job's history with iteration >= from_iteration, then for
  // every new one, until the job is terminal and its last event was sent (OK), `send` returns
  // false or `stop` returns true (Cancelled), or the service is draining (Unavailable).
  using EventSink = std::function<bool(const store::ProgressEvent& event, const store::Job& job)>;
  ServiceStatus WatchJob(const Caller& caller, const std::string& job_id, int from_iteration,
                         const EventSink& send, const std::function<bool()>& stop);

  // The caller's capture with its manifest, then each file's bytes in chunks of at most
  // upload_limits.max_chunk_bytes, file by file in manifest order, until done (OK) or a sink
  // returns false (Cancelled). NotFound for another station's capture, like a missing one;
  // Internal when a blob of it is missing (a damaged data directory).
  using CaptureSink = std::function<bool(const store::Capture& capture)>;
  using ChunkSink =
      std::function<bool(const std::string& path, int64_t offset_bytes, std::string_view data)>;
  ServiceStatus DownloadCapture(const Caller& caller, const std::string& capture_id,
                                const CaptureSink& send_capture, const ChunkSink& send_chunk);

  // The bytes of file `name` of a SUCCEEDED job's report (JobResult::artifacts) in chunks of at
  // most upload_limits.max_chunk_bytes, until done (OK) or `send_chunk` returns false
  // (Cancelled). NotFound for a name the job's report does not list (or another station's job);
  // FailedPrecondition unless the job SUCCEEDED.
  ServiceStatus DownloadArtifact(const Caller& caller, const std::string& job_id,
                                 const std::string& name, const ChunkSink& send_chunk);

  // Counts a call against the caller's request rate: ResourceExhausted when it is over.
  ServiceStatus Admit(const Caller& caller);
  // Deletes a capture of the caller's that no job uses, with the blobs no other capture lists.
  // FailedPrecondition naming a job that still uses it.
  ServiceStatus DeleteCapture(const Caller& caller, const std::string& capture_id);

  // Deletes jobs that ended more than `age` ago, then captures older than that which no job uses
  // (with their unshared files). Returns how many jobs and captures went.
  ServiceResult<std::pair<int, int>> RemoveOlderThan(std::chrono::seconds age);

  // Refuse new jobs and end watches (shutdown).
  void StartDraining();
  bool draining() const { return draining_.load(); }

 private:
  // OK when `config` fits the capture's frames and the job limits (see CreateJob).
  // The job if `caller` may see it; NotFound (as for a missing job) otherwise.
  ServiceResult<store::Job> VisibleJob(const Caller& caller, const std::string& job_id);
  ServiceStatus CheckJobFitsCapture(const Caller& caller, const inverse::JobConfig& config,
                                    const std::string& capture_id, const std::string& request_id);
  // The sha256 of every file of the caller's captures (all captures for an admin).
  ServiceResult<std::unordered_set<std::string>> HeldFiles(const Caller& caller);
  // Feeds the upload the files it declared but was sent nothing of, from the blobs of the
  // caller's captures that hold them.
  ServiceStatus AddHeldFiles(const Caller& caller, CaptureUpload& upload);
  // After a failed upload: deletes those of `sha256s` that no capture refers to.
  void RemoveUnreferencedBlobs(const std::vector<std::string>& sha256s);

  store::JobStore* jobs_;
  const store::BlobStore* blobs_;
  JobEvents* events_;
  JobServiceOptions options_;
  std::shared_ptr<spdlog::logger> logger_;
  std::atomic<bool> draining_{false};
  std::atomic<int> uploads_in_progress_{0};
  RateLimiter rate_limiter_;
  // Per station: uploads in progress, and a lock that orders its quota checks with the commits
  // they guard (so concurrent calls of one station cannot overshoot a quota together).
  struct StationState {
    int uploads = 0;
    std::mutex quota;
  };
  StationState& Station(const std::string& station);
  ServiceStatus CheckStoredBytes(const Caller& caller, int64_t adding);
  std::mutex stations_mutex_;
  std::map<std::string, std::unique_ptr<StationState>> stations_;
  // Shared from an upload's first blob put to its commit; exclusive while a failed upload removes
  // its blobs (RemoveUnreferencedBlobs). options_.blob_puts when given, else own_blob_puts_.
  std::shared_mutex own_blob_puts_;
  std::shared_mutex& blob_puts_;
};

}  // namespace softid::server
