#include "server/store/sqlite_database.h"

#include <spdlog/spdlog.h>
#include <sqlite3.h>

#include <cmath>
#include <utility>

namespace softid::server::store {
namespace {

// SQL is quoted in messages; very long statements are cut so the message stays readable.
std::string Abbreviate(std::string_view sql) {
  constexpr size_t kMaxChars = 120;
  std::string out(sql.substr(0, kMaxChars));
  for (char& c : out) {
    if (c == '\n' || c == '\t') c = ' ';
  }
  if (sql.size() > kMaxChars) out += "...";
  return out;
}

// Disk and lock problems are outside the caller's control (IoError); everything else (a constraint
// the store did not anticipate, bad SQL, misuse) is a bug in the store (Internal).
StatusCode CodeFor(int result_code) {
  switch (result_code & 0xff) {
    case SQLITE_BUSY:
    case SQLITE_LOCKED:
    case SQLITE_IOERR:
    case SQLITE_CORRUPT:
    case SQLITE_FULL:
    case SQLITE_CANTOPEN:
    case SQLITE_READONLY:
    case SQLITE_NOTADB:
    case SQLITE_PERM:
    case SQLITE_PROTOCOL: return StatusCode::kIoError;
    default: return StatusCode::kInternal;
  }
}

}  // namespace

// --- SqliteDatabase ------------------------------------------------------------------------------

Result<SqliteDatabase> SqliteDatabase::Open(const std::filesystem::path& path,
                                            const SqliteOptions& options) {
  int flags = SQLITE_OPEN_READWRITE | SQLITE_OPEN_NOMUTEX;  // callers serialise access
  if (options.open_mode == OpenMode::kCreateIfMissing) flags |= SQLITE_OPEN_CREATE;
  sqlite3* raw = nullptr;
  const int rc = sqlite3_open_v2(path.c_str(), &raw, flags, nullptr);
  if (rc != SQLITE_OK) {
    // A handle is returned even on failure (unless out of memory) and must be closed.
    std::string message = raw != nullptr ? sqlite3_errmsg(raw) : sqlite3_errstr(rc);
    sqlite3_close_v2(raw);
    const StatusCode code =
        (rc & 0xff) == SQLITE_CANTOPEN && options.open_mode == OpenMode::kMustExist
            ? StatusCode::kNotFound
            : CodeFor(rc);
    return Status(code, path.string() + ": cannot open database: " + message);
  }
  SqliteDatabase db(raw, path,
                    options.logger != nullptr ? options.logger : spdlog::default_logger());
  // Extended codes name the exact failure (SQLITE_IOERR_FSYNC rather than SQLITE_IOERR).
  sqlite3_extended_result_codes(raw, 1);
  // busy_timeout first: switching to WAL itself needs a lock another process may hold.
  const int busy_rc = sqlite3_busy_timeout(raw, static_cast<int>(options.busy_timeout.count()));
  if (busy_rc != SQLITE_OK) return db.Error(busy_rc, "set busy_timeout");

  // journal_mode answers with the mode actually in effect; a read-only or in-memory database may
  // refuse WAL, and we want to know rather than silently run with a rollback journal.
  SOFTID_ASSIGN_OR_RETURN(SqliteStatement journal, db.Prepare("PRAGMA journal_mode=WAL"));
  SOFTID_ASSIGN_OR_RETURN(const bool has_row, journal.Step());
  if (!has_row || journal.ColumnText(0) != "wal") {
    return Status::IoError(path.string() + ": cannot switch to WAL journal mode (got '" +
                           (has_row ? journal.ColumnText(0) : std::string()) + "')");
  }
  journal.Reset();
  SOFTID_RETURN_IF_ERROR(db.Exec(options.sync_mode == SyncMode::kFull
                                     ? "PRAGMA synchronous=FULL"
                                     : "PRAGMA synchronous=NORMAL"));
  SOFTID_RETURN_IF_ERROR(db.Exec("PRAGMA foreign_keys=ON"));
  return db;
}

SqliteDatabase::SqliteDatabase(sqlite3* db, std::filesystem::path path,
                               std::shared_ptr<spdlog::logger> logger)
    : db_(db), path_(std::move(path)), logger_(std::move(logger)) {}

SqliteDatabase::SqliteDatabase(SqliteDatabase&& other) noexcept
    : db_(std::exchange(other.db_, nullptr)),
      path_(std::move(other.path_)),
      logger_(std::move(other.logger_)) {}

SqliteDatabase& SqliteDatabase::operator=(SqliteDatabase&& other) noexcept {
  if (this != &other) {
    // Close our own handle first: Nix's move-assignment leaked it.
    CloseOrDefer();
    db_ = std::exchange(other.db_, nullptr);
    path_ = std::move(other.path_);
    logger_ = std::move(other.logger_);
  }
  return *this;
}

SqliteDatabase::~SqliteDatabase() {
  CloseOrDefer();
}

void SqliteDatabase::CloseOrDefer() {
  const Status closed = Close();
  if (closed.ok()) return;
  if (logger_ != nullptr) logger_->warn("{}", closed.ToString());
  // Do not leak the handle: _v2 defers the close until the last statement is finalised.
  sqlite3_close_v2(std::exchange(db_, nullptr));
}

Status SqliteDatabase::Close() {
  if (db_ == nullptr) return Status::Ok();
  // sqlite3_close (not _v2) fails with SQLITE_BUSY instead of deferring when statements are still
  // alive, which surfaces a leaked statement instead of hiding it.
  const int rc = sqlite3_close(db_);
  if (rc == SQLITE_BUSY) {
    return Status::Internal(path_.string() + ": close: a prepared statement is still alive");
  }
  if (rc != SQLITE_OK) return Error(rc, "close");
  db_ = nullptr;
  return Status::Ok();
}

Status SqliteDatabase::Exec(std::string_view sql) {
  if (db_ == nullptr) return Status::FailedPrecondition(path_.string() + ": database is closed");
  const std::string text(sql);
  const int rc = sqlite3_exec(db_, text.c_str(), nullptr, nullptr, nullptr);
  if (rc != SQLITE_OK) return Error(rc, "exec", sql);
  return Status::Ok();
}

Result<SqliteStatement> SqliteDatabase::Prepare(std::string_view sql) {
  if (db_ == nullptr) return Status::FailedPrecondition(path_.string() + ": database is closed");
  sqlite3_stmt* stmt = nullptr;
  const int rc = sqlite3_prepare_v2(db_, sql.data(), static_cast<int>(sql.size()), &stmt, nullptr);
  if (rc != SQLITE_OK) {
    sqlite3_finalize(stmt);
    return Error(rc, "prepare", sql);
  }
  return SqliteStatement(this, stmt);
}

int64_t SqliteDatabase::changes() const {
  return sqlite3_changes64(db_);
}

bool SqliteDatabase::autocommit() const {
  return sqlite3_get_autocommit(db_) != 0;
}

Status SqliteDatabase::Error(int result_code, std::string_view action, std::string_view sql) const {
  std::string message = path_.string() + ": " + std::string(action);
  if (!sql.empty()) message += " `" + Abbreviate(sql) + "`";
  // The connection's message is only about this error if the code matches (another call on the
  // same connection may have overwritten it); fall back to the generic text otherwise.
  const bool fresh = db_ != nullptr && sqlite3_extended_errcode(db_) == result_code;
  message += ": ";
  message += fresh ? sqlite3_errmsg(db_) : sqlite3_errstr(result_code);
  return Status(CodeFor(result_code), std::move(message));
}

// --- SqliteStatement -----------------------------------------------------------------------------

SqliteStatement::SqliteStatement(SqliteStatement&& other) noexcept
    : db_(other.db_), stmt_(std::exchange(other.stmt_, nullptr)) {}

SqliteStatement& SqliteStatement::operator=(SqliteStatement&& other) noexcept {
  if (this != &other) {
    sqlite3_finalize(stmt_);
    db_ = other.db_;
    stmt_ = std::exchange(other.stmt_, nullptr);
  }
  return *this;
}

// sqlite3_finalize only repeats the last step's error, which Step() already reported.
SqliteStatement::~SqliteStatement() {
  sqlite3_finalize(stmt_);
}

Status SqliteStatement::BindOne(int index, int64_t value) {
  const int rc = sqlite3_bind_int64(stmt_, index, value);
  return rc == SQLITE_OK ? Status::Ok() : db_->Error(rc, "bind", sql());
}

Status SqliteStatement::BindOne(int index, double value) {
  const int rc = std::isnan(value) ? sqlite3_bind_null(stmt_, index)
                                   : sqlite3_bind_double(stmt_, index, value);
  return rc == SQLITE_OK ? Status::Ok() : db_->Error(rc, "bind", sql());
}

Status SqliteStatement::BindOne(int index, std::string_view value) {
  // SQLITE_TRANSIENT: SQLite copies the text, so temporaries are safe to bind.
  const int rc =
      sqlite3_bind_text64(stmt_, index, value.data(), value.size(), SQLITE_TRANSIENT, SQLITE_UTF8);
  return rc == SQLITE_OK ? Status::Ok() : db_->Error(rc, "bind", sql());
}

Status SqliteStatement::BindOne(int index, std::nullopt_t) {
  const int rc = sqlite3_bind_null(stmt_, index);
  return rc == SQLITE_OK ? Status::Ok() : db_->Error(rc, "bind", sql());
}

Result<bool> SqliteStatement::Step() {
  const int rc = sqlite3_step(stmt_);
  if (rc == SQLITE_ROW) return true;
  if (rc == SQLITE_DONE) return false;
  return db_->Error(rc, "step", sql());
}

Status SqliteStatement::Run() {
  SOFTID_ASSIGN_OR_RETURN(const bool has_row, Step());
  if (has_row) {
    return Status::Internal(db_->path().string() + ": `" + Abbreviate(sql()) +
                            "` returned a row where none was expected");
  }
  return Status::Ok();
}

void SqliteStatement::Reset() {
  sqlite3_reset(stmt_);
  sqlite3_clear_bindings(stmt_);
}

bool SqliteStatement::IsNull(int index) const {
  return sqlite3_column_type(stmt_, index) == SQLITE_NULL;
}

int64_t SqliteStatement::ColumnInt64(int index) const {
  return sqlite3_column_int64(stmt_, index);
}

double SqliteStatement::ColumnDouble(int index) const {
  return IsNull(index) ? std::nan("") : sqlite3_column_double(stmt_, index);
}

std::string SqliteStatement::ColumnText(int index) const {
  const auto* text = reinterpret_cast<const char*>(sqlite3_column_text(stmt_, index));
  if (text == nullptr) return {};
  return std::string(text, static_cast<size_t>(sqlite3_column_bytes(stmt_, index)));
}

std::optional<int64_t> SqliteStatement::ColumnOptionalInt64(int index) const {
  if (IsNull(index)) return std::nullopt;
  return ColumnInt64(index);
}

std::optional<std::string> SqliteStatement::ColumnOptionalText(int index) const {
  if (IsNull(index)) return std::nullopt;
  return ColumnText(index);
}

std::string_view SqliteStatement::sql() const {
  const char* text = stmt_ != nullptr ? sqlite3_sql(stmt_) : nullptr;
  return text != nullptr ? std::string_view(text) : std::string_view();
}

// --- SqliteTransaction ---------------------------------------------------------------------------

Result<SqliteTransaction> SqliteTransaction::Begin(SqliteDatabase& db, TransactionMode mode) {
  SOFTID_RETURN_IF_ERROR(
      db.Exec(mode == TransactionMode::kImmediate ? "BEGIN IMMEDIATE" : "BEGIN"));
  return SqliteTransaction(&db);
}

SqliteTransaction::SqliteTransaction(SqliteTransaction&& other) noexcept
    : db_(std::exchange(other.db_, nullptr)) {}

SqliteTransaction::~SqliteTransaction() {
  if (db_ == nullptr) return;
  const Status rolled_back = Rollback();
  if (!rolled_back.ok()) db_->logger().warn("{}", rolled_back.ToString());
}

Status SqliteTransaction::Commit() {
  if (db_ == nullptr) return Status::FailedPrecondition("transaction already finished");
  const Status committed = db_->Exec("COMMIT");
  if (!committed.ok()) {
    // A failed COMMIT (e.g. SQLITE_FULL) may leave the transaction open; roll it back so the
    // connection is usable again, and report the commit error.
    if (!db_->autocommit()) (void)db_->Exec("ROLLBACK");
    db_ = nullptr;
    return committed;
  }
  db_ = nullptr;
  return Status::Ok();
}

Status SqliteTransaction::Rollback() {
  if (db_ == nullptr) return Status::FailedPrecondition("transaction already finished");
  SqliteDatabase* db = std::exchange(db_, nullptr);
  // SQLite rolls back by itself after some errors (SQLITE_FULL, SQLITE_IOERR, ...); a second
  // ROLLBACK would then fail with "no transaction is active".
  if (db->autocommit()) return Status::Ok();
  return db->Exec("ROLLBACK");
}

}  // namespace softid::server::store
