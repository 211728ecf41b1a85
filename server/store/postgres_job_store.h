// The JobStore on a PostgreSQL server, for several softid-server processes (on several hosts)
// sharing one queue: captures, jobs, progress, checkpoints and API tokens in the database named by
// a postgresql:// URL; schema in postgres_schema.cc. Same contract as SqliteJobStore (the
// conformance suite in tests/server/job_store_conformance_test.cc runs against both).
//
// Concurrency: a small pool of connections (PostgresJobStoreOptions::max_connections), one per
// call in flight, so that one process's workers, heartbeats and API calls do not queue behind each
// other's round trips, and so that the database, not a mutex of ours, decides what may run at
// once: the same rules then hold between threads and between processes. Write transactions run at
// READ COMMITTED and take explicit locks:
//  - a claim takes the oldest QUEUED job with SELECT ... FOR UPDATE SKIP LOCKED, so concurrent
//    claimers take different jobs without waiting for each other;
//  - every change to a job first locks its row (SELECT ... FOR UPDATE), so its state check, its
//    update and the next progress seq are decided by one transaction at a time;
//  - creates with a request id hold a transaction-scoped advisory lock on (owner, request id), and
//    bounded creates one on the queue, so that the lookup or count and the insert are atomic; at
//    READ COMMITTED each statement after the lock sees what the previous holder committed
//    (REPEATABLE READ would keep the snapshot taken before the wait);
//  - a job's capture is locked FOR KEY SHARE while a job is attached to it, and FOR UPDATE while it
//    is deleted, so a delete never misses a job that is being created.
// Reads run in REPEATABLE READ READ ONLY transactions (one consistent snapshot per call; they
// never fail to serialise). A transaction that fails with a serialization failure or a deadlock
// is retried a few times; every other failure is returned.
//
// Timestamps come from the injected clock, never from the database server's now(): tests step the
// clock, and both stores keep the same time. With several hosts, a lease written with one host's
// clock is judged by another's, so their clocks must agree to well within a lease (NTP does).
#pragma once

#include <chrono>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "server/store/api_token.h"
#include "server/store/job_store.h"
#include "server/store/postgres_connection.h"
#include "server/store/timestamp.h"

namespace spdlog {
class logger;
}

namespace softid::server::store {

struct PostgresJobStoreOptions {
  // Connections opened at most (lazily, as calls need them); >= 1. One process's calls beyond it
  // wait for a connection to come back.
  int max_connections = 4;
  // Source of created_at, started_at, lease expiry, ...; null means the system clock.
  Clock clock;
  // For warnings that cannot be returned; null means spdlog's default logger.
  std::shared_ptr<spdlog::logger> logger;
};

class PostgresJobStore final : public JobStore, public TokenStore {
 public:
  // Connects to `url` (postgresql://user:password@host:port/database) and migrates the schema
  // (see MigratePostgresSchema). IoError naming the URL (password redacted) when the server
  // cannot be reached. Does not recover jobs left RUNNING: the caller decides when.
  static Result<std::unique_ptr<PostgresJobStore>> Open(
      const std::string& url, const PostgresJobStoreOptions& options = {});

  ~PostgresJobStore() override;
  PostgresJobStore(const PostgresJobStore&) = delete;
  PostgresJobStore& operator=(const PostgresJobStore&) = delete;

  Result<Capture> CreateCapture(const std::vector<ManifestEntry>& manifest,
                                const std::string& request_id, const std::string& owner = "",
                                std::string_view format = kCaptureFormat) override;
  Result<Capture> GetCapture(const std::string& capture_id) override;
  Result<Capture> DeleteCapture(const std::string& capture_id) override;
  Result<int64_t> StoredBytes(const std::string& owner) override;
  Result<CapturePage> ListCaptures(const ListCapturesRequest& request) override;
  Result<std::vector<std::string>> ListUnusedCaptures(Timestamp created_before) override;
  Result<std::vector<std::string>> ListEndedJobs(Timestamp finished_before) override;

  Result<Job> CreateJob(const std::string& capture_id, const nlohmann::json& config,
                        const std::string& request_id, const std::string& owner = "") override;
  Result<std::optional<Job>> CreateJobBounded(const std::string& capture_id,
                                              const nlohmann::json& config,
                                              const std::string& request_id, int64_t max_queued,
                                              const std::string& owner = "") override;
  Result<Job> GetJob(const std::string& job_id) override;
  Result<bool> HasJobWithRequestId(const std::string& request_id,
                                   const std::string& owner) override;
  Result<JobPage> ListJobs(const ListJobsRequest& request) override;
  Result<int64_t> CountJobs(std::optional<JobState> state,
                            std::optional<std::string> owner = std::nullopt) override;
  Result<Job> RequestCancel(const std::string& job_id) override;
  Status DeleteJob(const std::string& job_id) override;

  Result<std::optional<Job>> ClaimNextJob(const std::string& worker_id,
                                          std::chrono::milliseconds lease) override;
  Status RenewLease(const std::string& job_id, const std::string& worker_id,
                    std::chrono::milliseconds lease) override;
  Result<int64_t> AppendProgress(const std::string& job_id, const ProgressEvent& event) override;
  Result<std::vector<ProgressEvent>> ListProgress(const std::string& job_id,
                                                  int from_iteration) override;
  Status SaveCheckpoint(const std::string& job_id, const nlohmann::json& checkpoint) override;
  Result<std::optional<nlohmann::json>> LoadCheckpoint(const std::string& job_id) override;
  Status SetDerivedCapture(const std::string& job_id, const std::string& worker_id,
                           const std::string& capture_id) override;
  Status CompleteJob(const std::string& job_id, const nlohmann::json& result) override;
  Status FailJob(const std::string& job_id, const std::string& error) override;
  Result<bool> IsCancelRequested(const std::string& job_id) override;
  Status MarkCancelled(const std::string& job_id) override;
  Status ReleaseJob(const std::string& job_id, const std::string& worker_id,
                    const std::string& reason) override;

  Status CreateStartTasks(const std::string& job_id, const std::string& worker_id,
                          int num_tasks) override;
  Result<int> CreateTaskBatch(const std::string& job_id, const std::string& worker_id,
                              const std::string& batch,
                              const std::vector<nlohmann::json>& inputs) override;
  Result<std::optional<StartTask>> ClaimStartTask(const std::string& worker_id,
                                                  std::chrono::milliseconds lease,
                                                  const std::string& job_id = "") override;
  Status RenewStartTask(const std::string& job_id, int index, const std::string& worker_id,
                        std::chrono::milliseconds lease) override;
  Status CompleteStartTask(const std::string& job_id, int index, const std::string& worker_id,
                           const nlohmann::json& result) override;
  Status ReleaseStartTask(const std::string& job_id, int index,
                          const std::string& worker_id) override;
  Result<std::vector<StartTask>> ListStartTasks(const std::string& job_id) override;
  Result<RecoverySummary> RecoverAfterCrash(int max_attempts, RecoveryScope scope) override;
  Result<bool> IsBlobReferenced(const std::string& sha256) override;
  Result<std::vector<std::string>> ListReferencedBlobs() override;
  Status Close() override;

  // TokenStore
  Result<ApiToken> CreateToken(const std::string& station, bool admin,
                               std::optional<Timestamp> expires_at,
                               const std::string& secret_sha256) override;
  Result<std::optional<ApiToken>> FindToken(const std::string& secret_sha256) override;
  Result<std::vector<ApiToken>> ListTokens() override;
  Status RevokeToken(const std::string& token_id) override;

  // The URL with its password redacted, for messages.
  const std::string& where() const { return where_; }

 private:
  class Pool;
  PostgresJobStore(std::unique_ptr<Pool> pool, std::string where, Clock clock,
                   std::shared_ptr<spdlog::logger> logger);

  Timestamp Now() const;
  // Runs `fn(connection)` in a READ COMMITTED transaction that commits if `fn` returns OK and
  // rolls back otherwise; retried on a serialization failure or deadlock.
  template <typename Fn>
  auto Write(Fn&& fn) -> decltype(fn(std::declval<PostgresConnection&>()));
  // The same in a REPEATABLE READ READ ONLY transaction.
  template <typename Fn>
  auto Read(Fn&& fn) -> decltype(fn(std::declval<PostgresConnection&>()));
  template <typename Fn>
  auto Transact(bool write, Fn&& fn) -> decltype(fn(std::declval<PostgresConnection&>()));

  // CreateJob and CreateJobBounded; nullopt `max_queued` means no bound.
  Result<std::optional<Job>> CreateJobIfRoom(const std::string& capture_id,
                                             const nlohmann::json& config,
                                             const std::string& request_id,
                                             std::optional<int64_t> max_queued,
                                             const std::string& owner);
  // Sets a RUNNING job's terminal `state` (SUCCEEDED, FAILED or CANCELLED after a requested
  // cancel) and records it in the history; shared by CompleteJob, FailJob and MarkCancelled.
  Status FinishRunningJob(PostgresConnection& db, Job& job, JobState state,
                          const std::optional<nlohmann::json>& result, const std::string& error,
                          const std::string& message);

  std::unique_ptr<Pool> pool_;
  std::string where_;
  Clock clock_;
  std::shared_ptr<spdlog::logger> logger_;
};

}  // namespace softid::server::store
