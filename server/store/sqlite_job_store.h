// The embedded, single-node JobStore: one SQLite database file (WAL mode) holding captures, jobs,
// progress and checkpoints; schema in sqlite_schema.cc.
//
// Concurrency: one connection per SqliteJobStore, used under a mutex, so calls from many threads
// are serialised (SQLite serialises writers anyway). Several SqliteJobStore objects, in one or
// several processes, may open the same file: every read-then-write runs under BEGIN IMMEDIATE, so
// for example two of them never claim the same job.
//
// Durability: a call that returned OK survives a crash of the process; with SyncMode::kFull it
// also survives power loss.
#pragma once

#include <chrono>
#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "server/store/api_token.h"
#include "server/store/job_store.h"
#include "server/store/sqlite_database.h"
#include "server/store/timestamp.h"

namespace softid::server::store {

struct SqliteJobStoreOptions {
  SyncMode sync_mode = SyncMode::kNormal;
  // See SqliteOptions::busy_timeout.
  std::chrono::milliseconds busy_timeout{5000};
  // Source of created_at, started_at, lease expiry, ...; null means the system clock.
  Clock clock;
  // For warnings that cannot be returned; null means spdlog's default logger.
  std::shared_ptr<spdlog::logger> logger;
};

class SqliteJobStore final : public JobStore, public TokenStore {
 public:
  // Opens or creates the database at `path` and migrates its schema (see MigrateSqliteSchema:
  // FailedPrecondition for a newer schema). Does not recover jobs left RUNNING: the caller decides
  // when (RecoverAfterCrash), e.g. before starting its workers.
  static Result<std::unique_ptr<SqliteJobStore>> Open(const std::filesystem::path& path,
                                                      const SqliteJobStoreOptions& options = {});

  ~SqliteJobStore() override = default;
  SqliteJobStore(const SqliteJobStore&) = delete;
  SqliteJobStore& operator=(const SqliteJobStore&) = delete;

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

  // SQLite only: a consistent copy of the database at `destination` (VACUUM INTO), taken while the
  // store stays in use. `destination` must not exist.
  Status Backup(const std::filesystem::path& destination);

  const std::filesystem::path& path() const { return db_.path(); }

 private:
  SqliteJobStore(SqliteDatabase db, Clock clock);

  Timestamp Now() const;
  // Runs `fn` under the mutex in a BEGIN IMMEDIATE (or, for reads, deferred) transaction that
  // commits if `fn` returns OK and rolls back otherwise.
  template <typename Fn>
  auto Write(Fn&& fn) -> decltype(fn());
  template <typename Fn>
  auto Read(Fn&& fn) -> decltype(fn());

  // CreateJob and CreateJobBounded; nullopt `max_queued` means no bound.
  Result<std::optional<Job>> CreateJobIfRoom(const std::string& capture_id,
                                             const nlohmann::json& config,
                                             const std::string& request_id,
                                             std::optional<int64_t> max_queued,
                                             const std::string& owner);

  // Helpers for use inside Write/Read.
  Result<Job> LoadJob(const std::string& job_id);
  Result<std::optional<Capture>> FindCaptureByRequestId(const std::string& request_id,
                                                        const std::string& owner);
  Result<std::optional<Job>> FindJobByRequestId(const std::string& request_id,
                                                const std::string& owner);
  // Records a state change (or a worker's note) in the job's progress history.
  Result<int64_t> AppendStateEvent(const Job& job, const std::string& message, Timestamp now);

  std::mutex mutex_;
  SqliteDatabase db_;
  Clock clock_;
};

}  // namespace softid::server::store
