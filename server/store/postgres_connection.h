// A small RAII layer over libpq (the PostgreSQL C client), in the manner of sqlite_database.h: a
// connection, the result of one command, and parameters passed apart from the SQL text
// (PQexecParams), so values never become part of a statement. No ORM: callers write SQL.
//
// Errors come back as Status and carry the action, the SQL, the server's message and its SQLSTATE,
// e.g. "postgres: query `INSERT INTO jobs ...`: duplicate key value violates unique constraint
// "jobs_pkey" (SQLSTATE 23505)". The libpq types are forward-declared so that includers do not see
// the C API. URLs in messages have their password replaced by "****" (RedactPostgresUrl).
#pragma once

#include <cmath>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include "core/common/status.h"

struct pg_conn;
struct pg_result;

namespace softid::server::store {

// `url` with the password (user:PASSWORD@ or a password= parameter) replaced by "****", for
// messages and logs.
std::string RedactPostgresUrl(std::string_view url);

// True for a postgresql:// or postgres:// URL (the forms RedactPostgresUrl understands).
bool IsPostgresUrl(std::string_view url);

// SQLSTATEs the store retries on: the transaction lost a race, not a bug.
inline constexpr std::string_view kSqlStateSerializationFailure = "40001";
inline constexpr std::string_view kSqlStateDeadlockDetected = "40P01";

// Parameters $1, $2, ... in text format; a NULL is std::nullopt. Doubles keep every bit (17
// significant digits); NaN becomes NULL, as the SQLite store stores it (and reads NULL back as
// NaN).
class PostgresParams {
 public:
  template <typename... Args>
  explicit PostgresParams(const Args&... args) {
    (Add(args), ...);
  }

  void Add(std::nullopt_t) { values_.emplace_back(std::nullopt); }
  void Add(bool value) { values_.emplace_back(value ? "true" : "false"); }
  void Add(double value);
  // PostgreSQL text holds neither NUL bytes nor invalid UTF-8 (in a UTF8 database): such bytes
  // are stored as U+FFFD rather than failing the call, as the SQLite store does for JSON.
  void Add(std::string_view value);
  void Add(const std::string& value) { Add(std::string_view(value)); }
  void Add(const char* value) { Add(std::string_view(value)); }
  template <typename T>
  requires(std::is_integral_v<T> && !std::is_same_v<T, bool>) void Add(T value) {
    values_.emplace_back(std::to_string(value));
  }
  template <typename T>
  void Add(const std::optional<T>& value) {
    if (value.has_value()) {
      Add(*value);
    } else {
      Add(std::nullopt);
    }
  }

  const std::vector<std::optional<std::string>>& values() const { return values_; }

 private:
  std::vector<std::optional<std::string>> values_;
};

// The rows of one command, in text format. Movable, not copyable; freed on destruction.
class PostgresResult {
 public:
  PostgresResult(PostgresResult&& other) noexcept;
  PostgresResult& operator=(PostgresResult&& other) noexcept;
  PostgresResult(const PostgresResult&) = delete;
  PostgresResult& operator=(const PostgresResult&) = delete;
  ~PostgresResult();

  int rows() const;
  // Rows an INSERT/UPDATE/DELETE changed (or a SELECT returned).
  int64_t affected_rows() const;

  // Column accessors; `row` and `column` count from 0. A value that does not parse as the type
  // asked for reads as 0 (the store only asks for columns whose SQL type it declared).
  bool IsNull(int row, int column) const;
  std::string Text(int row, int column) const;
  int64_t Int64(int row, int column) const;
  // NULL reads back as NaN (see PostgresParams).
  double Double(int row, int column) const;
  bool Bool(int row, int column) const;
  std::optional<int64_t> OptionalInt64(int row, int column) const;
  std::optional<std::string> OptionalText(int row, int column) const;

 private:
  friend class PostgresConnection;
  explicit PostgresResult(pg_result* result) : result_(result) {}

  pg_result* result_ = nullptr;
};

// One open connection. Movable, not copyable; closed on destruction. Not thread-safe: use it from
// one thread at a time (PostgresJobStore hands each call a connection of its own).
class PostgresConnection {
 public:
  // Connects to `url` (postgresql://user:password@host:port/database?param=value) and checks the
  // server speaks a version we support (>= 13). IoError naming the redacted URL when the server
  // cannot be reached or refuses us; InvalidArgument when libpq cannot parse the URL.
  static Result<PostgresConnection> Connect(const std::string& url);

  PostgresConnection(PostgresConnection&& other) noexcept;
  PostgresConnection& operator=(PostgresConnection&& other) noexcept;
  PostgresConnection(const PostgresConnection&) = delete;
  PostgresConnection& operator=(const PostgresConnection&) = delete;
  ~PostgresConnection();

  void Close();
  // False once closed, or when the server went away (the connection cannot be used again).
  bool healthy() const;
  // True while a transaction is open (or failed and not yet rolled back).
  bool in_transaction() const;

  // Runs one or more statements that take no parameters (DDL, BEGIN, COMMIT).
  Status Exec(std::string_view sql);
  // Runs one statement with `params` bound to $1, $2, ...
  Result<PostgresResult> Query(std::string_view sql,
                               const PostgresParams& params = PostgresParams());
  template <typename... Args>
  Result<PostgresResult> Query(std::string_view sql, const Args&... args) {
    return Query(sql, PostgresParams(args...));
  }

  // The SQLSTATE of the last command that failed on the server; empty after one that succeeded.
  const std::string& last_sqlstate() const { return last_sqlstate_; }
  // The redacted URL this connection was opened with.
  const std::string& where() const { return where_; }

 private:
  PostgresConnection(pg_conn* conn, std::string where) : conn_(conn), where_(std::move(where)) {}
  // Turns a finished command into OK or a Status naming `action` and `sql`; takes ownership.
  Result<PostgresResult> Check(pg_result* result, std::string_view action, std::string_view sql);

  pg_conn* conn_ = nullptr;
  std::string where_;
  std::string last_sqlstate_;
};

}  // namespace softid::server::store
