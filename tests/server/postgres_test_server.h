// The PostgreSQL server of the tests: tests/server/with_postgres.sh starts one and passes its URL
// in SOFTID_TEST_POSTGRES_URL. Each test gets a database of its own (TestDatabase), so tests never
// see each other's rows. Without the variable the PostgreSQL tests skip (PostgresUnavailable).
#pragma once

#include <algorithm>
#include <cstdlib>
#include <functional>
#include <iomanip>
#include <optional>
#include <sstream>
#include <string>

#include "server/store/postgres_connection.h"

namespace softid::server::store::testing {

inline constexpr const char* kPostgresUrlVariable = "SOFTID_TEST_POSTGRES_URL";

// The server's URL (a database the tests may connect to for administration), or nullopt.
inline std::optional<std::string> TestPostgresUrl() {
  const char* url = std::getenv(kPostgresUrlVariable);
  if (url == nullptr || *url == '\0') return std::nullopt;
  return std::string(url);
}

// Why the PostgreSQL tests cannot run here, or nullopt when they can.
inline std::optional<std::string> PostgresUnavailable() {
  if (TestPostgresUrl().has_value()) return std::nullopt;
  return std::string(kPostgresUrlVariable) +
         " is not set: run the PostgreSQL tests through tests/server/with_postgres.sh (ctest does; "
         "it needs postgresql-15)";
}

// `url` with its database replaced by `database`.
inline std::string WithDatabase(const std::string& url, const std::string& database) {
  const size_t authority = url.find("://") + 3;
  const size_t query = url.find('?', authority);
  size_t path = url.find('/', authority);
  if (path == std::string::npos || (query != std::string::npos && path > query)) path = query;
  const std::string tail = query == std::string::npos ? "" : url.substr(query);
  return url.substr(0, std::min(path, url.size())) + "/" + database + tail;
}

// "softid_t_" and 16 hex digits of `key`'s hash: safe to splice into DDL, which takes no
// parameters.
inline std::string TestDatabaseName(const std::string& key) {
  std::ostringstream name;
  name << "softid_t_" << std::hex << std::setw(16) << std::setfill('0')
       << std::hash<std::string>{}(key);
  return name.str();
}

// A database named after `key` (so the same key finds the same database again), created on first
// use; its URL.
inline Result<std::string> TestDatabase(const std::string& key) {
  const std::optional<std::string> admin_url = TestPostgresUrl();
  if (!admin_url.has_value()) return Status::FailedPrecondition(*PostgresUnavailable());
  const std::string name = TestDatabaseName(key);
  SOFTID_ASSIGN_OR_RETURN(PostgresConnection admin, PostgresConnection::Connect(*admin_url));
  SOFTID_ASSIGN_OR_RETURN(PostgresResult found,
                          admin.Query("SELECT 1 FROM pg_database WHERE datname = $1", name));
  if (found.rows() == 0) SOFTID_RETURN_IF_ERROR(admin.Exec("CREATE DATABASE " + name));
  return WithDatabase(*admin_url, name);
}

// Drops the database TestDatabase(key) made, closing connections still open to it.
inline Status DropTestDatabase(const std::string& key) {
  const std::optional<std::string> admin_url = TestPostgresUrl();
  if (!admin_url.has_value()) return Status::Ok();
  const std::string name = TestDatabaseName(key);
  SOFTID_ASSIGN_OR_RETURN(PostgresConnection admin, PostgresConnection::Connect(*admin_url));
  return admin.Exec("DROP DATABASE IF EXISTS " + name + " WITH (FORCE)");
}

}  // namespace softid::server::store::testing
