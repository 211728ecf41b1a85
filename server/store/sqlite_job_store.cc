#include "server/store/sqlite_job_store.h"

#include <cmath>
#include <utility>

#include "core/common/json_fields.h"
#include "server/store/job_rules.h"
#include "server/store/page_token.h"
#include "server/store/resource_id.h"
#include "server/store/sha256.h"
#include "server/store/sqlite_schema.h"
#include "server/store/start_task.h"

namespace softid::server::store {
namespace {

// Long enough for a UUID or any reasonable client key, short enough to keep the index small.

constexpr std::string_view kJobColumns =
    "id, station_request_id, capture_id, config, state, cancel_requested, attempts, error, "
    "created_at, "
    "started_at, finished_at, lease_owner, lease_expires_at, result, released_attempts, owner, "
    "derived_capture_id";

constexpr std::string_view kProgressColumns =
    "seq, attempt, event, iteration, cost, gradient_norm, parameters, elapsed_s, state, message, "
    "created_at, start, num_starts, remaining_s";

// Reads a row selected with kJobColumns.
Result<Job> ReadJob(const SqliteStatement& row) {
  Job job;
  job.id = row.ColumnText(0);
  job.request_id = row.ColumnText(1);
  job.capture_id = row.ColumnText(2);
  SOFTID_ASSIGN_OR_RETURN(job.config, ParseStoredJson(row.ColumnText(3), "jobs.config"));
  SOFTID_ASSIGN_OR_RETURN(job.state, JobStateFromString(row.ColumnText(4)));
  job.cancel_requested = row.ColumnInt64(5) != 0;
  job.attempts = static_cast<int>(row.ColumnInt64(6));
  job.error = row.ColumnText(7);
  job.created_at = FromUnixMicros(row.ColumnInt64(8));
  job.started_at = OptionalTimestamp(row.ColumnOptionalInt64(9));
  job.finished_at = OptionalTimestamp(row.ColumnOptionalInt64(10));
  job.lease_owner = row.ColumnText(11);
  job.lease_expires_at = OptionalTimestamp(row.ColumnOptionalInt64(12));
  if (!row.IsNull(13)) {
    SOFTID_ASSIGN_OR_RETURN(job.result, ParseStoredJson(row.ColumnText(13), "jobs.result"));
  }
  job.released_attempts = static_cast<int>(row.ColumnInt64(14));
  job.owner = row.ColumnText(15);
  job.derived_capture_id = row.ColumnOptionalText(16).value_or("");
  return job;
}

// Reads a row selected with kProgressColumns.
Result<ProgressEvent> ReadProgress(const SqliteStatement& row) {
  ProgressEvent event;
  event.seq = row.ColumnInt64(0);
  event.attempt = static_cast<int>(row.ColumnInt64(1));
  SOFTID_ASSIGN_OR_RETURN(event.kind, ProgressKindFromString(row.ColumnText(2)));
  event.iteration = static_cast<int>(row.ColumnInt64(3));
  event.cost = row.ColumnDouble(4);
  event.gradient_norm = row.ColumnDouble(5);
  if (!row.IsNull(6)) {
    SOFTID_ASSIGN_OR_RETURN(event.parameters,
                            ParseStoredJson(row.ColumnText(6), "progress.parameters"));
  }
  event.elapsed_s = row.ColumnDouble(7);
  if (!row.IsNull(8)) {
    SOFTID_ASSIGN_OR_RETURN(event.state, JobStateFromString(row.ColumnText(8)));
  }
  event.message = row.ColumnText(9);
  event.created_at = FromUnixMicros(row.ColumnInt64(10));
  event.start = static_cast<int>(row.ColumnInt64(11));
  event.num_starts = static_cast<int>(row.ColumnInt64(12));
  event.remaining_s = row.ColumnDouble(13);
  return event;
}

constexpr std::string_view kStartTaskColumns =
    "job_id, idx, state, attempts, lease_owner, lease_expires_at, result, batch, input";

// Reads a row selected with kStartTaskColumns.
Result<StartTask> ReadStartTask(const SqliteStatement& row) {
  StartTask task;
  task.job_id = row.ColumnText(0);
  task.index = static_cast<int>(row.ColumnInt64(1));
  SOFTID_ASSIGN_OR_RETURN(task.state, StartTaskStateFromString(row.ColumnText(2)));
  task.attempts = static_cast<int>(row.ColumnInt64(3));
  task.lease_owner = row.ColumnOptionalText(4).value_or("");
  task.lease_expires_at = OptionalTimestamp(row.ColumnOptionalInt64(5));
  if (!row.IsNull(6)) {
    SOFTID_ASSIGN_OR_RETURN(task.result, ParseStoredJson(row.ColumnText(6), "start_tasks.result"));
  }
  task.batch = row.ColumnText(7);
  if (!row.IsNull(8)) {
    SOFTID_ASSIGN_OR_RETURN(task.input, ParseStoredJson(row.ColumnText(8), "start_tasks.input"));
  }
  return task;
}

Result<StartTask> LoadStartTask(SqliteDatabase& db, const std::string& job_id, int index) {
  SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt,
                          db.Prepare("SELECT " + std::string(kStartTaskColumns) +
                                     " FROM start_tasks WHERE job_id = ?1 AND idx = ?2"));
  SOFTID_RETURN_IF_ERROR(stmt.Bind(job_id, index));
  SOFTID_ASSIGN_OR_RETURN(const bool found, stmt.Step());
  if (!found) {
    return Status::NotFound("start task " + std::to_string(index) + " of job " + job_id +
                            " not found");
  }
  return ReadStartTask(stmt);
}

}  // namespace

// --- Opening and plumbing ------------------------------------------------------------------------

Result<std::unique_ptr<SqliteJobStore>> SqliteJobStore::Open(const std::filesystem::path& path,
                                                             const SqliteJobStoreOptions& options) {
  SqliteOptions db_options;
  db_options.sync_mode = options.sync_mode;
  db_options.busy_timeout = options.busy_timeout;
  db_options.logger = options.logger;
  SOFTID_ASSIGN_OR_RETURN(SqliteDatabase db, SqliteDatabase::Open(path, db_options));
  SOFTID_RETURN_IF_ERROR(MigrateSqliteSchema(db));
  Clock clock =
      options.clock ? options.clock : Clock([] { return std::chrono::system_clock::now(); });
  return std::unique_ptr<SqliteJobStore>(new SqliteJobStore(std::move(db), std::move(clock)));
}

SqliteJobStore::SqliteJobStore(SqliteDatabase db, Clock clock)
    : db_(std::move(db)), clock_(std::move(clock)) {}

Timestamp SqliteJobStore::Now() const {
  return ToTimestamp(clock_());
}

template <typename Fn>
auto SqliteJobStore::Write(Fn&& fn) -> decltype(fn()) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (!db_.is_open()) return Status::FailedPrecondition(db_.path().string() + ": store is closed");
  SOFTID_ASSIGN_OR_RETURN(SqliteTransaction transaction,
                          SqliteTransaction::Begin(db_, TransactionMode::kImmediate));
  auto result = fn();
  if (!result.ok()) return result;  // the transaction's destructor rolls back
  SOFTID_RETURN_IF_ERROR(transaction.Commit());
  return result;
}

template <typename Fn>
auto SqliteJobStore::Read(Fn&& fn) -> decltype(fn()) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (!db_.is_open()) return Status::FailedPrecondition(db_.path().string() + ": store is closed");
  SOFTID_ASSIGN_OR_RETURN(SqliteTransaction transaction,
                          SqliteTransaction::Begin(db_, TransactionMode::kReadOnly));
  auto result = fn();
  if (!result.ok()) return result;
  SOFTID_RETURN_IF_ERROR(transaction.Commit());
  return result;
}

Status SqliteJobStore::Close() {
  std::lock_guard<std::mutex> lock(mutex_);
  return db_.Close();
}

Status SqliteJobStore::Backup(const std::filesystem::path& destination) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (!db_.is_open()) return Status::FailedPrecondition(db_.path().string() + ": store is closed");
  SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt, db_.Prepare("VACUUM INTO ?1"));
  SOFTID_RETURN_IF_ERROR(stmt.Bind(destination.string()));
  return stmt.Run().WithContext("backup to " + destination.string());
}

// --- Helpers used inside transactions ------------------------------------------------------------

Result<Job> SqliteJobStore::LoadJob(const std::string& job_id) {
  SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt, db_.Prepare("SELECT " + std::string(kJobColumns) +
                                                            " FROM jobs WHERE id = ?1"));
  SOFTID_RETURN_IF_ERROR(stmt.Bind(job_id));
  SOFTID_ASSIGN_OR_RETURN(const bool found, stmt.Step());
  if (!found) return Status::NotFound("job " + job_id + " not found");
  return ReadJob(stmt);
}

Result<std::optional<Capture>> SqliteJobStore::FindCaptureByRequestId(const std::string& request_id,
                                                                      const std::string& owner) {
  SOFTID_ASSIGN_OR_RETURN(
      SqliteStatement stmt,
      db_.Prepare("SELECT id, manifest, created_at, owner, format "
                  "FROM captures WHERE owner = ?1 AND station_request_id = ?2"));
  SOFTID_RETURN_IF_ERROR(stmt.Bind(owner, request_id));
  SOFTID_ASSIGN_OR_RETURN(const bool found, stmt.Step());
  if (!found) return std::optional<Capture>();
  Capture capture;
  capture.id = stmt.ColumnText(0);
  capture.request_id = request_id;
  SOFTID_ASSIGN_OR_RETURN(const nlohmann::json manifest,
                          ParseStoredJson(stmt.ColumnText(1), "captures.manifest"));
  SOFTID_ASSIGN_OR_RETURN(capture.manifest, ManifestFromJson(manifest));
  capture.created_at = FromUnixMicros(stmt.ColumnInt64(2));
  capture.owner = stmt.ColumnText(3);
  capture.format = stmt.ColumnText(4);
  return std::optional<Capture>(std::move(capture));
}

Result<std::optional<Job>> SqliteJobStore::FindJobByRequestId(const std::string& request_id,
                                                              const std::string& owner) {
  SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt,
                          db_.Prepare("SELECT " + std::string(kJobColumns) +
                                      " FROM jobs WHERE owner = ?1 AND station_request_id = ?2"));
  SOFTID_RETURN_IF_ERROR(stmt.Bind(owner, request_id));
  SOFTID_ASSIGN_OR_RETURN(const bool found, stmt.Step());
  if (!found) return std::optional<Job>();
  SOFTID_ASSIGN_OR_RETURN(Job job, ReadJob(stmt));
  return std::optional<Job>(std::move(job));
}

Result<int64_t> SqliteJobStore::AppendStateEvent(const Job& job, const std::string& message,
                                                 Timestamp now) {
  // seq continues the job's history; iteration repeats the latest iteration event's, so that
  // ListProgress(from_iteration = N) includes the state changes that followed iteration N.
  SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt, db_.Prepare(R"sql(
      INSERT INTO progress (job_id, seq, attempt, event, iteration, elapsed_s, state, message,
                            created_at)
      VALUES (?1,
              (SELECT COALESCE(MAX(seq), 0) + 1 FROM progress WHERE job_id = ?1),
              ?2, 'state',
              COALESCE((SELECT iteration FROM progress WHERE job_id = ?1 AND event = 'iteration'
                        ORDER BY seq DESC LIMIT 1), 0),
              ?3, ?4, ?5, ?6)
      RETURNING seq)sql"));
  SOFTID_RETURN_IF_ERROR(stmt.Bind(job.id, job.attempts, ElapsedSeconds(job, now),
                                   ToString(job.state), message, ToUnixMicros(now)));
  SOFTID_ASSIGN_OR_RETURN(const bool has_row, stmt.Step());
  if (!has_row) return Status::Internal("INSERT ... RETURNING seq returned no row");
  const int64_t seq = stmt.ColumnInt64(0);
  SOFTID_ASSIGN_OR_RETURN(const bool more, stmt.Step());
  (void)more;
  return seq;
}

// --- Captures ------------------------------------------------------------------------------------

Result<Capture> SqliteJobStore::CreateCapture(const std::vector<ManifestEntry>& manifest,
                                              const std::string& request_id,
                                              const std::string& owner, std::string_view format) {
  SOFTID_RETURN_IF_ERROR(ValidateManifest(manifest));
  if (format != kCaptureFormat && format != kRecordingFormat) {
    return json::Invalid("format", std::string(format),
                         "must be \"softid-capture/1\" or \"softid-recording/1\"");
  }
  SOFTID_RETURN_IF_ERROR(CheckRequestId(request_id));
  return Write([&]() -> Result<Capture> {
    if (!request_id.empty()) {
      SOFTID_ASSIGN_OR_RETURN(std::optional<Capture> existing,
                              FindCaptureByRequestId(request_id, owner));
      if (existing.has_value()) {
        if (existing->manifest != manifest || existing->format != format) {
          return Status::FailedPrecondition("request_id '" + request_id +
                                            "' was already used to create capture " + existing->id +
                                            " with a different manifest");
        }
        return *std::move(existing);
      }
    }
    Capture capture;
    capture.id = NewResourceId(kCaptureIdPrefix);
    capture.request_id = request_id;
    capture.manifest = manifest;
    capture.created_at = Now();
    capture.owner = owner;
    capture.format = std::string(format);
    SOFTID_ASSIGN_OR_RETURN(
        SqliteStatement stmt,
        db_.Prepare("INSERT INTO captures (id, station_request_id, manifest, "
                    "created_at, owner, format) VALUES (?1, ?2, ?3, ?4, ?5, ?6)"));
    SOFTID_RETURN_IF_ERROR(stmt.Bind(capture.id, NullIfEmpty(request_id),
                                     DumpJson(ManifestToJson(manifest)),
                                     ToUnixMicros(capture.created_at), owner, capture.format));
    SOFTID_RETURN_IF_ERROR(stmt.Run());
    return capture;
  });
}

Result<Capture> SqliteJobStore::GetCapture(const std::string& capture_id) {
  SOFTID_RETURN_IF_ERROR(CheckResourceId(capture_id, kCaptureIdPrefix, "capture id"));
  return Read([&]() -> Result<Capture> {
    SOFTID_ASSIGN_OR_RETURN(
        SqliteStatement stmt,
        db_.Prepare("SELECT station_request_id, manifest, created_at, owner, format "
                    "FROM captures WHERE id = ?1"));
    SOFTID_RETURN_IF_ERROR(stmt.Bind(capture_id));
    SOFTID_ASSIGN_OR_RETURN(const bool found, stmt.Step());
    if (!found) return Status::NotFound("capture " + capture_id + " not found");
    Capture capture;
    capture.id = capture_id;
    capture.request_id = stmt.ColumnText(0);
    SOFTID_ASSIGN_OR_RETURN(const nlohmann::json manifest,
                            ParseStoredJson(stmt.ColumnText(1), "captures.manifest"));
    SOFTID_ASSIGN_OR_RETURN(capture.manifest, ManifestFromJson(manifest));
    capture.created_at = FromUnixMicros(stmt.ColumnInt64(2));
    capture.owner = stmt.ColumnText(3);
    capture.format = stmt.ColumnText(4);
    return capture;
  });
}

Result<Capture> SqliteJobStore::DeleteCapture(const std::string& capture_id) {
  SOFTID_RETURN_IF_ERROR(CheckResourceId(capture_id, kCaptureIdPrefix, "capture id"));
  SOFTID_ASSIGN_OR_RETURN(Capture capture, GetCapture(capture_id));
  return Write([&]() -> Result<Capture> {
    {
      SOFTID_ASSIGN_OR_RETURN(
          SqliteStatement stmt,
          db_.Prepare("SELECT id FROM jobs WHERE capture_id = ?1 OR derived_capture_id = ?1 "
                      "LIMIT 1"));
      SOFTID_RETURN_IF_ERROR(stmt.Bind(capture_id));
      SOFTID_ASSIGN_OR_RETURN(const bool used, stmt.Step());
      if (used) {
        return Status::FailedPrecondition("capture " + capture_id + " is used by job " +
                                          stmt.ColumnText(0) + ": delete its jobs first");
      }
    }
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt,
                            db_.Prepare("DELETE FROM captures WHERE id = ?1 RETURNING id"));
    SOFTID_RETURN_IF_ERROR(stmt.Bind(capture_id));
    SOFTID_ASSIGN_OR_RETURN(const bool deleted, stmt.Step());
    if (!deleted) return Status::NotFound("capture " + capture_id + " not found");
    SOFTID_ASSIGN_OR_RETURN(const bool more, stmt.Step());
    (void)more;
    return capture;
  });
}

namespace {

// The first column of every row of `stmt`.
Result<std::vector<std::string>> Column0(SqliteStatement& stmt) {
  std::vector<std::string> out;
  while (true) {
    SOFTID_ASSIGN_OR_RETURN(const bool has_row, stmt.Step());
    if (!has_row) break;
    out.push_back(stmt.ColumnText(0));
  }
  return out;
}

}  // namespace

Result<CapturePage> SqliteJobStore::ListCaptures(const ListCapturesRequest& request) {
  if (request.page_size < 0) {
    return Status::InvalidArgument("page_size = " + std::to_string(request.page_size) +
                                   ": must not be negative");
  }
  const int page_size =
      std::min(request.page_size == 0 ? ListJobsRequest::kDefaultPageSize : request.page_size,
               ListJobsRequest::kMaxPageSize);
  // "captures" keeps a token of a job list from being used here.
  std::string filter = "captures";
  if (request.owner.has_value()) filter += "&owner=" + *request.owner;
  std::optional<PageCursor> after;
  if (!request.page_token.empty()) {
    SOFTID_ASSIGN_OR_RETURN(after, DecodePageToken(request.page_token, filter));
  }
  std::string sql =
      "SELECT id, station_request_id, manifest, created_at, owner, "
      "(SELECT count(*) FROM jobs WHERE jobs.capture_id = captures.id "
      "OR jobs.derived_capture_id = captures.id), format FROM captures WHERE 1";
  if (request.owner.has_value()) sql += " AND owner = ?1";
  if (after.has_value()) sql += " AND (created_at, id) > (?2, ?3)";
  sql += " ORDER BY created_at, id LIMIT ?4";  // the highest parameter: see ListJobs

  return Read([&]() -> Result<CapturePage> {
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt, db_.Prepare(sql));
    std::optional<int64_t> after_created;
    std::optional<std::string> after_id;
    if (after.has_value()) {
      after_created = ToUnixMicros(after->created_at);
      after_id = after->id;
    }
    SOFTID_RETURN_IF_ERROR(stmt.Bind(request.owner, after_created, after_id, page_size + 1));
    CapturePage page;
    while (true) {
      SOFTID_ASSIGN_OR_RETURN(const bool has_row, stmt.Step());
      if (!has_row) break;
      CaptureListing listing;
      listing.capture.id = stmt.ColumnText(0);
      listing.capture.request_id = stmt.ColumnText(1);
      SOFTID_ASSIGN_OR_RETURN(const nlohmann::json manifest,
                              ParseStoredJson(stmt.ColumnText(2), "captures.manifest"));
      SOFTID_ASSIGN_OR_RETURN(listing.capture.manifest, ManifestFromJson(manifest));
      listing.capture.created_at = FromUnixMicros(stmt.ColumnInt64(3));
      listing.capture.owner = stmt.ColumnText(4);
      listing.num_jobs = stmt.ColumnInt64(5);
      listing.capture.format = stmt.ColumnText(6);
      page.captures.push_back(std::move(listing));
    }
    if (static_cast<int>(page.captures.size()) > page_size) {
      page.captures.pop_back();
      const Capture& last = page.captures.back().capture;
      page.next_page_token = EncodePageToken(PageCursor{last.created_at, last.id}, filter);
    }
    return page;
  });
}

Result<std::vector<std::string>> SqliteJobStore::ListUnusedCaptures(Timestamp created_before) {
  return Read([&]() -> Result<std::vector<std::string>> {
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt, db_.Prepare(R"sql(
        SELECT id FROM captures WHERE created_at < ?1
          AND NOT EXISTS (SELECT 1 FROM jobs WHERE jobs.capture_id = captures.id
                                               OR jobs.derived_capture_id = captures.id)
        ORDER BY created_at, id)sql"));
    SOFTID_RETURN_IF_ERROR(stmt.Bind(ToUnixMicros(created_before)));
    return Column0(stmt);
  });
}

Result<std::vector<std::string>> SqliteJobStore::ListEndedJobs(Timestamp finished_before) {
  return Read([&]() -> Result<std::vector<std::string>> {
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt, db_.Prepare(R"sql(
        SELECT id FROM jobs WHERE state IN ('SUCCEEDED', 'FAILED', 'CANCELLED')
          AND finished_at < ?1 ORDER BY finished_at, id)sql"));
    SOFTID_RETURN_IF_ERROR(stmt.Bind(ToUnixMicros(finished_before)));
    return Column0(stmt);
  });
}

Result<int64_t> SqliteJobStore::StoredBytes(const std::string& owner) {
  return Read([&]() -> Result<int64_t> {
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt, db_.Prepare(R"sql(
        SELECT COALESCE(SUM(json_extract(file.value, '$.size')), 0)
        FROM captures, json_each(captures.manifest) AS file WHERE captures.owner = ?1)sql"));
    SOFTID_RETURN_IF_ERROR(stmt.Bind(owner));
    SOFTID_ASSIGN_OR_RETURN(const bool has_row, stmt.Step());
    if (!has_row) return Status::Internal("SUM returned no row");
    return stmt.ColumnInt64(0);
  });
}

// --- Jobs: API side ------------------------------------------------------------------------------

Result<Job> SqliteJobStore::CreateJob(const std::string& capture_id, const nlohmann::json& config,
                                      const std::string& request_id, const std::string& owner) {
  SOFTID_ASSIGN_OR_RETURN(std::optional<Job> job,
                          CreateJobIfRoom(capture_id, config, request_id, std::nullopt, owner));
  return *std::move(job);
}

Result<std::optional<Job>> SqliteJobStore::CreateJobBounded(const std::string& capture_id,
                                                            const nlohmann::json& config,
                                                            const std::string& request_id,
                                                            int64_t max_queued,
                                                            const std::string& owner) {
  if (max_queued < 1) {
    return Status::InvalidArgument("max_queued = " + std::to_string(max_queued) +
                                   ": must be at least 1");
  }
  return CreateJobIfRoom(capture_id, config, request_id, max_queued, owner);
}

Result<std::optional<Job>> SqliteJobStore::CreateJobIfRoom(const std::string& capture_id,
                                                           const nlohmann::json& config,
                                                           const std::string& request_id,
                                                           std::optional<int64_t> max_queued,
                                                           const std::string& owner) {
  SOFTID_RETURN_IF_ERROR(CheckResourceId(capture_id, kCaptureIdPrefix, "capture id"));
  if (!config.is_object()) return json::Invalid("config", config, "must be a JSON object");
  SOFTID_RETURN_IF_ERROR(CheckRequestId(request_id));
  return Write([&]() -> Result<std::optional<Job>> {
    if (!request_id.empty()) {
      SOFTID_ASSIGN_OR_RETURN(std::optional<Job> existing, FindJobByRequestId(request_id, owner));
      if (existing.has_value()) {
        if (existing->capture_id != capture_id || existing->config != config) {
          return Status::FailedPrecondition(
              "request_id '" + request_id + "' was already used to create job " + existing->id +
              " with a different " + (existing->capture_id != capture_id ? "capture" : "config"));
        }
        return existing;
      }
    }
    {
      SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt,
                              db_.Prepare("SELECT 1 FROM captures WHERE id = ?1"));
      SOFTID_RETURN_IF_ERROR(stmt.Bind(capture_id));
      SOFTID_ASSIGN_OR_RETURN(const bool found, stmt.Step());
      if (!found) return Status::NotFound("capture " + capture_id + " not found");
    }
    if (max_queued.has_value()) {
      // Counted inside the write transaction: no other create can slip in between.
      SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt,
                              db_.Prepare("SELECT count(*) FROM jobs WHERE state = 'QUEUED'"));
      SOFTID_ASSIGN_OR_RETURN(const bool has_row, stmt.Step());
      if (!has_row) return Status::Internal("count(*) returned no row");
      if (stmt.ColumnInt64(0) >= *max_queued) return std::optional<Job>();
    }
    Job job;
    job.id = NewResourceId(kJobIdPrefix);
    job.request_id = request_id;
    job.capture_id = capture_id;
    job.config = config;
    job.state = JobState::kQueued;
    job.created_at = Now();
    job.owner = owner;
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt, db_.Prepare(R"sql(
        INSERT INTO jobs (id, station_request_id, capture_id, config, state, created_at, owner)
        VALUES (?1, ?2, ?3, ?4, 'QUEUED', ?5, ?6))sql"));
    SOFTID_RETURN_IF_ERROR(stmt.Bind(job.id, NullIfEmpty(request_id), capture_id, DumpJson(config),
                                     ToUnixMicros(job.created_at), owner));
    SOFTID_RETURN_IF_ERROR(stmt.Run());
    SOFTID_RETURN_IF_ERROR(AppendStateEvent(job, "created", job.created_at).status());
    return std::optional<Job>(std::move(job));
  });
}

Result<Job> SqliteJobStore::GetJob(const std::string& job_id) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  return Read([&] { return LoadJob(job_id); });
}

Result<bool> SqliteJobStore::HasJobWithRequestId(const std::string& request_id,
                                                 const std::string& owner) {
  if (request_id.empty()) return false;
  return Read([&]() -> Result<bool> {
    SOFTID_ASSIGN_OR_RETURN(std::optional<Job> job, FindJobByRequestId(request_id, owner));
    return job.has_value();
  });
}

Result<JobPage> SqliteJobStore::ListJobs(const ListJobsRequest& request) {
  if (request.page_size < 0) {
    return Status::InvalidArgument("page_size = " + std::to_string(request.page_size) +
                                   ": must not be negative");
  }
  int page_size = request.page_size == 0 ? ListJobsRequest::kDefaultPageSize : request.page_size;
  page_size = std::min(page_size, ListJobsRequest::kMaxPageSize);
  std::string filter =
      request.state.has_value() ? std::string("state=") + ToString(*request.state) : "";
  if (request.owner.has_value()) filter += "&owner=" + *request.owner;
  std::optional<PageCursor> after;
  if (!request.page_token.empty()) {
    SOFTID_ASSIGN_OR_RETURN(after, DecodePageToken(request.page_token, filter));
  }

  // Separate SQL per case (rather than "?1 IS NULL OR state = ?1") so the planner can seek the
  // matching index: jobs_by_state with a filter, jobs_by_creation without.
  std::string sql = "SELECT " + std::string(kJobColumns) + " FROM jobs WHERE 1";
  if (request.state.has_value()) sql += " AND state = ?1";
  if (request.owner.has_value()) sql += " AND owner = ?4";
  if (after.has_value()) sql += " AND (created_at, id) > (?2, ?3)";
  // The limit is the highest parameter, so the unused filters' slots below it can be bound.
  sql += " ORDER BY created_at, id LIMIT ?5";

  return Read([&]() -> Result<JobPage> {
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt, db_.Prepare(sql));
    std::optional<std::string> state_text;
    if (request.state.has_value()) state_text = ToString(*request.state);
    std::optional<int64_t> after_created;
    std::optional<std::string> after_id;
    if (after.has_value()) {
      after_created = ToUnixMicros(after->created_at);
      after_id = after->id;
    }
    // One row more than the page tells whether another page follows, so the last page never
    // hands out a token that leads to an empty page.
    SOFTID_RETURN_IF_ERROR(
        stmt.Bind(state_text, after_created, after_id, request.owner, page_size + 1));
    JobPage page;
    while (true) {
      SOFTID_ASSIGN_OR_RETURN(const bool has_row, stmt.Step());
      if (!has_row) break;
      SOFTID_ASSIGN_OR_RETURN(Job job, ReadJob(stmt));
      page.jobs.push_back(std::move(job));
    }
    if (static_cast<int>(page.jobs.size()) > page_size) {
      page.jobs.pop_back();
      const Job& last = page.jobs.back();
      page.next_page_token = EncodePageToken(PageCursor{last.created_at, last.id}, filter);
    }
    return page;
  });
}

Result<int64_t> SqliteJobStore::CountJobs(std::optional<JobState> state,
                                          std::optional<std::string> owner) {
  return Read([&]() -> Result<int64_t> {
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt, db_.Prepare(R"sql(
        SELECT count(*) FROM jobs
        WHERE (?1 IS NULL OR state = ?1) AND (?2 IS NULL OR owner = ?2))sql"));
    std::optional<std::string> state_text;
    if (state.has_value()) state_text = ToString(*state);
    SOFTID_RETURN_IF_ERROR(stmt.Bind(state_text, owner));
    SOFTID_ASSIGN_OR_RETURN(const bool has_row, stmt.Step());
    if (!has_row) return Status::Internal("count(*) returned no row");
    return stmt.ColumnInt64(0);
  });
}

Result<Job> SqliteJobStore::RequestCancel(const std::string& job_id) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  return Write([&]() -> Result<Job> {
    SOFTID_ASSIGN_OR_RETURN(Job job, LoadJob(job_id));
    const Timestamp now = Now();
    switch (job.state) {
      case JobState::kQueued: {
        SOFTID_ASSIGN_OR_RETURN(
            SqliteStatement stmt,
            db_.Prepare("UPDATE jobs SET state = 'CANCELLED', finished_at = ?2 WHERE id = ?1"));
        SOFTID_RETURN_IF_ERROR(stmt.Bind(job_id, ToUnixMicros(now)));
        SOFTID_RETURN_IF_ERROR(stmt.Run());
        job.state = JobState::kCancelled;
        job.finished_at = now;
        SOFTID_RETURN_IF_ERROR(AppendStateEvent(job, "cancelled while queued", now).status());
        return job;
      }
      case JobState::kRunning: {
        if (job.cancel_requested) return job;  // asked before: nothing new to record
        SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt,
                                db_.Prepare("UPDATE jobs SET cancel_requested = 1 WHERE id = ?1"));
        SOFTID_RETURN_IF_ERROR(stmt.Bind(job_id));
        SOFTID_RETURN_IF_ERROR(stmt.Run());
        job.cancel_requested = true;
        SOFTID_RETURN_IF_ERROR(AppendStateEvent(job, "cancel requested", now).status());
        return job;
      }
      case JobState::kSucceeded:
      case JobState::kFailed:
      case JobState::kCancelled: break;
    }
    return WrongState(job, "a finished job cannot be cancelled");
  });
}

Status SqliteJobStore::DeleteJob(const std::string& job_id) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  return Write([&]() -> Status {
    SOFTID_ASSIGN_OR_RETURN(const Job job, LoadJob(job_id));
    if (job.state == JobState::kRunning) {
      return WrongState(job, "cancel it and wait until it stops before deleting it");
    }
    // progress and checkpoints go with it (ON DELETE CASCADE).
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt, db_.Prepare("DELETE FROM jobs WHERE id = ?1"));
    SOFTID_RETURN_IF_ERROR(stmt.Bind(job_id));
    return stmt.Run();
  });
}

// --- Jobs: worker side ---------------------------------------------------------------------------

Result<std::optional<Job>> SqliteJobStore::ClaimNextJob(const std::string& worker_id,
                                                        std::chrono::milliseconds lease) {
  SOFTID_RETURN_IF_ERROR(CheckWorkerId(worker_id));
  SOFTID_RETURN_IF_ERROR(CheckLease(lease));
  return Write([&]() -> Result<std::optional<Job>> {
    const Timestamp now = Now();
    // One statement picks and takes the job; under BEGIN IMMEDIATE no other connection can take
    // the same one in between.
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt, db_.Prepare(R"sql(
        UPDATE jobs
        SET state = 'RUNNING', attempts = attempts + 1, started_at = ?1, lease_owner = ?2,
            lease_expires_at = ?3
        WHERE id = (SELECT id FROM jobs WHERE state = 'QUEUED' ORDER BY created_at, id LIMIT 1)
        RETURNING )sql" + std::string(kJobColumns)));
    const Timestamp expires = now + std::chrono::duration_cast<std::chrono::microseconds>(lease);
    SOFTID_RETURN_IF_ERROR(stmt.Bind(ToUnixMicros(now), worker_id, ToUnixMicros(expires)));
    SOFTID_ASSIGN_OR_RETURN(const bool claimed, stmt.Step());
    if (!claimed) return std::optional<Job>();
    SOFTID_ASSIGN_OR_RETURN(Job job, ReadJob(stmt));
    SOFTID_ASSIGN_OR_RETURN(const bool more, stmt.Step());  // runs the statement to completion
    if (more) return Status::Internal("claim updated more than one job");
    // The worker's id (host and process) stays in the server's log: progress is shown to clients.
    SOFTID_RETURN_IF_ERROR(
        AppendStateEvent(job, "started (attempt " + std::to_string(job.attempts) + ")", now)
            .status());
    return std::optional<Job>(std::move(job));
  });
}

Status SqliteJobStore::RenewLease(const std::string& job_id, const std::string& worker_id,
                                  std::chrono::milliseconds lease) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  SOFTID_RETURN_IF_ERROR(CheckWorkerId(worker_id));
  SOFTID_RETURN_IF_ERROR(CheckLease(lease));
  return Write([&]() -> Status {
    SOFTID_ASSIGN_OR_RETURN(const Job job, LoadJob(job_id));
    if (job.state != JobState::kRunning) return WrongState(job, "only a RUNNING job has a lease");
    if (job.lease_owner != worker_id) return NotLeasedTo(job, worker_id);
    const Timestamp expires = Now() + std::chrono::duration_cast<std::chrono::microseconds>(lease);
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt,
                            db_.Prepare("UPDATE jobs SET lease_expires_at = ?2 WHERE id = ?1"));
    SOFTID_RETURN_IF_ERROR(stmt.Bind(job_id, ToUnixMicros(expires)));
    return stmt.Run();
  });
}

Result<int64_t> SqliteJobStore::AppendProgress(const std::string& job_id,
                                               const ProgressEvent& event) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  if (event.kind == ProgressKind::kIteration && event.iteration < 0) {
    return Status::InvalidArgument("iteration = " + std::to_string(event.iteration) +
                                   ": must not be negative");
  }
  if (event.kind == ProgressKind::kIteration &&
      (event.num_starts < 1 || event.start < 0 || event.start >= event.num_starts)) {
    return Status::InvalidArgument("start = " + std::to_string(event.start) + " of " +
                                   std::to_string(event.num_starts) +
                                   ": must lie in [0, num_starts)");
  }
  if (!std::isfinite(event.elapsed_s) || event.elapsed_s < 0) {
    return Status::InvalidArgument("elapsed_s = " + std::to_string(event.elapsed_s) +
                                   ": must be finite and non-negative");
  }
  return Write([&]() -> Result<int64_t> {
    SOFTID_ASSIGN_OR_RETURN(const Job job, LoadJob(job_id));
    const Timestamp now = Now();
    if (event.kind == ProgressKind::kState) return AppendStateEvent(job, event.message, now);
    if (job.state != JobState::kRunning) {
      return WrongState(job, "iteration progress is only accepted while RUNNING");
    }
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt, db_.Prepare(R"sql(
        INSERT INTO progress (job_id, seq, attempt, event, iteration, cost, gradient_norm,
                              parameters, elapsed_s, message, created_at, start, num_starts,
                              remaining_s)
        VALUES (?1, (SELECT COALESCE(MAX(seq), 0) + 1 FROM progress WHERE job_id = ?1),
                ?2, 'iteration', ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12)
        RETURNING seq)sql"));
    std::optional<std::string> parameters;
    if (!event.parameters.is_null()) parameters = DumpJson(event.parameters);
    SOFTID_RETURN_IF_ERROR(stmt.Bind(job_id, job.attempts, event.iteration, event.cost,
                                     event.gradient_norm, parameters, event.elapsed_s,
                                     event.message, ToUnixMicros(now), event.start,
                                     event.num_starts, event.remaining_s));
    SOFTID_ASSIGN_OR_RETURN(const bool has_row, stmt.Step());
    if (!has_row) return Status::Internal("INSERT ... RETURNING seq returned no row");
    const int64_t seq = stmt.ColumnInt64(0);
    SOFTID_ASSIGN_OR_RETURN(const bool more, stmt.Step());
    (void)more;
    return seq;
  });
}

Result<std::vector<ProgressEvent>> SqliteJobStore::ListProgress(const std::string& job_id,
                                                                int from_iteration) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  return Read([&]() -> Result<std::vector<ProgressEvent>> {
    SOFTID_RETURN_IF_ERROR(LoadJob(job_id).status());
    SOFTID_ASSIGN_OR_RETURN(
        SqliteStatement stmt,
        db_.Prepare("SELECT " + std::string(kProgressColumns) +
                    " FROM progress WHERE job_id = ?1 AND iteration >= ?2 ORDER BY seq"));
    SOFTID_RETURN_IF_ERROR(stmt.Bind(job_id, from_iteration));
    std::vector<ProgressEvent> events;
    while (true) {
      SOFTID_ASSIGN_OR_RETURN(const bool has_row, stmt.Step());
      if (!has_row) break;
      SOFTID_ASSIGN_OR_RETURN(ProgressEvent event, ReadProgress(stmt));
      events.push_back(std::move(event));
    }
    return events;
  });
}

Status SqliteJobStore::SaveCheckpoint(const std::string& job_id, const nlohmann::json& checkpoint) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  return Write([&]() -> Status {
    SOFTID_ASSIGN_OR_RETURN(const Job job, LoadJob(job_id));
    if (job.state != JobState::kRunning) {
      return WrongState(job, "checkpoints are only accepted while RUNNING");
    }
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt, db_.Prepare(R"sql(
        INSERT INTO checkpoints (job_id, attempt, data, updated_at) VALUES (?1, ?2, ?3, ?4)
        ON CONFLICT (job_id) DO UPDATE
        SET attempt = excluded.attempt, data = excluded.data,
            updated_at = excluded.updated_at)sql"));
    SOFTID_RETURN_IF_ERROR(
        stmt.Bind(job_id, job.attempts, DumpJson(checkpoint), ToUnixMicros(Now())));
    return stmt.Run();
  });
}

Result<std::optional<nlohmann::json>> SqliteJobStore::LoadCheckpoint(const std::string& job_id) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  return Read([&]() -> Result<std::optional<nlohmann::json>> {
    SOFTID_RETURN_IF_ERROR(LoadJob(job_id).status());
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt,
                            db_.Prepare("SELECT data FROM checkpoints WHERE job_id = ?1"));
    SOFTID_RETURN_IF_ERROR(stmt.Bind(job_id));
    SOFTID_ASSIGN_OR_RETURN(const bool found, stmt.Step());
    if (!found) return std::optional<nlohmann::json>();
    SOFTID_ASSIGN_OR_RETURN(nlohmann::json data,
                            ParseStoredJson(stmt.ColumnText(0), "checkpoints.data"));
    return std::optional<nlohmann::json>(std::move(data));
  });
}

Status SqliteJobStore::CompleteJob(const std::string& job_id, const nlohmann::json& result) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  return Write([&]() -> Status {
    SOFTID_ASSIGN_OR_RETURN(Job job, LoadJob(job_id));
    if (job.state != JobState::kRunning) {
      return WrongState(job, "only a RUNNING job can be completed");
    }
    const Timestamp now = Now();
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt, db_.Prepare(R"sql(
        UPDATE jobs SET state = 'SUCCEEDED', finished_at = ?2, result = ?3, lease_owner = NULL,
                        lease_expires_at = NULL
        WHERE id = ?1)sql"));
    SOFTID_RETURN_IF_ERROR(stmt.Bind(job_id, ToUnixMicros(now), DumpJson(result)));
    SOFTID_RETURN_IF_ERROR(stmt.Run());
    job.state = JobState::kSucceeded;
    return AppendStateEvent(job, "succeeded", now).status();
  });
}

Status SqliteJobStore::SetDerivedCapture(const std::string& job_id, const std::string& worker_id,
                                         const std::string& capture_id) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  SOFTID_RETURN_IF_ERROR(CheckWorkerId(worker_id));
  SOFTID_RETURN_IF_ERROR(CheckResourceId(capture_id, kCaptureIdPrefix, "capture id"));
  return Write([&]() -> Status {
    SOFTID_ASSIGN_OR_RETURN(const Job job, LoadJob(job_id));
    if (job.state != JobState::kRunning) {
      return WrongState(job, "only a RUNNING job derives a capture");
    }
    if (job.lease_owner != worker_id) return NotLeasedTo(job, worker_id);
    {
      SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt,
                              db_.Prepare("SELECT 1 FROM captures WHERE id = ?1"));
      SOFTID_RETURN_IF_ERROR(stmt.Bind(capture_id));
      SOFTID_ASSIGN_OR_RETURN(const bool found, stmt.Step());
      if (!found) return Status::NotFound("capture " + capture_id + " not found");
    }
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt,
                            db_.Prepare("UPDATE jobs SET derived_capture_id = ?2 WHERE id = ?1"));
    SOFTID_RETURN_IF_ERROR(stmt.Bind(job_id, capture_id));
    return stmt.Run();
  });
}

Status SqliteJobStore::FailJob(const std::string& job_id, const std::string& error) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  if (error.empty()) return Status::InvalidArgument("error = '': a failed job needs a reason");
  return Write([&]() -> Status {
    SOFTID_ASSIGN_OR_RETURN(Job job, LoadJob(job_id));
    if (job.state != JobState::kRunning) return WrongState(job, "only a RUNNING job can fail");
    const Timestamp now = Now();
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt, db_.Prepare(R"sql(
        UPDATE jobs SET state = 'FAILED', finished_at = ?2, error = ?3, lease_owner = NULL,
                        lease_expires_at = NULL
        WHERE id = ?1)sql"));
    SOFTID_RETURN_IF_ERROR(stmt.Bind(job_id, ToUnixMicros(now), error));
    SOFTID_RETURN_IF_ERROR(stmt.Run());
    job.state = JobState::kFailed;
    return AppendStateEvent(job, error, now).status();
  });
}

Result<bool> SqliteJobStore::IsCancelRequested(const std::string& job_id) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  return Read([&]() -> Result<bool> {
    SOFTID_ASSIGN_OR_RETURN(const Job job, LoadJob(job_id));
    return job.cancel_requested || job.state == JobState::kCancelled;
  });
}

Status SqliteJobStore::MarkCancelled(const std::string& job_id) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  return Write([&]() -> Status {
    SOFTID_ASSIGN_OR_RETURN(Job job, LoadJob(job_id));
    if (job.state != JobState::kRunning) {
      return WrongState(job, "only a RUNNING job can acknowledge a cancel");
    }
    if (!job.cancel_requested) {
      return WrongState(job, "no cancel was requested (use FailJob to stop for another reason)");
    }
    const Timestamp now = Now();
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt, db_.Prepare(R"sql(
        UPDATE jobs SET state = 'CANCELLED', finished_at = ?2, lease_owner = NULL,
                        lease_expires_at = NULL
        WHERE id = ?1)sql"));
    SOFTID_RETURN_IF_ERROR(stmt.Bind(job_id, ToUnixMicros(now)));
    SOFTID_RETURN_IF_ERROR(stmt.Run());
    job.state = JobState::kCancelled;
    return AppendStateEvent(job, "cancelled", now).status();
  });
}

Status SqliteJobStore::ReleaseJob(const std::string& job_id, const std::string& worker_id,
                                  const std::string& reason) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  SOFTID_RETURN_IF_ERROR(CheckWorkerId(worker_id));
  return Write([&]() -> Status {
    SOFTID_ASSIGN_OR_RETURN(Job job, LoadJob(job_id));
    if (job.state != JobState::kRunning) return WrongState(job, "only a RUNNING job is released");
    if (job.lease_owner != worker_id) return NotLeasedTo(job, worker_id);
    const Timestamp now = Now();
    std::string message;
    if (job.cancel_requested) {
      // Running it again would only be cancelled again.
      job.state = JobState::kCancelled;
      message = "cancelled: released (" + reason + ") after the cancel was requested";
      SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt, db_.Prepare(R"sql(
          UPDATE jobs SET state = 'CANCELLED', finished_at = ?2, lease_owner = NULL,
                          lease_expires_at = NULL
          WHERE id = ?1)sql"));
      SOFTID_RETURN_IF_ERROR(stmt.Bind(job_id, ToUnixMicros(now)));
      SOFTID_RETURN_IF_ERROR(stmt.Run());
    } else {
      job.state = JobState::kQueued;
      message = "requeued: " + reason + " during attempt " + std::to_string(job.attempts) +
                " (not counted against max_attempts)";
      SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt, db_.Prepare(R"sql(
          UPDATE jobs SET state = 'QUEUED', released_attempts = released_attempts + 1,
                          lease_owner = NULL, lease_expires_at = NULL
          WHERE id = ?1)sql"));
      SOFTID_RETURN_IF_ERROR(stmt.Bind(job_id));
      SOFTID_RETURN_IF_ERROR(stmt.Run());
    }
    return AppendStateEvent(job, message, now).status();
  });
}

// --- Maintenance ---------------------------------------------------------------------------------

Result<bool> SqliteJobStore::IsBlobReferenced(const std::string& sha256) {
  return Read([&]() -> Result<bool> {
    // A scan of every manifest: only failed uploads ask, and they are rare.
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt, db_.Prepare(R"sql(
        SELECT 1 FROM captures, json_each(captures.manifest) AS file
        WHERE json_extract(file.value, '$.sha256') = ?1 LIMIT 1)sql"));
    SOFTID_RETURN_IF_ERROR(stmt.Bind(sha256));
    return stmt.Step();
  });
}

Result<std::vector<std::string>> SqliteJobStore::ListReferencedBlobs() {
  return Read([&]() -> Result<std::vector<std::string>> {
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt, db_.Prepare(R"sql(
        SELECT DISTINCT json_extract(file.value, '$.sha256')
        FROM captures, json_each(captures.manifest) AS file)sql"));
    std::vector<std::string> hashes;
    while (true) {
      SOFTID_ASSIGN_OR_RETURN(const bool has_row, stmt.Step());
      if (!has_row) break;
      hashes.push_back(stmt.ColumnText(0));
    }
    return hashes;
  });
}

// --- Start tasks -----------------------------------------------------------------------------

Status SqliteJobStore::CreateStartTasks(const std::string& job_id, const std::string& worker_id,
                                        int num_tasks) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  SOFTID_RETURN_IF_ERROR(CheckWorkerId(worker_id));
  SOFTID_RETURN_IF_ERROR(CheckTaskCount(num_tasks));
  return Write([&]() -> Status {
    SOFTID_ASSIGN_OR_RETURN(const Job job, LoadJob(job_id));
    SOFTID_RETURN_IF_ERROR(CheckTaskOwner(job, worker_id));
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement count, db_.Prepare("SELECT count(*) FROM start_tasks "
                                                               "WHERE job_id = ?1 AND batch = ''"));
    SOFTID_RETURN_IF_ERROR(count.Bind(job_id));
    SOFTID_RETURN_IF_ERROR(count.Step().status());
    SOFTID_RETURN_IF_ERROR(CheckExistingTasks(job_id, count.ColumnInt64(0), num_tasks));
    if (count.ColumnInt64(0) == num_tasks) return Status::Ok();
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement insert, db_.Prepare(R"sql(
        INSERT INTO start_tasks (job_id, idx, state, created_at) VALUES (?1, ?2, 'QUEUED', ?3))sql"));
    const int64_t now = ToUnixMicros(Now());
    for (int index = 0; index < num_tasks; ++index) {
      insert.Reset();
      SOFTID_RETURN_IF_ERROR(insert.Bind(job_id, index, now));
      SOFTID_RETURN_IF_ERROR(insert.Run());
    }
    return Status::Ok();
  });
}

Result<int> SqliteJobStore::CreateTaskBatch(const std::string& job_id, const std::string& worker_id,
                                            const std::string& batch,
                                            const std::vector<nlohmann::json>& inputs) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  SOFTID_RETURN_IF_ERROR(CheckWorkerId(worker_id));
  SOFTID_RETURN_IF_ERROR(CheckBatchName(batch));
  SOFTID_RETURN_IF_ERROR(CheckTaskCount(static_cast<int>(inputs.size())));
  return Write([&]() -> Result<int> {
    SOFTID_ASSIGN_OR_RETURN(const Job job, LoadJob(job_id));
    SOFTID_RETURN_IF_ERROR(CheckTaskOwner(job, worker_id));
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement existing, db_.Prepare(R"sql(
        SELECT count(*), coalesce(min(idx), -1),
               (SELECT coalesce(max(idx), -1) FROM start_tasks WHERE job_id = ?1)
        FROM start_tasks WHERE job_id = ?1 AND batch = ?2)sql"));
    SOFTID_RETURN_IF_ERROR(existing.Bind(job_id, batch));
    SOFTID_RETURN_IF_ERROR(existing.Step().status());
    const int num_tasks = static_cast<int>(inputs.size());
    SOFTID_RETURN_IF_ERROR(CheckExistingBatch(job_id, batch, existing.ColumnInt64(0), num_tasks));
    if (existing.ColumnInt64(0) == num_tasks) return static_cast<int>(existing.ColumnInt64(1));
    const int first = static_cast<int>(existing.ColumnInt64(2)) + 1;
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement insert, db_.Prepare(R"sql(
        INSERT INTO start_tasks (job_id, idx, state, created_at, batch, input)
        VALUES (?1, ?2, 'QUEUED', ?3, ?4, ?5))sql"));
    const int64_t now = ToUnixMicros(Now());
    for (int i = 0; i < num_tasks; ++i) {
      insert.Reset();
      SOFTID_RETURN_IF_ERROR(insert.Bind(job_id, first + i, now, batch, DumpJson(inputs[i])));
      SOFTID_RETURN_IF_ERROR(insert.Run());
    }
    return first;
  });
}

Result<std::optional<StartTask>> SqliteJobStore::ClaimStartTask(const std::string& worker_id,
                                                                std::chrono::milliseconds lease,
                                                                const std::string& job_id) {
  SOFTID_RETURN_IF_ERROR(CheckWorkerId(worker_id));
  SOFTID_RETURN_IF_ERROR(CheckLease(lease));
  if (!job_id.empty()) SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  return Write([&]() -> Result<std::optional<StartTask>> {
    const Timestamp now = Now();
    const Timestamp expires = now + std::chrono::duration_cast<std::chrono::microseconds>(lease);
    // Under BEGIN IMMEDIATE no other connection can take the same task in between.
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt, db_.Prepare(R"sql(
        UPDATE start_tasks
        SET state = 'RUNNING', attempts = attempts + 1, lease_owner = ?1, lease_expires_at = ?2
        WHERE (job_id, idx) = (
          SELECT t.job_id, t.idx FROM start_tasks t JOIN jobs j ON j.id = t.job_id
          WHERE j.state = 'RUNNING' AND j.cancel_requested = 0 AND (?3 = '' OR t.job_id = ?3)
            AND (t.state = 'QUEUED' OR (t.state = 'RUNNING' AND t.lease_expires_at <= ?4))
          ORDER BY j.created_at, t.job_id, t.idx LIMIT 1)
        RETURNING )sql" + std::string(kStartTaskColumns)));
    SOFTID_RETURN_IF_ERROR(stmt.Bind(worker_id, ToUnixMicros(expires), job_id, ToUnixMicros(now)));
    SOFTID_ASSIGN_OR_RETURN(const bool claimed, stmt.Step());
    if (!claimed) return std::optional<StartTask>();
    SOFTID_ASSIGN_OR_RETURN(StartTask task, ReadStartTask(stmt));
    SOFTID_ASSIGN_OR_RETURN(const bool more, stmt.Step());  // runs the statement to completion
    if (more) return Status::Internal("claim updated more than one start task");
    return std::optional<StartTask>(std::move(task));
  });
}

Status SqliteJobStore::RenewStartTask(const std::string& job_id, int index,
                                      const std::string& worker_id,
                                      std::chrono::milliseconds lease) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  SOFTID_RETURN_IF_ERROR(CheckWorkerId(worker_id));
  SOFTID_RETURN_IF_ERROR(CheckLease(lease));
  return Write([&]() -> Status {
    SOFTID_ASSIGN_OR_RETURN(const Job job, LoadJob(job_id));
    SOFTID_ASSIGN_OR_RETURN(const StartTask task, LoadStartTask(db_, job_id, index));
    SOFTID_RETURN_IF_ERROR(CheckTaskHeld(job, task, worker_id));
    const Timestamp expires = Now() + std::chrono::duration_cast<std::chrono::microseconds>(lease);
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt, db_.Prepare(R"sql(
        UPDATE start_tasks SET lease_expires_at = ?3 WHERE job_id = ?1 AND idx = ?2)sql"));
    SOFTID_RETURN_IF_ERROR(stmt.Bind(job_id, index, ToUnixMicros(expires)));
    return stmt.Run();
  });
}

Status SqliteJobStore::CompleteStartTask(const std::string& job_id, int index,
                                         const std::string& worker_id,
                                         const nlohmann::json& result) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  SOFTID_RETURN_IF_ERROR(CheckWorkerId(worker_id));
  return Write([&]() -> Status {
    SOFTID_ASSIGN_OR_RETURN(const Job job, LoadJob(job_id));
    SOFTID_ASSIGN_OR_RETURN(const StartTask task, LoadStartTask(db_, job_id, index));
    SOFTID_RETURN_IF_ERROR(CheckTaskHeld(job, task, worker_id));
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt, db_.Prepare(R"sql(
        UPDATE start_tasks SET state = 'DONE', result = ?3, lease_owner = NULL,
                               lease_expires_at = NULL
        WHERE job_id = ?1 AND idx = ?2)sql"));
    SOFTID_RETURN_IF_ERROR(stmt.Bind(job_id, index, DumpJson(result)));
    return stmt.Run();
  });
}

Status SqliteJobStore::ReleaseStartTask(const std::string& job_id, int index,
                                        const std::string& worker_id) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  SOFTID_RETURN_IF_ERROR(CheckWorkerId(worker_id));
  return Write([&]() -> Status {
    SOFTID_ASSIGN_OR_RETURN(const StartTask task, LoadStartTask(db_, job_id, index));
    SOFTID_RETURN_IF_ERROR(CheckTaskLease(task, worker_id));
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt, db_.Prepare(R"sql(
        UPDATE start_tasks SET state = 'QUEUED', lease_owner = NULL, lease_expires_at = NULL
        WHERE job_id = ?1 AND idx = ?2)sql"));
    SOFTID_RETURN_IF_ERROR(stmt.Bind(job_id, index));
    return stmt.Run();
  });
}

Result<std::vector<StartTask>> SqliteJobStore::ListStartTasks(const std::string& job_id) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  return Read([&]() -> Result<std::vector<StartTask>> {
    SOFTID_RETURN_IF_ERROR(LoadJob(job_id).status());
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt,
                            db_.Prepare("SELECT " + std::string(kStartTaskColumns) +
                                        " FROM start_tasks WHERE job_id = ?1 ORDER BY idx"));
    SOFTID_RETURN_IF_ERROR(stmt.Bind(job_id));
    std::vector<StartTask> tasks;
    while (true) {
      SOFTID_ASSIGN_OR_RETURN(const bool has_row, stmt.Step());
      if (!has_row) break;
      SOFTID_ASSIGN_OR_RETURN(StartTask task, ReadStartTask(stmt));
      tasks.push_back(std::move(task));
    }
    return tasks;
  });
}

Result<RecoverySummary> SqliteJobStore::RecoverAfterCrash(int max_attempts, RecoveryScope scope) {
  SOFTID_RETURN_IF_ERROR(CheckMaxAttempts(max_attempts));
  return Write([&]() -> Result<RecoverySummary> {
    const Timestamp now = Now();
    std::vector<Job> lost;
    {
      std::string sql = "SELECT " + std::string(kJobColumns) + " FROM jobs WHERE state = 'RUNNING'";
      if (scope == RecoveryScope::kExpiredLeasesOnly) sql += " AND lease_expires_at <= ?1";
      sql += " ORDER BY created_at, id";
      SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt, db_.Prepare(sql));
      if (scope == RecoveryScope::kExpiredLeasesOnly) {
        SOFTID_RETURN_IF_ERROR(stmt.Bind(ToUnixMicros(now)));
      }
      while (true) {
        SOFTID_ASSIGN_OR_RETURN(const bool has_row, stmt.Step());
        if (!has_row) break;
        SOFTID_ASSIGN_OR_RETURN(Job job, ReadJob(stmt));
        lost.push_back(std::move(job));
      }
    }

    RecoverySummary summary;
    for (Job& job : lost) {
      const RecoveryVerdict verdict = DecideRecovery(job, max_attempts, scope);
      std::string sql;
      if (verdict.state == JobState::kCancelled) {
        sql = "UPDATE jobs SET state = 'CANCELLED', finished_at = ?2";
        ++summary.num_cancelled;
      } else if (verdict.state == JobState::kFailed) {
        sql = "UPDATE jobs SET state = 'FAILED', finished_at = ?2, error = ?3";
        ++summary.num_failed;
      } else {
        sql = "UPDATE jobs SET state = 'QUEUED'";
        ++summary.num_requeued;
      }
      job.state = verdict.state;
      job.error = verdict.error;
      sql += ", lease_owner = NULL, lease_expires_at = NULL WHERE id = ?1";
      SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt, db_.Prepare(sql));
      if (job.state == JobState::kQueued) {
        SOFTID_RETURN_IF_ERROR(stmt.Bind(job.id));
      } else if (job.state == JobState::kCancelled) {
        SOFTID_RETURN_IF_ERROR(stmt.Bind(job.id, ToUnixMicros(now)));
      } else {
        SOFTID_RETURN_IF_ERROR(stmt.Bind(job.id, ToUnixMicros(now), job.error));
      }
      SOFTID_RETURN_IF_ERROR(stmt.Run());
      SOFTID_RETURN_IF_ERROR(AppendStateEvent(job, verdict.message, now).status());
    }
    return summary;
  });
}

// --- Tokens --------------------------------------------------------------------------------------

namespace {

constexpr std::string_view kTokenColumns =
    "id, station, admin, secret_sha256, created_at, expires_at, revoked_at";

ApiToken ReadToken(const SqliteStatement& row) {
  ApiToken token;
  token.id = row.ColumnText(0);
  token.station = row.ColumnText(1);
  token.admin = row.ColumnInt64(2) != 0;
  token.secret_sha256 = row.ColumnText(3);
  token.created_at = FromUnixMicros(row.ColumnInt64(4));
  token.expires_at = OptionalTimestamp(row.ColumnOptionalInt64(5));
  token.revoked_at = OptionalTimestamp(row.ColumnOptionalInt64(6));
  return token;
}

}  // namespace

Result<ApiToken> SqliteJobStore::CreateToken(const std::string& station, bool admin,
                                             std::optional<Timestamp> expires_at,
                                             const std::string& secret_sha256) {
  SOFTID_RETURN_IF_ERROR(ValidateStationName(station));
  if (!Sha256::IsValidHex(secret_sha256)) {
    return json::Invalid("secret_sha256", secret_sha256, "must be 64 lowercase hex digits");
  }
  return Write([&]() -> Result<ApiToken> {
    ApiToken token;
    token.id = NewResourceId(kTokenIdPrefix);
    token.station = station;
    token.admin = admin;
    token.secret_sha256 = secret_sha256;
    token.created_at = Now();
    token.expires_at = expires_at;
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt,
                            db_.Prepare("INSERT INTO tokens (" + std::string(kTokenColumns) +
                                        ") VALUES (?1, ?2, ?3, ?4, ?5, ?6, NULL)"));
    std::optional<int64_t> expires;
    if (expires_at.has_value()) expires = ToUnixMicros(*expires_at);
    SOFTID_RETURN_IF_ERROR(stmt.Bind(token.id, station, int64_t{admin ? 1 : 0}, secret_sha256,
                                     ToUnixMicros(token.created_at), expires));
    SOFTID_RETURN_IF_ERROR(stmt.Run());
    return token;
  });
}

Result<std::optional<ApiToken>> SqliteJobStore::FindToken(const std::string& secret_sha256) {
  return Read([&]() -> Result<std::optional<ApiToken>> {
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt,
                            db_.Prepare("SELECT " + std::string(kTokenColumns) +
                                        " FROM tokens WHERE secret_sha256 = ?1"));
    SOFTID_RETURN_IF_ERROR(stmt.Bind(secret_sha256));
    SOFTID_ASSIGN_OR_RETURN(const bool found, stmt.Step());
    if (!found) return std::optional<ApiToken>();
    return std::optional<ApiToken>(ReadToken(stmt));
  });
}

Result<std::vector<ApiToken>> SqliteJobStore::ListTokens() {
  return Read([&]() -> Result<std::vector<ApiToken>> {
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt,
                            db_.Prepare("SELECT " + std::string(kTokenColumns) +
                                        " FROM tokens ORDER BY created_at, id"));
    std::vector<ApiToken> tokens;
    while (true) {
      SOFTID_ASSIGN_OR_RETURN(const bool has_row, stmt.Step());
      if (!has_row) break;
      tokens.push_back(ReadToken(stmt));
    }
    return tokens;
  });
}

Status SqliteJobStore::RevokeToken(const std::string& token_id) {
  SOFTID_RETURN_IF_ERROR(CheckResourceId(token_id, kTokenIdPrefix, "token id"));
  return Write([&]() -> Status {
    SOFTID_ASSIGN_OR_RETURN(
        SqliteStatement stmt,
        db_.Prepare("UPDATE tokens SET revoked_at = COALESCE(revoked_at, ?2) WHERE id = ?1 "
                    "RETURNING id"));
    SOFTID_RETURN_IF_ERROR(stmt.Bind(token_id, ToUnixMicros(Now())));
    SOFTID_ASSIGN_OR_RETURN(const bool found, stmt.Step());
    if (!found) return Status::NotFound("token " + token_id + " not found");
    SOFTID_ASSIGN_OR_RETURN(const bool more, stmt.Step());
    (void)more;
    return Status::Ok();
  });
}

}  // namespace softid::server::store
