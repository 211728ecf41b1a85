// A small RAII layer over the raw sqlite3 C API (after NixOS/nix src/libstore/sqlite.hh): a
// connection, prepared statements and a transaction guard. No ORM: callers write SQL.
//
// Errors come back as Status and carry the action, the SQL, SQLite's own message and the database
// path, e.g. "jobs.db: step `INSERT INTO jobs ...`: UNIQUE constraint failed: jobs.id".
// The sqlite3 types are forward-declared so that includers do not see the C API.
#pragma once

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <type_traits>

#include "core/common/status.h"

struct sqlite3;
struct sqlite3_stmt;

namespace spdlog {
class logger;
}

namespace softid::server::store {

// How hard a commit pushes data to stable storage (PRAGMA synchronous).
enum class SyncMode {
  // In WAL mode a commit survives a crash of the process but the last commits may be lost on
  // power failure; the database is never corrupted. SQLite's recommended setting for WAL.
  kNormal,
  // Every commit is fsynced before it returns: survives power loss, costs one fsync per commit.
  kFull,
};

enum class OpenMode {
  kCreateIfMissing,
  kMustExist,
};

struct SqliteOptions {
  OpenMode open_mode = OpenMode::kCreateIfMissing;
  SyncMode sync_mode = SyncMode::kNormal;
  // How long a statement waits for another connection's write lock before failing with
  // SQLITE_BUSY. Writers hold the lock for one short transaction (well under 10 ms), so 5 s only
  // runs out when something is badly stuck.
  std::chrono::milliseconds busy_timeout{5000};
  // Receives warnings that cannot be returned as a Status (a rollback failing in a destructor).
  // Null means spdlog's default logger.
  std::shared_ptr<spdlog::logger> logger;
};

class SqliteStatement;

// One open connection, in WAL mode with foreign keys enforced. Movable, not copyable.
// Not thread-safe: use it from one thread at a time (SqliteJobStore serialises its calls).
class SqliteDatabase {
 public:
  // Opens (or creates) the database and applies the per-connection settings: journal_mode=WAL,
  // synchronous, busy_timeout, foreign_keys=ON.
  static Result<SqliteDatabase> Open(const std::filesystem::path& path,
                                     const SqliteOptions& options = {});

  SqliteDatabase(SqliteDatabase&& other) noexcept;
  SqliteDatabase& operator=(SqliteDatabase&& other) noexcept;
  SqliteDatabase(const SqliteDatabase&) = delete;
  SqliteDatabase& operator=(const SqliteDatabase&) = delete;
  // Closes the connection; a failure is logged (use Close() to see it).
  ~SqliteDatabase();

  // Closes the connection, finalising nothing on its behalf: every SqliteStatement must have been
  // destroyed first (else Internal, and the connection stays open). Idempotent.
  Status Close();
  bool is_open() const { return db_ != nullptr; }

  // Runs one or more statements that bind no parameters (DDL, PRAGMAs).
  Status Exec(std::string_view sql);
  Result<SqliteStatement> Prepare(std::string_view sql);
  // Rows changed by the most recent INSERT/UPDATE/DELETE on this connection.
  int64_t changes() const;
  // True when no transaction is open.
  bool autocommit() const;

  const std::filesystem::path& path() const { return path_; }
  spdlog::logger& logger() const { return *logger_; }

  // A Status for the SQLite error `result_code` just returned by this connection, with the
  // action and SQL that failed.
  Status Error(int result_code, std::string_view action, std::string_view sql = {}) const;

 private:
  SqliteDatabase(sqlite3* db, std::filesystem::path path, std::shared_ptr<spdlog::logger> logger);
  // Close() for destructors: logs a failure and hands the handle to sqlite3_close_v2.
  void CloseOrDefer();

  sqlite3* db_ = nullptr;
  std::filesystem::path path_;
  std::shared_ptr<spdlog::logger> logger_;
};

// A prepared statement. It must not outlive its SqliteDatabase, nor be used after that database
// object was moved. Parameters are bound in order with Bind(...), then Step() walks the rows;
// Reset() makes it reusable. Movable, not copyable; finalised on destruction.
class SqliteStatement {
 public:
  SqliteStatement(SqliteStatement&& other) noexcept;
  SqliteStatement& operator=(SqliteStatement&& other) noexcept;
  SqliteStatement(const SqliteStatement&) = delete;
  SqliteStatement& operator=(const SqliteStatement&) = delete;
  ~SqliteStatement();

  // Binds parameters ?1, ?2, ... in order. Accepted: integral types, double (NaN is stored as
  // NULL, which is SQLite's own behaviour made explicit), string-like values (bound as TEXT),
  // std::nullopt and std::optional of those.
  template <typename... Args>
  Status Bind(const Args&... args) {
    int index = 1;
    Status status;
    ((status.ok() ? (void)(status = BindOne(index++, args)) : (void)0), ...);
    return status;
  }

  // Advances to the next row: true when a row is available, false when done.
  Result<bool> Step();
  // Steps a statement that must produce no rows (INSERT/UPDATE/DELETE without RETURNING).
  Status Run();
  // Resets the statement and clears its bindings so it can run again.
  void Reset();

  // Column accessors for the current row; `index` counts from 0.
  bool IsNull(int index) const;
  int64_t ColumnInt64(int index) const;
  // NULL reads back as NaN (see Bind).
  double ColumnDouble(int index) const;
  std::string ColumnText(int index) const;
  std::optional<int64_t> ColumnOptionalInt64(int index) const;
  std::optional<std::string> ColumnOptionalText(int index) const;

  std::string_view sql() const;

 private:
  friend class SqliteDatabase;
  SqliteStatement(const SqliteDatabase* db, sqlite3_stmt* stmt) : db_(db), stmt_(stmt) {}

  Status BindOne(int index, int64_t value);
  Status BindOne(int index, double value);
  Status BindOne(int index, std::string_view value);
  Status BindOne(int index, std::nullopt_t);
  Status BindOne(int index, const std::string& value) {
    return BindOne(index, std::string_view(value));
  }
  Status BindOne(int index, const char* value) { return BindOne(index, std::string_view(value)); }
  template <typename T>
  requires std::is_integral_v<T> Status BindOne(int index, T value) {
    return BindOne(index, static_cast<int64_t>(value));
  }
  template <typename T>
  Status BindOne(int index, const std::optional<T>& value) {
    return value.has_value() ? BindOne(index, *value) : BindOne(index, std::nullopt);
  }

  const SqliteDatabase* db_ = nullptr;
  sqlite3_stmt* stmt_ = nullptr;
};

enum class TransactionMode {
  // BEGIN IMMEDIATE: takes the write lock up front, so a read-then-write transaction waits
  // (busy_timeout) instead of failing at once with SQLITE_BUSY when it later tries to write, as a
  // deferred transaction would. Use for every transaction that may write.
  kImmediate,
  // BEGIN (deferred): a consistent snapshot for several reads without blocking writers (WAL).
  // Only for transactions that never write.
  kReadOnly,
};

// BEGIN ... COMMIT, rolled back on destruction unless committed.
class SqliteTransaction {
 public:
  static Result<SqliteTransaction> Begin(SqliteDatabase& db,
                                         TransactionMode mode = TransactionMode::kImmediate);

  SqliteTransaction(SqliteTransaction&& other) noexcept;
  SqliteTransaction& operator=(SqliteTransaction&&) = delete;
  SqliteTransaction(const SqliteTransaction&) = delete;
  SqliteTransaction& operator=(const SqliteTransaction&) = delete;
  // Rolls back if neither Commit() nor Rollback() ran; a failed rollback is logged.
  ~SqliteTransaction();

  Status Commit();
  Status Rollback();

 private:
  explicit SqliteTransaction(SqliteDatabase* db) : db_(db) {}

  SqliteDatabase* db_ = nullptr;  // null once committed or rolled back
};

}  // namespace softid::server::store
