#include "server/store/postgres_job_store.h"

#include <spdlog/spdlog.h>

#include <cmath>
#include <thread>
#include <utility>

#include "core/common/json_fields.h"
#include "server/store/job_rules.h"
#include "server/store/page_token.h"
#include "server/store/postgres_schema.h"
#include "server/store/resource_id.h"
#include "server/store/sha256.h"
#include "server/store/start_task.h"

namespace softid::server::store {
namespace {

constexpr std::string_view kJobColumns =
    "id, station_request_id, capture_id, config, state, cancel_requested, attempts, error, "
    "created_at, started_at, finished_at, lease_owner, lease_expires_at, result, "
    "released_attempts, owner, derived_capture_id";

constexpr std::string_view kProgressColumns =
    "seq, attempt, event, iteration, cost, gradient_norm, parameters, elapsed_s, state, message, "
    "created_at, start, num_starts, remaining_s";

constexpr std::string_view kTokenColumns =
    "id, station, admin, secret_sha256, created_at, expires_at, revoked_at";

// Namespaces of the two-key advisory locks (pg_advisory_xact_lock(int, int)); the second key is a
// hash, and two keys that collide only make their creates wait for each other.
constexpr int kCaptureRequestLock = 1;  // (owner, request id) of a capture being created
constexpr int kJobRequestLock = 2;      // (owner, request id) of a job being created
constexpr int kQueueLock = 3;           // the queue, while a bounded create counts it

// A transaction that lost a race is tried again up to this many times in all.
constexpr int kMaxTransactionAttempts = 8;

// Reads row `r` of a result selected with kJobColumns.
Result<Job> ReadJob(const PostgresResult& rows, int r) {
  Job job;
  job.id = rows.Text(r, 0);
  job.request_id = rows.Text(r, 1);
  job.capture_id = rows.Text(r, 2);
  SOFTID_ASSIGN_OR_RETURN(job.config, ParseStoredJson(rows.Text(r, 3), "jobs.config"));
  SOFTID_ASSIGN_OR_RETURN(job.state, JobStateFromString(rows.Text(r, 4)));
  job.cancel_requested = rows.Bool(r, 5);
  job.attempts = static_cast<int>(rows.Int64(r, 6));
  job.error = rows.Text(r, 7);
  job.created_at = FromUnixMicros(rows.Int64(r, 8));
  job.started_at = OptionalTimestamp(rows.OptionalInt64(r, 9));
  job.finished_at = OptionalTimestamp(rows.OptionalInt64(r, 10));
  job.lease_owner = rows.Text(r, 11);
  job.lease_expires_at = OptionalTimestamp(rows.OptionalInt64(r, 12));
  if (!rows.IsNull(r, 13)) {
    SOFTID_ASSIGN_OR_RETURN(job.result, ParseStoredJson(rows.Text(r, 13), "jobs.result"));
  }
  job.released_attempts = static_cast<int>(rows.Int64(r, 14));
  job.owner = rows.Text(r, 15);
  job.derived_capture_id = rows.Text(r, 16);
  return job;
}

// Reads row `r` of a result selected with kProgressColumns.
Result<ProgressEvent> ReadProgress(const PostgresResult& rows, int r) {
  ProgressEvent event;
  event.seq = rows.Int64(r, 0);
  event.attempt = static_cast<int>(rows.Int64(r, 1));
  SOFTID_ASSIGN_OR_RETURN(event.kind, ProgressKindFromString(rows.Text(r, 2)));
  event.iteration = static_cast<int>(rows.Int64(r, 3));
  event.cost = rows.Double(r, 4);
  event.gradient_norm = rows.Double(r, 5);
  if (!rows.IsNull(r, 6)) {
    SOFTID_ASSIGN_OR_RETURN(event.parameters,
                            ParseStoredJson(rows.Text(r, 6), "progress.parameters"));
  }
  event.elapsed_s = rows.Double(r, 7);
  if (!rows.IsNull(r, 8)) {
    SOFTID_ASSIGN_OR_RETURN(event.state, JobStateFromString(rows.Text(r, 8)));
  }
  event.message = rows.Text(r, 9);
  event.created_at = FromUnixMicros(rows.Int64(r, 10));
  event.start = static_cast<int>(rows.Int64(r, 11));
  event.num_starts = static_cast<int>(rows.Int64(r, 12));
  event.remaining_s = rows.Double(r, 13);
  return event;
}

// Reads row `r` of a result selected with kTokenColumns.
ApiToken ReadToken(const PostgresResult& rows, int r) {
  ApiToken token;
  token.id = rows.Text(r, 0);
  token.station = rows.Text(r, 1);
  token.admin = rows.Bool(r, 2);
  token.secret_sha256 = rows.Text(r, 3);
  token.created_at = FromUnixMicros(rows.Int64(r, 4));
  token.expires_at = OptionalTimestamp(rows.OptionalInt64(r, 5));
  token.revoked_at = OptionalTimestamp(rows.OptionalInt64(r, 6));
  return token;
}

// Reads a capture from columns id, station_request_id, manifest, created_at, owner, format
// starting at `first`.
Result<Capture> ReadCapture(const PostgresResult& rows, int r, int first = 0) {
  Capture capture;
  capture.id = rows.Text(r, first);
  capture.request_id = rows.Text(r, first + 1);
  SOFTID_ASSIGN_OR_RETURN(const nlohmann::json manifest,
                          ParseStoredJson(rows.Text(r, first + 2), "captures.manifest"));
  SOFTID_ASSIGN_OR_RETURN(capture.manifest, ManifestFromJson(manifest));
  capture.created_at = FromUnixMicros(rows.Int64(r, first + 3));
  capture.owner = rows.Text(r, first + 4);
  capture.format = rows.Text(r, first + 5);
  return capture;
}

constexpr std::string_view kCaptureColumns =
    "id, station_request_id, manifest, created_at, owner, format";

// The first column of every row.
std::vector<std::string> Column0(const PostgresResult& rows) {
  std::vector<std::string> out;
  out.reserve(static_cast<size_t>(rows.rows()));
  for (int r = 0; r < rows.rows(); ++r) out.push_back(rows.Text(r, 0));
  return out;
}

// Appends `value` to `params` and returns its placeholder ("$3"), for SQL whose filters depend on
// the request: PostgreSQL wants every parameter it is sent to appear in the statement.
template <typename T>
std::string Placeholder(PostgresParams& params, const T& value) {
  params.Add(value);
  std::string placeholder = "$";
  placeholder += std::to_string(params.values().size());
  return placeholder;
}

constexpr std::string_view kStartTaskColumns =
    "job_id, idx, state, attempts, lease_owner, lease_expires_at, result, batch, input";

// Reads row `r` of a result selected with kStartTaskColumns.
Result<StartTask> ReadStartTask(const PostgresResult& rows, int r) {
  StartTask task;
  task.job_id = rows.Text(r, 0);
  task.index = static_cast<int>(rows.Int64(r, 1));
  SOFTID_ASSIGN_OR_RETURN(task.state, StartTaskStateFromString(rows.Text(r, 2)));
  task.attempts = static_cast<int>(rows.Int64(r, 3));
  task.lease_owner = rows.Text(r, 4);
  task.lease_expires_at = OptionalTimestamp(rows.OptionalInt64(r, 5));
  if (!rows.IsNull(r, 6)) {
    SOFTID_ASSIGN_OR_RETURN(task.result, ParseStoredJson(rows.Text(r, 6), "start_tasks.result"));
  }
  task.batch = rows.Text(r, 7);
  if (!rows.IsNull(r, 8)) {
    SOFTID_ASSIGN_OR_RETURN(task.input, ParseStoredJson(rows.Text(r, 8), "start_tasks.input"));
  }
  return task;
}

// The task, locked until the transaction ends.
Result<StartTask> LoadStartTaskForUpdate(PostgresConnection& db, const std::string& job_id,
                                         int index) {
  SOFTID_ASSIGN_OR_RETURN(
      PostgresResult rows,
      db.Query("SELECT " + std::string(kStartTaskColumns) +
                   " FROM start_tasks WHERE job_id = $1 AND idx = $2 FOR UPDATE",
               job_id, index));
  if (rows.rows() == 0) {
    return Status::NotFound("start task " + std::to_string(index) + " of job " + job_id +
                            " not found");
  }
  return ReadStartTask(rows, 0);
}

bool IsRetriable(const std::string& sqlstate) {
  return sqlstate == kSqlStateSerializationFailure || sqlstate == kSqlStateDeadlockDetected;
}

// --- Helpers used inside transactions ------------------------------------------------------------

enum class RowLock { kNone, kForUpdate };

Result<Job> LoadJob(PostgresConnection& db, const std::string& job_id, RowLock lock) {
  SOFTID_ASSIGN_OR_RETURN(
      PostgresResult rows,
      db.Query("SELECT " + std::string(kJobColumns) + " FROM jobs WHERE id = $1" +
                   (lock == RowLock::kForUpdate ? " FOR UPDATE" : ""),
               job_id));
  if (rows.rows() == 0) return Status::NotFound("job " + job_id + " not found");
  return ReadJob(rows, 0);
}

// NotFound unless the capture exists. Locks it FOR KEY SHARE: it cannot be deleted until this
// transaction ends, and a job inserted for it is visible to the delete's check.
Status LockCaptureForReference(PostgresConnection& db, const std::string& capture_id) {
  SOFTID_ASSIGN_OR_RETURN(
      PostgresResult rows,
      db.Query("SELECT 1 FROM captures WHERE id = $1 FOR KEY SHARE", capture_id));
  if (rows.rows() == 0) return Status::NotFound("capture " + capture_id + " not found");
  return Status::Ok();
}

// Serialises the creates that use the same (owner, request_id) until this transaction ends.
Status LockRequestId(PostgresConnection& db, int lock_namespace, const std::string& owner,
                     const std::string& request_id) {
  return db
      .Query("SELECT pg_advisory_xact_lock($1::integer, hashtext($2))", lock_namespace,
             owner + "\n" + request_id)
      .status();
}

Result<std::optional<Capture>> FindCaptureByRequestId(PostgresConnection& db,
                                                      const std::string& request_id,
                                                      const std::string& owner) {
  SOFTID_ASSIGN_OR_RETURN(
      PostgresResult rows,
      db.Query("SELECT " + std::string(kCaptureColumns) +
                   " FROM captures WHERE owner = $1 AND station_request_id = $2",
               owner, request_id));
  if (rows.rows() == 0) return std::optional<Capture>();
  SOFTID_ASSIGN_OR_RETURN(Capture capture, ReadCapture(rows, 0));
  return std::optional<Capture>(std::move(capture));
}

Result<std::optional<Job>> FindJobByRequestId(PostgresConnection& db, const std::string& request_id,
                                              const std::string& owner) {
  SOFTID_ASSIGN_OR_RETURN(PostgresResult rows,
                          db.Query("SELECT " + std::string(kJobColumns) +
                                       " FROM jobs WHERE owner = $1 AND station_request_id = $2",
                                   owner, request_id));
  if (rows.rows() == 0) return std::optional<Job>();
  SOFTID_ASSIGN_OR_RETURN(Job job, ReadJob(rows, 0));
  return std::optional<Job>(std::move(job));
}

// Records a state change (or a worker's note) in the job's progress history. The caller holds the
// job's row lock (or created the job in this transaction), so the next seq is its alone.
Result<int64_t> AppendStateEvent(PostgresConnection& db, const Job& job, const std::string& message,
                                 Timestamp now) {
  // seq continues the job's history; iteration repeats the latest iteration event's, so that
  // ListProgress(from_iteration = N) includes the state changes that followed iteration N.
  SOFTID_ASSIGN_OR_RETURN(PostgresResult rows,
                          db.Query(R"sql(
      INSERT INTO progress (job_id, seq, attempt, event, iteration, elapsed_s, state, message,
                            created_at)
      VALUES ($1,
              (SELECT COALESCE(MAX(seq), 0) + 1 FROM progress WHERE job_id = $1),
              $2, 'state',
              COALESCE((SELECT iteration FROM progress WHERE job_id = $1 AND event = 'iteration'
                        ORDER BY seq DESC LIMIT 1), 0),
              $3, $4, $5, $6)
      RETURNING seq)sql",
                                   job.id, job.attempts, ElapsedSeconds(job, now),
                                   ToString(job.state), message, ToUnixMicros(now)));
  if (rows.rows() != 1) return Status::Internal("INSERT ... RETURNING seq returned no row");
  return rows.Int64(0, 0);
}

}  // namespace

// --- The connection pool -------------------------------------------------------------------------

// Up to max_connections connections, opened when calls need them. A connection that broke (the
// server restarted) is dropped when it comes back, and the next call opens a new one.
class PostgresJobStore::Pool {
 public:
  Pool(std::string url, int max_connections) : url_(std::move(url)), max_(max_connections) {}

  // A connection of the caller's own, waiting while max_connections are in use.
  Result<PostgresConnection> Acquire() {
    {
      std::unique_lock lock(mutex_);
      returned_.wait(lock, [&] { return closed_ || !idle_.empty() || open_ < max_; });
      if (closed_) return Status::FailedPrecondition(RedactPostgresUrl(url_) + ": store is closed");
      if (!idle_.empty()) {
        PostgresConnection connection = std::move(idle_.back());
        idle_.pop_back();
        return connection;
      }
      ++open_;
    }
    Result<PostgresConnection> connection = PostgresConnection::Connect(url_);
    if (!connection.ok()) Forget();
    return connection;
  }

  void Release(PostgresConnection connection) {
    std::unique_lock lock(mutex_);
    if (closed_ || !connection.healthy() || connection.in_transaction()) {
      lock.unlock();
      connection.Close();
      Forget();
      return;
    }
    idle_.push_back(std::move(connection));
    returned_.notify_one();
  }

  // Closes the idle connections now and the others as they come back; Acquire fails from now on.
  void Close() {
    std::vector<PostgresConnection> idle;
    {
      std::lock_guard lock(mutex_);
      closed_ = true;
      idle.swap(idle_);
      open_ -= static_cast<int>(idle.size());
    }
    returned_.notify_all();
  }

 private:
  // One connection fewer is open (it failed to open or was closed).
  void Forget() {
    std::lock_guard lock(mutex_);
    --open_;
    returned_.notify_one();
  }

  const std::string url_;  // with its password: needed to open more connections
  const int max_;
  std::mutex mutex_;
  std::condition_variable returned_;
  std::vector<PostgresConnection> idle_;
  int open_ = 0;  // idle plus in use
  bool closed_ = false;
};

// --- Opening and plumbing ------------------------------------------------------------------------

Result<std::unique_ptr<PostgresJobStore>> PostgresJobStore::Open(
    const std::string& url, const PostgresJobStoreOptions& options) {
  if (options.max_connections < 1) {
    return Status::InvalidArgument("max_connections = " + std::to_string(options.max_connections) +
                                   ": must be at least 1");
  }
  auto pool = std::make_unique<Pool>(url, options.max_connections);
  {
    SOFTID_ASSIGN_OR_RETURN(PostgresConnection first, pool->Acquire());
    const Status migrated = MigratePostgresSchema(first);
    pool->Release(std::move(first));
    SOFTID_RETURN_IF_ERROR(migrated);
  }
  Clock clock =
      options.clock ? options.clock : Clock([] { return std::chrono::system_clock::now(); });
  std::shared_ptr<spdlog::logger> logger =
      options.logger != nullptr ? options.logger : spdlog::default_logger();
  return std::unique_ptr<PostgresJobStore>(new PostgresJobStore(
      std::move(pool), RedactPostgresUrl(url), std::move(clock), std::move(logger)));
}

PostgresJobStore::PostgresJobStore(std::unique_ptr<Pool> pool, std::string where, Clock clock,
                                   std::shared_ptr<spdlog::logger> logger)
    : pool_(std::move(pool)),
      where_(std::move(where)),
      clock_(std::move(clock)),
      logger_(std::move(logger)) {}

PostgresJobStore::~PostgresJobStore() {
  pool_->Close();
}

Status PostgresJobStore::Close() {
  pool_->Close();
  return Status::Ok();
}

Timestamp PostgresJobStore::Now() const {
  return ToTimestamp(clock_());
}

template <typename Fn>
auto PostgresJobStore::Transact(bool write, Fn&& fn)
    -> decltype(fn(std::declval<PostgresConnection&>())) {
  const std::string_view begin = write ? "BEGIN ISOLATION LEVEL READ COMMITTED"
                                       : "BEGIN ISOLATION LEVEL REPEATABLE READ READ ONLY";
  for (int attempt = 1;; ++attempt) {
    SOFTID_ASSIGN_OR_RETURN(PostgresConnection db, pool_->Acquire());
    if (Status begun = db.Exec(begin); !begun.ok()) {
      // An idle connection the server closed (a restart) fails here, before anything was done:
      // safe to try again on a new one.
      const bool broken = !db.healthy();
      pool_->Release(std::move(db));
      if (broken && attempt < kMaxTransactionAttempts) continue;
      return begun;
    }
    auto result = fn(db);
    Status ended = result.ok() ? db.Exec("COMMIT") : db.Exec("ROLLBACK");
    const std::string sqlstate = db.last_sqlstate();
    pool_->Release(std::move(db));
    // A serialization failure or deadlock shows in the statement that failed, or at COMMIT.
    const bool lost_race = (!result.ok() || !ended.ok()) && IsRetriable(sqlstate);
    if (lost_race && attempt < kMaxTransactionAttempts) {
      logger_->debug("{}: transaction lost a race (SQLSTATE {}), attempt {}", where_, sqlstate,
                     attempt);
      std::this_thread::sleep_for(std::chrono::milliseconds(attempt * attempt));
      continue;
    }
    if (!result.ok()) return result;
    SOFTID_RETURN_IF_ERROR(ended);
    return result;
  }
}

template <typename Fn>
auto PostgresJobStore::Write(Fn&& fn) -> decltype(fn(std::declval<PostgresConnection&>())) {
  return Transact(/*write=*/true, std::forward<Fn>(fn));
}

template <typename Fn>
auto PostgresJobStore::Read(Fn&& fn) -> decltype(fn(std::declval<PostgresConnection&>())) {
  return Transact(/*write=*/false, std::forward<Fn>(fn));
}

// --- Captures ------------------------------------------------------------------------------------

Result<Capture> PostgresJobStore::CreateCapture(const std::vector<ManifestEntry>& manifest,
                                                const std::string& request_id,
                                                const std::string& owner, std::string_view format) {
  SOFTID_RETURN_IF_ERROR(ValidateManifest(manifest));
  if (format != kCaptureFormat && format != kRecordingFormat) {
    return json::Invalid("format", std::string(format),
                         "must be \"softid-capture/1\" or \"softid-recording/1\"");
  }
  SOFTID_RETURN_IF_ERROR(CheckRequestId(request_id));
  return Write([&](PostgresConnection& db) -> Result<Capture> {
    if (!request_id.empty()) {
      SOFTID_RETURN_IF_ERROR(LockRequestId(db, kCaptureRequestLock, owner, request_id));
      SOFTID_ASSIGN_OR_RETURN(std::optional<Capture> existing,
                              FindCaptureByRequestId(db, request_id, owner));
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
    SOFTID_RETURN_IF_ERROR(db.Query("INSERT INTO captures (" + std::string(kCaptureColumns) +
                                        ") VALUES ($1, $2, $3, $4, $5, $6)",
                                    capture.id, NullIfEmpty(request_id),
                                    DumpJson(ManifestToJson(manifest)),
                                    ToUnixMicros(capture.created_at), owner, capture.format)
                               .status());
    return capture;
  });
}

Result<Capture> PostgresJobStore::GetCapture(const std::string& capture_id) {
  SOFTID_RETURN_IF_ERROR(CheckResourceId(capture_id, kCaptureIdPrefix, "capture id"));
  return Read([&](PostgresConnection& db) -> Result<Capture> {
    SOFTID_ASSIGN_OR_RETURN(PostgresResult rows, db.Query("SELECT " + std::string(kCaptureColumns) +
                                                              " FROM captures WHERE id = $1",
                                                          capture_id));
    if (rows.rows() == 0) return Status::NotFound("capture " + capture_id + " not found");
    return ReadCapture(rows, 0);
  });
}

Result<Capture> PostgresJobStore::DeleteCapture(const std::string& capture_id) {
  SOFTID_RETURN_IF_ERROR(CheckResourceId(capture_id, kCaptureIdPrefix, "capture id"));
  return Write([&](PostgresConnection& db) -> Result<Capture> {
    // FOR UPDATE waits for creates that hold the capture FOR KEY SHARE; the check below then sees
    // the jobs they committed.
    SOFTID_ASSIGN_OR_RETURN(PostgresResult rows,
                            db.Query("SELECT " + std::string(kCaptureColumns) +
                                         " FROM captures WHERE id = $1 FOR UPDATE",
                                     capture_id));
    if (rows.rows() == 0) return Status::NotFound("capture " + capture_id + " not found");
    SOFTID_ASSIGN_OR_RETURN(Capture capture, ReadCapture(rows, 0));
    SOFTID_ASSIGN_OR_RETURN(
        PostgresResult users,
        db.Query("SELECT id FROM jobs WHERE capture_id = $1 OR derived_capture_id = $1 LIMIT 1",
                 capture_id));
    if (users.rows() > 0) {
      return Status::FailedPrecondition("capture " + capture_id + " is used by job " +
                                        users.Text(0, 0) + ": delete its jobs first");
    }
    SOFTID_RETURN_IF_ERROR(db.Query("DELETE FROM captures WHERE id = $1", capture_id).status());
    return capture;
  });
}

Result<CapturePage> PostgresJobStore::ListCaptures(const ListCapturesRequest& request) {
  SOFTID_RETURN_IF_ERROR(CheckPageSize(request.page_size));
  const int page_size = EffectivePageSize(request.page_size);
  // "captures" keeps a token of a job list from being used here.
  std::string filter = "captures";
  if (request.owner.has_value()) filter += "&owner=" + *request.owner;
  std::optional<PageCursor> after;
  if (!request.page_token.empty()) {
    SOFTID_ASSIGN_OR_RETURN(after, DecodePageToken(request.page_token, filter));
  }
  PostgresParams params;
  std::string sql = "SELECT " + std::string(kCaptureColumns) +
                    ", (SELECT count(*) FROM jobs WHERE jobs.capture_id = captures.id "
                    "OR jobs.derived_capture_id = captures.id) FROM captures WHERE TRUE";
  if (request.owner.has_value()) sql += " AND owner = " + Placeholder(params, *request.owner);
  if (after.has_value()) {
    sql += " AND (created_at, id) > (" + Placeholder(params, ToUnixMicros(after->created_at)) +
           "::bigint, " + Placeholder(params, after->id) + "::text)";
  }
  sql += " ORDER BY created_at, id LIMIT " + Placeholder(params, page_size + 1);

  return Read([&](PostgresConnection& db) -> Result<CapturePage> {
    SOFTID_ASSIGN_OR_RETURN(PostgresResult rows, db.Query(sql, params));
    CapturePage page;
    for (int r = 0; r < rows.rows(); ++r) {
      CaptureListing listing;
      SOFTID_ASSIGN_OR_RETURN(listing.capture, ReadCapture(rows, r));
      listing.num_jobs = rows.Int64(r, 6);
      page.captures.push_back(std::move(listing));
    }
    // One row more than the page tells whether another page follows.
    if (static_cast<int>(page.captures.size()) > page_size) {
      page.captures.pop_back();
      const Capture& last = page.captures.back().capture;
      page.next_page_token = EncodePageToken(PageCursor{last.created_at, last.id}, filter);
    }
    return page;
  });
}

Result<std::vector<std::string>> PostgresJobStore::ListUnusedCaptures(Timestamp created_before) {
  return Read([&](PostgresConnection& db) -> Result<std::vector<std::string>> {
    SOFTID_ASSIGN_OR_RETURN(PostgresResult rows, db.Query(R"sql(
        SELECT id FROM captures WHERE created_at < $1
          AND NOT EXISTS (SELECT 1 FROM jobs WHERE jobs.capture_id = captures.id
                                               OR jobs.derived_capture_id = captures.id)
        ORDER BY created_at, id)sql",
                                                          ToUnixMicros(created_before)));
    return Column0(rows);
  });
}

Result<std::vector<std::string>> PostgresJobStore::ListEndedJobs(Timestamp finished_before) {
  return Read([&](PostgresConnection& db) -> Result<std::vector<std::string>> {
    SOFTID_ASSIGN_OR_RETURN(PostgresResult rows, db.Query(R"sql(
        SELECT id FROM jobs WHERE state IN ('SUCCEEDED', 'FAILED', 'CANCELLED')
          AND finished_at < $1 ORDER BY finished_at, id)sql",
                                                          ToUnixMicros(finished_before)));
    return Column0(rows);
  });
}

Result<int64_t> PostgresJobStore::StoredBytes(const std::string& owner) {
  return Read([&](PostgresConnection& db) -> Result<int64_t> {
    SOFTID_ASSIGN_OR_RETURN(PostgresResult rows, db.Query(R"sql(
        SELECT COALESCE(SUM((file ->> 'size')::bigint), 0)::bigint
        FROM captures, json_array_elements(captures.manifest) AS file
        WHERE captures.owner = $1)sql",
                                                          owner));
    return rows.Int64(0, 0);
  });
}

// --- Jobs: API side ------------------------------------------------------------------------------

Result<Job> PostgresJobStore::CreateJob(const std::string& capture_id, const nlohmann::json& config,
                                        const std::string& request_id, const std::string& owner) {
  SOFTID_ASSIGN_OR_RETURN(std::optional<Job> job,
                          CreateJobIfRoom(capture_id, config, request_id, std::nullopt, owner));
  return *std::move(job);
}

Result<std::optional<Job>> PostgresJobStore::CreateJobBounded(const std::string& capture_id,
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

Result<std::optional<Job>> PostgresJobStore::CreateJobIfRoom(const std::string& capture_id,
                                                             const nlohmann::json& config,
                                                             const std::string& request_id,
                                                             std::optional<int64_t> max_queued,
                                                             const std::string& owner) {
  SOFTID_RETURN_IF_ERROR(CheckResourceId(capture_id, kCaptureIdPrefix, "capture id"));
  if (!config.is_object()) return json::Invalid("config", config, "must be a JSON object");
  SOFTID_RETURN_IF_ERROR(CheckRequestId(request_id));
  return Write([&](PostgresConnection& db) -> Result<std::optional<Job>> {
    if (!request_id.empty()) {
      SOFTID_RETURN_IF_ERROR(LockRequestId(db, kJobRequestLock, owner, request_id));
      SOFTID_ASSIGN_OR_RETURN(std::optional<Job> existing,
                              FindJobByRequestId(db, request_id, owner));
      if (existing.has_value()) {
        if (existing->capture_id != capture_id || existing->config != config) {
          return Status::FailedPrecondition(
              "request_id '" + request_id + "' was already used to create job " + existing->id +
              " with a different " + (existing->capture_id != capture_id ? "capture" : "config"));
        }
        return existing;
      }
    }
    SOFTID_RETURN_IF_ERROR(LockCaptureForReference(db, capture_id));
    if (max_queued.has_value()) {
      // Counted under the queue lock: no other bounded create can count or insert in between.
      SOFTID_RETURN_IF_ERROR(
          db.Query("SELECT pg_advisory_xact_lock($1::integer, 0)", kQueueLock).status());
      SOFTID_ASSIGN_OR_RETURN(PostgresResult count,
                              db.Query("SELECT count(*) FROM jobs WHERE state = 'QUEUED'"));
      if (count.Int64(0, 0) >= *max_queued) return std::optional<Job>();
    }
    Job job;
    job.id = NewResourceId(kJobIdPrefix);
    job.request_id = request_id;
    job.capture_id = capture_id;
    job.config = config;
    job.state = JobState::kQueued;
    job.created_at = Now();
    job.owner = owner;
    SOFTID_RETURN_IF_ERROR(db.Query(R"sql(
        INSERT INTO jobs (id, station_request_id, capture_id, config, state, created_at, owner)
        VALUES ($1, $2, $3, $4, 'QUEUED', $5, $6))sql",
                                    job.id, NullIfEmpty(request_id), capture_id, DumpJson(config),
                                    ToUnixMicros(job.created_at), owner)
                               .status());
    SOFTID_RETURN_IF_ERROR(AppendStateEvent(db, job, "created", job.created_at).status());
    return std::optional<Job>(std::move(job));
  });
}

Result<Job> PostgresJobStore::GetJob(const std::string& job_id) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  return Read([&](PostgresConnection& db) { return LoadJob(db, job_id, RowLock::kNone); });
}

Result<bool> PostgresJobStore::HasJobWithRequestId(const std::string& request_id,
                                                   const std::string& owner) {
  if (request_id.empty()) return false;
  return Read([&](PostgresConnection& db) -> Result<bool> {
    SOFTID_ASSIGN_OR_RETURN(std::optional<Job> job, FindJobByRequestId(db, request_id, owner));
    return job.has_value();
  });
}

Result<JobPage> PostgresJobStore::ListJobs(const ListJobsRequest& request) {
  SOFTID_RETURN_IF_ERROR(CheckPageSize(request.page_size));
  const int page_size = EffectivePageSize(request.page_size);
  std::string filter =
      request.state.has_value() ? std::string("state=") + ToString(*request.state) : "";
  if (request.owner.has_value()) filter += "&owner=" + *request.owner;
  std::optional<PageCursor> after;
  if (!request.page_token.empty()) {
    SOFTID_ASSIGN_OR_RETURN(after, DecodePageToken(request.page_token, filter));
  }
  // Only the filters asked for appear in the SQL, so the planner can walk the matching index.
  PostgresParams params;
  std::string sql = "SELECT " + std::string(kJobColumns) + " FROM jobs WHERE TRUE";
  if (request.state.has_value()) {
    sql += " AND state = " + Placeholder(params, std::string(ToString(*request.state)));
  }
  if (request.owner.has_value()) sql += " AND owner = " + Placeholder(params, *request.owner);
  if (after.has_value()) {
    sql += " AND (created_at, id) > (" + Placeholder(params, ToUnixMicros(after->created_at)) +
           "::bigint, " + Placeholder(params, after->id) + "::text)";
  }
  sql += " ORDER BY created_at, id LIMIT " + Placeholder(params, page_size + 1);

  return Read([&](PostgresConnection& db) -> Result<JobPage> {
    SOFTID_ASSIGN_OR_RETURN(PostgresResult rows, db.Query(sql, params));
    JobPage page;
    for (int r = 0; r < rows.rows(); ++r) {
      SOFTID_ASSIGN_OR_RETURN(Job job, ReadJob(rows, r));
      page.jobs.push_back(std::move(job));
    }
    // One row more than the page tells whether another page follows, so the last page never
    // hands out a token that leads to an empty page.
    if (static_cast<int>(page.jobs.size()) > page_size) {
      page.jobs.pop_back();
      const Job& last = page.jobs.back();
      page.next_page_token = EncodePageToken(PageCursor{last.created_at, last.id}, filter);
    }
    return page;
  });
}

Result<int64_t> PostgresJobStore::CountJobs(std::optional<JobState> state,
                                            std::optional<std::string> owner) {
  std::optional<std::string> state_text;
  if (state.has_value()) state_text = ToString(*state);
  return Read([&](PostgresConnection& db) -> Result<int64_t> {
    SOFTID_ASSIGN_OR_RETURN(PostgresResult rows, db.Query(R"sql(
        SELECT count(*) FROM jobs
        WHERE ($1::text IS NULL OR state = $1) AND ($2::text IS NULL OR owner = $2))sql",
                                                          state_text, owner));
    return rows.Int64(0, 0);
  });
}

Result<Job> PostgresJobStore::RequestCancel(const std::string& job_id) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  return Write([&](PostgresConnection& db) -> Result<Job> {
    SOFTID_ASSIGN_OR_RETURN(Job job, LoadJob(db, job_id, RowLock::kForUpdate));
    const Timestamp now = Now();
    switch (job.state) {
      case JobState::kQueued: {
        SOFTID_RETURN_IF_ERROR(
            db.Query("UPDATE jobs SET state = 'CANCELLED', finished_at = $2 WHERE id = $1", job_id,
                     ToUnixMicros(now))
                .status());
        job.state = JobState::kCancelled;
        job.finished_at = now;
        SOFTID_RETURN_IF_ERROR(AppendStateEvent(db, job, "cancelled while queued", now).status());
        return job;
      }
      case JobState::kRunning: {
        if (job.cancel_requested) return job;  // asked before: nothing new to record
        SOFTID_RETURN_IF_ERROR(
            db.Query("UPDATE jobs SET cancel_requested = TRUE WHERE id = $1", job_id).status());
        job.cancel_requested = true;
        SOFTID_RETURN_IF_ERROR(AppendStateEvent(db, job, "cancel requested", now).status());
        return job;
      }
      case JobState::kSucceeded:
      case JobState::kFailed:
      case JobState::kCancelled: break;
    }
    return WrongState(job, "a finished job cannot be cancelled");
  });
}

Status PostgresJobStore::DeleteJob(const std::string& job_id) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  return Write([&](PostgresConnection& db) -> Status {
    SOFTID_ASSIGN_OR_RETURN(const Job job, LoadJob(db, job_id, RowLock::kForUpdate));
    if (job.state == JobState::kRunning) {
      return WrongState(job, "cancel it and wait until it stops before deleting it");
    }
    // progress and checkpoints go with it (ON DELETE CASCADE).
    return db.Query("DELETE FROM jobs WHERE id = $1", job_id).status();
  });
}

// --- Jobs: worker side ---------------------------------------------------------------------------

Result<std::optional<Job>> PostgresJobStore::ClaimNextJob(const std::string& worker_id,
                                                          std::chrono::milliseconds lease) {
  SOFTID_RETURN_IF_ERROR(CheckWorkerId(worker_id));
  SOFTID_RETURN_IF_ERROR(CheckLease(lease));
  return Write([&](PostgresConnection& db) -> Result<std::optional<Job>> {
    const Timestamp now = Now();
    const Timestamp expires = now + std::chrono::duration_cast<std::chrono::microseconds>(lease);
    // The subquery locks the oldest QUEUED job that no other transaction holds (SKIP LOCKED: a
    // concurrent claimer takes the next one instead of waiting for this one), and the UPDATE takes
    // it; the row lock lasts until COMMIT.
    SOFTID_ASSIGN_OR_RETURN(PostgresResult rows,
                            db.Query(R"sql(
        UPDATE jobs
        SET state = 'RUNNING', attempts = attempts + 1, started_at = $1, lease_owner = $2,
            lease_expires_at = $3
        WHERE id = (SELECT id FROM jobs WHERE state = 'QUEUED' ORDER BY created_at, id LIMIT 1
                    FOR UPDATE SKIP LOCKED)
        RETURNING )sql" + std::string(kJobColumns),
                                     ToUnixMicros(now), worker_id, ToUnixMicros(expires)));
    if (rows.rows() == 0) return std::optional<Job>();
    if (rows.rows() > 1) return Status::Internal("claim updated more than one job");
    SOFTID_ASSIGN_OR_RETURN(Job job, ReadJob(rows, 0));
    // The worker's id (host and process) stays in the server's log: progress is shown to clients.
    SOFTID_RETURN_IF_ERROR(
        AppendStateEvent(db, job, "started (attempt " + std::to_string(job.attempts) + ")", now)
            .status());
    return std::optional<Job>(std::move(job));
  });
}

Status PostgresJobStore::RenewLease(const std::string& job_id, const std::string& worker_id,
                                    std::chrono::milliseconds lease) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  SOFTID_RETURN_IF_ERROR(CheckWorkerId(worker_id));
  SOFTID_RETURN_IF_ERROR(CheckLease(lease));
  return Write([&](PostgresConnection& db) -> Status {
    SOFTID_ASSIGN_OR_RETURN(const Job job, LoadJob(db, job_id, RowLock::kForUpdate));
    if (job.state != JobState::kRunning) return WrongState(job, "only a RUNNING job has a lease");
    if (job.lease_owner != worker_id) return NotLeasedTo(job, worker_id);
    const Timestamp expires = Now() + std::chrono::duration_cast<std::chrono::microseconds>(lease);
    return db
        .Query("UPDATE jobs SET lease_expires_at = $2 WHERE id = $1", job_id, ToUnixMicros(expires))
        .status();
  });
}

Result<int64_t> PostgresJobStore::AppendProgress(const std::string& job_id,
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
  return Write([&](PostgresConnection& db) -> Result<int64_t> {
    // The row lock makes this transaction the only one numbering the job's events.
    SOFTID_ASSIGN_OR_RETURN(const Job job, LoadJob(db, job_id, RowLock::kForUpdate));
    const Timestamp now = Now();
    if (event.kind == ProgressKind::kState) return AppendStateEvent(db, job, event.message, now);
    if (job.state != JobState::kRunning) {
      return WrongState(job, "iteration progress is only accepted while RUNNING");
    }
    std::optional<std::string> parameters;
    if (!event.parameters.is_null()) parameters = DumpJson(event.parameters);
    SOFTID_ASSIGN_OR_RETURN(
        PostgresResult rows,
        db.Query(R"sql(
        INSERT INTO progress (job_id, seq, attempt, event, iteration, cost, gradient_norm,
                              parameters, elapsed_s, message, created_at, start, num_starts,
                              remaining_s)
        VALUES ($1, (SELECT COALESCE(MAX(seq), 0) + 1 FROM progress WHERE job_id = $1),
                $2, 'iteration', $3, $4, $5, $6, $7, $8, $9, $10, $11, $12)
        RETURNING seq)sql",
                 job_id, job.attempts, event.iteration, event.cost, event.gradient_norm, parameters,
                 event.elapsed_s, event.message, ToUnixMicros(now), event.start, event.num_starts,
                 event.remaining_s));
    if (rows.rows() != 1) return Status::Internal("INSERT ... RETURNING seq returned no row");
    return rows.Int64(0, 0);
  });
}

Result<std::vector<ProgressEvent>> PostgresJobStore::ListProgress(const std::string& job_id,
                                                                  int from_iteration) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  return Read([&](PostgresConnection& db) -> Result<std::vector<ProgressEvent>> {
    SOFTID_RETURN_IF_ERROR(LoadJob(db, job_id, RowLock::kNone).status());
    SOFTID_ASSIGN_OR_RETURN(
        PostgresResult rows,
        db.Query("SELECT " + std::string(kProgressColumns) +
                     " FROM progress WHERE job_id = $1 AND iteration >= $2 ORDER BY seq",
                 job_id, from_iteration));
    std::vector<ProgressEvent> events;
    events.reserve(static_cast<size_t>(rows.rows()));
    for (int r = 0; r < rows.rows(); ++r) {
      SOFTID_ASSIGN_OR_RETURN(ProgressEvent event, ReadProgress(rows, r));
      events.push_back(std::move(event));
    }
    return events;
  });
}

Status PostgresJobStore::SaveCheckpoint(const std::string& job_id,
                                        const nlohmann::json& checkpoint) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  return Write([&](PostgresConnection& db) -> Status {
    SOFTID_ASSIGN_OR_RETURN(const Job job, LoadJob(db, job_id, RowLock::kForUpdate));
    if (job.state != JobState::kRunning) {
      return WrongState(job, "checkpoints are only accepted while RUNNING");
    }
    return db
        .Query(R"sql(
        INSERT INTO checkpoints (job_id, attempt, data, updated_at) VALUES ($1, $2, $3, $4)
        ON CONFLICT (job_id) DO UPDATE
        SET attempt = excluded.attempt, data = excluded.data,
            updated_at = excluded.updated_at)sql",
               job_id, job.attempts, DumpJson(checkpoint), ToUnixMicros(Now()))
        .status();
  });
}

Result<std::optional<nlohmann::json>> PostgresJobStore::LoadCheckpoint(const std::string& job_id) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  return Read([&](PostgresConnection& db) -> Result<std::optional<nlohmann::json>> {
    SOFTID_RETURN_IF_ERROR(LoadJob(db, job_id, RowLock::kNone).status());
    SOFTID_ASSIGN_OR_RETURN(PostgresResult rows,
                            db.Query("SELECT data FROM checkpoints WHERE job_id = $1", job_id));
    if (rows.rows() == 0) return std::optional<nlohmann::json>();
    SOFTID_ASSIGN_OR_RETURN(nlohmann::json data,
                            ParseStoredJson(rows.Text(0, 0), "checkpoints.data"));
    return std::optional<nlohmann::json>(std::move(data));
  });
}

Status PostgresJobStore::SetDerivedCapture(const std::string& job_id, const std::string& worker_id,
                                           const std::string& capture_id) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  SOFTID_RETURN_IF_ERROR(CheckWorkerId(worker_id));
  SOFTID_RETURN_IF_ERROR(CheckResourceId(capture_id, kCaptureIdPrefix, "capture id"));
  return Write([&](PostgresConnection& db) -> Status {
    SOFTID_ASSIGN_OR_RETURN(const Job job, LoadJob(db, job_id, RowLock::kForUpdate));
    if (job.state != JobState::kRunning) {
      return WrongState(job, "only a RUNNING job derives a capture");
    }
    if (job.lease_owner != worker_id) return NotLeasedTo(job, worker_id);
    SOFTID_RETURN_IF_ERROR(LockCaptureForReference(db, capture_id));
    return db.Query("UPDATE jobs SET derived_capture_id = $2 WHERE id = $1", job_id, capture_id)
        .status();
  });
}

Status PostgresJobStore::FinishRunningJob(PostgresConnection& db, Job& job, JobState state,
                                          const std::optional<nlohmann::json>& result,
                                          const std::string& error, const std::string& message) {
  const Timestamp now = Now();
  std::optional<std::string> result_text;
  if (result.has_value()) result_text = DumpJson(*result);
  // COALESCE keeps the error of a job that has one when none is given (SUCCEEDED, CANCELLED).
  SOFTID_RETURN_IF_ERROR(db.Query(R"sql(
      UPDATE jobs SET state = $2, finished_at = $3, result = COALESCE($4::json, result),
                      error = COALESCE($5, error), lease_owner = NULL, lease_expires_at = NULL
      WHERE id = $1)sql",
                                  job.id, std::string(ToString(state)), ToUnixMicros(now),
                                  result_text, NullIfEmpty(error))
                             .status());
  job.state = state;
  return AppendStateEvent(db, job, message, now).status();
}

Status PostgresJobStore::CompleteJob(const std::string& job_id, const nlohmann::json& result) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  return Write([&](PostgresConnection& db) -> Status {
    SOFTID_ASSIGN_OR_RETURN(Job job, LoadJob(db, job_id, RowLock::kForUpdate));
    if (job.state != JobState::kRunning) {
      return WrongState(job, "only a RUNNING job can be completed");
    }
    return FinishRunningJob(db, job, JobState::kSucceeded, result, "", "succeeded");
  });
}

Status PostgresJobStore::FailJob(const std::string& job_id, const std::string& error) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  if (error.empty()) return Status::InvalidArgument("error = '': a failed job needs a reason");
  return Write([&](PostgresConnection& db) -> Status {
    SOFTID_ASSIGN_OR_RETURN(Job job, LoadJob(db, job_id, RowLock::kForUpdate));
    if (job.state != JobState::kRunning) return WrongState(job, "only a RUNNING job can fail");
    return FinishRunningJob(db, job, JobState::kFailed, std::nullopt, error, error);
  });
}

Result<bool> PostgresJobStore::IsCancelRequested(const std::string& job_id) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  return Read([&](PostgresConnection& db) -> Result<bool> {
    SOFTID_ASSIGN_OR_RETURN(const Job job, LoadJob(db, job_id, RowLock::kNone));
    return job.cancel_requested || job.state == JobState::kCancelled;
  });
}

Status PostgresJobStore::MarkCancelled(const std::string& job_id) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  return Write([&](PostgresConnection& db) -> Status {
    SOFTID_ASSIGN_OR_RETURN(Job job, LoadJob(db, job_id, RowLock::kForUpdate));
    if (job.state != JobState::kRunning) {
      return WrongState(job, "only a RUNNING job can acknowledge a cancel");
    }
    if (!job.cancel_requested) {
      return WrongState(job, "no cancel was requested (use FailJob to stop for another reason)");
    }
    return FinishRunningJob(db, job, JobState::kCancelled, std::nullopt, "", "cancelled");
  });
}

Status PostgresJobStore::ReleaseJob(const std::string& job_id, const std::string& worker_id,
                                    const std::string& reason) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  SOFTID_RETURN_IF_ERROR(CheckWorkerId(worker_id));
  return Write([&](PostgresConnection& db) -> Status {
    SOFTID_ASSIGN_OR_RETURN(Job job, LoadJob(db, job_id, RowLock::kForUpdate));
    if (job.state != JobState::kRunning) return WrongState(job, "only a RUNNING job is released");
    if (job.lease_owner != worker_id) return NotLeasedTo(job, worker_id);
    if (job.cancel_requested) {
      // Running it again would only be cancelled again.
      return FinishRunningJob(
          db, job, JobState::kCancelled, std::nullopt, "",
          "cancelled: released (" + reason + ") after the cancel was requested");
    }
    SOFTID_RETURN_IF_ERROR(db.Query(R"sql(
        UPDATE jobs SET state = 'QUEUED', released_attempts = released_attempts + 1,
                        lease_owner = NULL, lease_expires_at = NULL
        WHERE id = $1)sql",
                                    job_id)
                               .status());
    job.state = JobState::kQueued;
    const std::string message = "requeued: " + reason + " during attempt " +
                                std::to_string(job.attempts) +
                                " (not counted against max_attempts)";
    return AppendStateEvent(db, job, message, Now()).status();
  });
}

// --- Maintenance ---------------------------------------------------------------------------------

Result<bool> PostgresJobStore::IsBlobReferenced(const std::string& sha256) {
  return Read([&](PostgresConnection& db) -> Result<bool> {
    // A scan of every manifest: only failed uploads ask, and they are rare.
    SOFTID_ASSIGN_OR_RETURN(PostgresResult rows, db.Query(R"sql(
        SELECT 1 FROM captures, json_array_elements(captures.manifest) AS file
        WHERE file ->> 'sha256' = $1 LIMIT 1)sql",
                                                          sha256));
    return rows.rows() > 0;
  });
}

Result<std::vector<std::string>> PostgresJobStore::ListReferencedBlobs() {
  return Read([&](PostgresConnection& db) -> Result<std::vector<std::string>> {
    SOFTID_ASSIGN_OR_RETURN(PostgresResult rows, db.Query(R"sql(
        SELECT DISTINCT file ->> 'sha256'
        FROM captures, json_array_elements(captures.manifest) AS file)sql"));
    return Column0(rows);
  });
}

// --- Start tasks -----------------------------------------------------------------------------

Status PostgresJobStore::CreateStartTasks(const std::string& job_id, const std::string& worker_id,
                                          int num_tasks) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  SOFTID_RETURN_IF_ERROR(CheckWorkerId(worker_id));
  SOFTID_RETURN_IF_ERROR(CheckTaskCount(num_tasks));
  return Write([&](PostgresConnection& db) -> Status {
    // The job's row lock orders this against another create and the job's transitions.
    SOFTID_ASSIGN_OR_RETURN(const Job job, LoadJob(db, job_id, RowLock::kForUpdate));
    SOFTID_RETURN_IF_ERROR(CheckTaskOwner(job, worker_id));
    SOFTID_ASSIGN_OR_RETURN(
        PostgresResult count,
        db.Query("SELECT count(*) FROM start_tasks WHERE job_id = $1 AND batch = ''", job_id));
    const int64_t existing = count.Int64(0, 0);
    SOFTID_RETURN_IF_ERROR(CheckExistingTasks(job_id, existing, num_tasks));
    if (existing == num_tasks) return Status::Ok();
    return db
        .Query(R"sql(
        INSERT INTO start_tasks (job_id, idx, state, created_at)
        SELECT $1, i, 'QUEUED', $3::bigint FROM generate_series(0, $2::integer - 1) AS i)sql",
               job_id, num_tasks, ToUnixMicros(Now()))
        .status();
  });
}

Result<int> PostgresJobStore::CreateTaskBatch(const std::string& job_id,
                                              const std::string& worker_id,
                                              const std::string& batch,
                                              const std::vector<nlohmann::json>& inputs) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  SOFTID_RETURN_IF_ERROR(CheckWorkerId(worker_id));
  SOFTID_RETURN_IF_ERROR(CheckBatchName(batch));
  SOFTID_RETURN_IF_ERROR(CheckTaskCount(static_cast<int>(inputs.size())));
  return Write([&](PostgresConnection& db) -> Result<int> {
    // The job's row lock orders this against another create and the job's transitions.
    SOFTID_ASSIGN_OR_RETURN(const Job job, LoadJob(db, job_id, RowLock::kForUpdate));
    SOFTID_RETURN_IF_ERROR(CheckTaskOwner(job, worker_id));
    SOFTID_ASSIGN_OR_RETURN(PostgresResult existing, db.Query(R"sql(
        SELECT count(*), coalesce(min(idx), -1),
               (SELECT coalesce(max(idx), -1) FROM start_tasks WHERE job_id = $1)
        FROM start_tasks WHERE job_id = $1 AND batch = $2)sql",
                                                              job_id, batch));
    const int num_tasks = static_cast<int>(inputs.size());
    SOFTID_RETURN_IF_ERROR(CheckExistingBatch(job_id, batch, existing.Int64(0, 0), num_tasks));
    if (existing.Int64(0, 0) == num_tasks) return static_cast<int>(existing.Int64(0, 1));
    const int first = static_cast<int>(existing.Int64(0, 2)) + 1;
    const int64_t now = ToUnixMicros(Now());
    for (int i = 0; i < num_tasks; ++i) {
      SOFTID_RETURN_IF_ERROR(db.Query(R"sql(
          INSERT INTO start_tasks (job_id, idx, state, created_at, batch, input)
          VALUES ($1, $2, 'QUEUED', $3, $4, $5))sql",
                                      job_id, first + i, now, batch, DumpJson(inputs[i]))
                                 .status());
    }
    return first;
  });
}

Result<std::optional<StartTask>> PostgresJobStore::ClaimStartTask(const std::string& worker_id,
                                                                  std::chrono::milliseconds lease,
                                                                  const std::string& job_id) {
  SOFTID_RETURN_IF_ERROR(CheckWorkerId(worker_id));
  SOFTID_RETURN_IF_ERROR(CheckLease(lease));
  if (!job_id.empty()) SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  return Write([&](PostgresConnection& db) -> Result<std::optional<StartTask>> {
    const Timestamp now = Now();
    const Timestamp expires = now + std::chrono::duration_cast<std::chrono::microseconds>(lease);
    // As ClaimNextJob: the subquery locks the first claimable task no other transaction holds,
    // the UPDATE takes it.
    SOFTID_ASSIGN_OR_RETURN(PostgresResult rows,
                            db.Query(R"sql(
        UPDATE start_tasks
        SET state = 'RUNNING', attempts = attempts + 1, lease_owner = $1, lease_expires_at = $2
        WHERE (job_id, idx) = (
          SELECT t.job_id, t.idx FROM start_tasks t JOIN jobs j ON j.id = t.job_id
          WHERE j.state = 'RUNNING' AND NOT j.cancel_requested AND ($3 = '' OR t.job_id = $3)
            AND (t.state = 'QUEUED' OR (t.state = 'RUNNING' AND t.lease_expires_at <= $4))
          ORDER BY j.created_at, t.job_id, t.idx LIMIT 1
          FOR UPDATE OF t SKIP LOCKED)
        RETURNING )sql" + std::string(kStartTaskColumns),
                                     worker_id, ToUnixMicros(expires), job_id, ToUnixMicros(now)));
    if (rows.rows() == 0) return std::optional<StartTask>();
    if (rows.rows() > 1) return Status::Internal("claim updated more than one start task");
    SOFTID_ASSIGN_OR_RETURN(StartTask task, ReadStartTask(rows, 0));
    return std::optional<StartTask>(std::move(task));
  });
}

Status PostgresJobStore::RenewStartTask(const std::string& job_id, int index,
                                        const std::string& worker_id,
                                        std::chrono::milliseconds lease) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  SOFTID_RETURN_IF_ERROR(CheckWorkerId(worker_id));
  SOFTID_RETURN_IF_ERROR(CheckLease(lease));
  return Write([&](PostgresConnection& db) -> Status {
    SOFTID_ASSIGN_OR_RETURN(const Job job, LoadJob(db, job_id, RowLock::kNone));
    SOFTID_ASSIGN_OR_RETURN(const StartTask task, LoadStartTaskForUpdate(db, job_id, index));
    SOFTID_RETURN_IF_ERROR(CheckTaskHeld(job, task, worker_id));
    const Timestamp expires = Now() + std::chrono::duration_cast<std::chrono::microseconds>(lease);
    return db
        .Query("UPDATE start_tasks SET lease_expires_at = $3 WHERE job_id = $1 AND idx = $2",
               job_id, index, ToUnixMicros(expires))
        .status();
  });
}

Status PostgresJobStore::CompleteStartTask(const std::string& job_id, int index,
                                           const std::string& worker_id,
                                           const nlohmann::json& result) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  SOFTID_RETURN_IF_ERROR(CheckWorkerId(worker_id));
  return Write([&](PostgresConnection& db) -> Status {
    SOFTID_ASSIGN_OR_RETURN(const Job job, LoadJob(db, job_id, RowLock::kNone));
    SOFTID_ASSIGN_OR_RETURN(const StartTask task, LoadStartTaskForUpdate(db, job_id, index));
    SOFTID_RETURN_IF_ERROR(CheckTaskHeld(job, task, worker_id));
    return db
        .Query(R"sql(
        UPDATE start_tasks SET state = 'DONE', result = $3, lease_owner = NULL,
                               lease_expires_at = NULL
        WHERE job_id = $1 AND idx = $2)sql",
               job_id, index, DumpJson(result))
        .status();
  });
}

Status PostgresJobStore::ReleaseStartTask(const std::string& job_id, int index,
                                          const std::string& worker_id) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  SOFTID_RETURN_IF_ERROR(CheckWorkerId(worker_id));
  return Write([&](PostgresConnection& db) -> Status {
    SOFTID_ASSIGN_OR_RETURN(const StartTask task, LoadStartTaskForUpdate(db, job_id, index));
    SOFTID_RETURN_IF_ERROR(CheckTaskLease(task, worker_id));
    return db
        .Query(R"sql(
        UPDATE start_tasks SET state = 'QUEUED', lease_owner = NULL, lease_expires_at = NULL
        WHERE job_id = $1 AND idx = $2)sql",
               job_id, index)
        .status();
  });
}

Result<std::vector<StartTask>> PostgresJobStore::ListStartTasks(const std::string& job_id) {
  SOFTID_RETURN_IF_ERROR(CheckJobId(job_id));
  return Read([&](PostgresConnection& db) -> Result<std::vector<StartTask>> {
    SOFTID_RETURN_IF_ERROR(LoadJob(db, job_id, RowLock::kNone).status());
    SOFTID_ASSIGN_OR_RETURN(PostgresResult rows,
                            db.Query("SELECT " + std::string(kStartTaskColumns) +
                                         " FROM start_tasks WHERE job_id = $1 ORDER BY idx",
                                     job_id));
    std::vector<StartTask> tasks;
    for (int r = 0; r < rows.rows(); ++r) {
      SOFTID_ASSIGN_OR_RETURN(StartTask task, ReadStartTask(rows, r));
      tasks.push_back(std::move(task));
    }
    return tasks;
  });
}

Result<RecoverySummary> PostgresJobStore::RecoverAfterCrash(int max_attempts, RecoveryScope scope) {
  SOFTID_RETURN_IF_ERROR(CheckMaxAttempts(max_attempts));
  return Write([&](PostgresConnection& db) -> Result<RecoverySummary> {
    const Timestamp now = Now();
    // Locked in one order (as every sweep does) so two sweeps cannot deadlock; a row whose worker
    // renewed or finished it while we waited for its lock no longer matches and is skipped.
    PostgresParams params;
    std::string sql = "SELECT " + std::string(kJobColumns) + " FROM jobs WHERE state = 'RUNNING'";
    if (scope == RecoveryScope::kExpiredLeasesOnly) {
      sql += " AND lease_expires_at <= " + Placeholder(params, ToUnixMicros(now));
    }
    sql += " ORDER BY created_at, id FOR UPDATE";
    SOFTID_ASSIGN_OR_RETURN(PostgresResult rows, db.Query(sql, params));

    RecoverySummary summary;
    for (int r = 0; r < rows.rows(); ++r) {
      SOFTID_ASSIGN_OR_RETURN(Job job, ReadJob(rows, r));
      const RecoveryVerdict verdict = DecideRecovery(job, max_attempts, scope);
      if (verdict.state == JobState::kCancelled) {
        ++summary.num_cancelled;
        SOFTID_RETURN_IF_ERROR(
            FinishRunningJob(db, job, JobState::kCancelled, std::nullopt, "", verdict.message));
      } else if (verdict.state == JobState::kFailed) {
        ++summary.num_failed;
        SOFTID_RETURN_IF_ERROR(FinishRunningJob(db, job, JobState::kFailed, std::nullopt,
                                                verdict.error, verdict.message));
      } else {
        ++summary.num_requeued;
        SOFTID_RETURN_IF_ERROR(db.Query("UPDATE jobs SET state = 'QUEUED', lease_owner = NULL, "
                                        "lease_expires_at = NULL WHERE id = $1",
                                        job.id)
                                   .status());
        job.state = JobState::kQueued;
        SOFTID_RETURN_IF_ERROR(AppendStateEvent(db, job, verdict.message, now).status());
      }
    }
    return summary;
  });
}

// --- Tokens --------------------------------------------------------------------------------------

Result<ApiToken> PostgresJobStore::CreateToken(const std::string& station, bool admin,
                                               std::optional<Timestamp> expires_at,
                                               const std::string& secret_sha256) {
  SOFTID_RETURN_IF_ERROR(ValidateStationName(station));
  if (!Sha256::IsValidHex(secret_sha256)) {
    return json::Invalid("secret_sha256", secret_sha256, "must be 64 lowercase hex digits");
  }
  return Write([&](PostgresConnection& db) -> Result<ApiToken> {
    ApiToken token;
    token.id = NewResourceId(kTokenIdPrefix);
    token.station = station;
    token.admin = admin;
    token.secret_sha256 = secret_sha256;
    token.created_at = Now();
    token.expires_at = expires_at;
    std::optional<int64_t> expires;
    if (expires_at.has_value()) expires = ToUnixMicros(*expires_at);
    SOFTID_RETURN_IF_ERROR(db.Query("INSERT INTO tokens (" + std::string(kTokenColumns) +
                                        ") VALUES ($1, $2, $3, $4, $5, $6, NULL)",
                                    token.id, station, admin, secret_sha256,
                                    ToUnixMicros(token.created_at), expires)
                               .status());
    return token;
  });
}

Result<std::optional<ApiToken>> PostgresJobStore::FindToken(const std::string& secret_sha256) {
  return Read([&](PostgresConnection& db) -> Result<std::optional<ApiToken>> {
    SOFTID_ASSIGN_OR_RETURN(
        PostgresResult rows,
        db.Query("SELECT " + std::string(kTokenColumns) + " FROM tokens WHERE secret_sha256 = $1",
                 secret_sha256));
    if (rows.rows() == 0) return std::optional<ApiToken>();
    return std::optional<ApiToken>(ReadToken(rows, 0));
  });
}

Result<std::vector<ApiToken>> PostgresJobStore::ListTokens() {
  return Read([&](PostgresConnection& db) -> Result<std::vector<ApiToken>> {
    SOFTID_ASSIGN_OR_RETURN(PostgresResult rows, db.Query("SELECT " + std::string(kTokenColumns) +
                                                          " FROM tokens ORDER BY created_at, id"));
    std::vector<ApiToken> tokens;
    for (int r = 0; r < rows.rows(); ++r) tokens.push_back(ReadToken(rows, r));
    return tokens;
  });
}

Status PostgresJobStore::RevokeToken(const std::string& token_id) {
  SOFTID_RETURN_IF_ERROR(CheckResourceId(token_id, kTokenIdPrefix, "token id"));
  return Write([&](PostgresConnection& db) -> Status {
    SOFTID_ASSIGN_OR_RETURN(
        PostgresResult rows,
        db.Query("UPDATE tokens SET revoked_at = COALESCE(revoked_at, $2) WHERE id = $1 "
                 "RETURNING id",
                 token_id, ToUnixMicros(Now())));
    if (rows.rows() == 0) return Status::NotFound("token " + token_id + " not found");
    return Status::Ok();
  });
}

}  // namespace softid::server::store
