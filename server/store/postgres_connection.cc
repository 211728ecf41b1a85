#include "server/store/postgres_connection.h"

#include <libpq-fe.h>

#include <charconv>
#include <cstdio>
#include <cstdlib>
#include <utility>

namespace softid::server::store {
namespace {

constexpr std::string_view kRedacted = "****";

// SQL is quoted in messages; very long statements are cut so the message stays readable.
std::string Abbreviate(std::string_view sql) {
  constexpr size_t kMaxChars = 120;
  std::string out;
  for (char c : sql.substr(0, kMaxChars)) {
    const char replaced = c == '\n' || c == '\t' ? ' ' : c;
    // Runs of spaces (the indentation of raw string literals) shrink to one.
    if (replaced == ' ' && (out.empty() || out.back() == ' ')) continue;
    out += replaced;
  }
  if (sql.size() > kMaxChars) out += "...";
  return out;
}

// libpq's messages end with a newline and may span lines ("ERROR: ...\nDETAIL: ...", or
// "...refused\n\tIs the server running..."): one line, single spaces.
std::string OneLine(std::string_view text) {
  std::string out;
  for (char c : text) {
    if (c == '\n' || c == '\t' || c == '\r') c = ' ';
    if (c == ' ' && (out.empty() || out.back() == ' ')) continue;
    out += c;
  }
  if (!out.empty() && out.back() == ' ') out.pop_back();
  return out;
}

// The password in `url` (user:PASSWORD@host), if any; libpq's messages may quote it.
std::string_view PasswordOf(std::string_view url) {
  const size_t scheme = url.find("://");
  if (scheme == std::string_view::npos) return {};
  const size_t start = scheme + 3;
  const size_t at = url.find('@', start);
  const size_t slash = url.find('/', start);
  if (at == std::string_view::npos || (slash != std::string_view::npos && slash < at)) return {};
  const size_t colon = url.find(':', start);
  if (colon == std::string_view::npos || colon > at) return {};
  return url.substr(colon + 1, at - colon - 1);
}

std::string ReplaceAll(std::string text, std::string_view what, std::string_view with) {
  if (what.empty()) return text;
  for (size_t at = text.find(what); at != std::string::npos;
       at = text.find(what, at + with.size())) {
    text.replace(at, what.size(), with);
  }
  return text;
}

}  // namespace

bool IsPostgresUrl(std::string_view url) {
  return url.starts_with("postgresql://") || url.starts_with("postgres://");
}

std::string RedactPostgresUrl(std::string_view url) {
  std::string out(url);
  if (const std::string_view password = PasswordOf(url); !password.empty()) {
    const size_t at = static_cast<size_t>(password.data() - url.data());
    out.replace(at, password.size(), kRedacted);
  }
  // ...?password=secret&sslmode=require
  for (size_t at = out.find("password="); at != std::string::npos;
       at = out.find("password=", at + 1)) {
    if (at > 0 && out[at - 1] != '?' && out[at - 1] != '&') continue;
    const size_t start = at + 9;
    const size_t end = std::min(out.find('&', start), out.size());
    out.replace(start, end - start, kRedacted);
  }
  return out;
}

// --- PostgresParams ------------------------------------------------------------------------------

namespace {

constexpr std::string_view kReplacementCharacter = "\xEF\xBF\xBD";  // U+FFFD

// The length of the well-formed UTF-8 sequence at the start of `text` (Unicode table 3-7: no
// overlong forms, no surrogates, nothing above U+10FFFF), or 0.
size_t Utf8SequenceLength(std::string_view text) {
  const auto byte = [&](size_t i) { return static_cast<unsigned char>(text[i]); };
  const unsigned char lead = byte(0);
  if (lead >= 0x01 && lead <= 0x7F) return 1;  // NUL is refused too: text cannot hold it
  size_t length = 0;
  unsigned char low = 0x80, high = 0xBF;  // the allowed range of the second byte
  if (lead >= 0xC2 && lead <= 0xDF) {
    length = 2;
  } else if (lead >= 0xE0 && lead <= 0xEF) {
    length = 3;
    if (lead == 0xE0) low = 0xA0;
    if (lead == 0xED) high = 0x9F;
  } else if (lead >= 0xF0 && lead <= 0xF4) {
    length = 4;
    if (lead == 0xF0) low = 0x90;
    if (lead == 0xF4) high = 0x8F;
  } else {
    return 0;
  }
  if (text.size() < length || byte(1) < low || byte(1) > high) return 0;
  for (size_t i = 2; i < length; ++i) {
    if (byte(i) < 0x80 || byte(i) > 0xBF) return 0;
  }
  return length;
}

}  // namespace

void PostgresParams::Add(std::string_view value) {
  std::string text;
  text.reserve(value.size());
  while (!value.empty()) {
    const size_t length = Utf8SequenceLength(value);
    if (length == 0) {
      text += kReplacementCharacter;
      value.remove_prefix(1);
    } else {
      text += value.substr(0, length);
      value.remove_prefix(length);
    }
  }
  values_.emplace_back(std::move(text));
}

void PostgresParams::Add(double value) {
  if (std::isnan(value)) {
    values_.emplace_back(std::nullopt);
  } else if (std::isinf(value)) {
    values_.emplace_back(value > 0 ? "Infinity" : "-Infinity");
  } else {
    char text[32];
    std::snprintf(text, sizeof(text), "%.17g", value);
    values_.emplace_back(text);
  }
}

// --- PostgresResult ------------------------------------------------------------------------------

PostgresResult::PostgresResult(PostgresResult&& other) noexcept
    : result_(std::exchange(other.result_, nullptr)) {}

PostgresResult& PostgresResult::operator=(PostgresResult&& other) noexcept {
  if (this != &other) {
    PQclear(result_);
    result_ = std::exchange(other.result_, nullptr);
  }
  return *this;
}

PostgresResult::~PostgresResult() {
  PQclear(result_);
}

int PostgresResult::rows() const {
  return PQntuples(result_);
}

int64_t PostgresResult::affected_rows() const {
  const char* text = PQcmdTuples(result_);
  return text[0] == '\0' ? 0 : std::strtoll(text, nullptr, 10);
}

bool PostgresResult::IsNull(int row, int column) const {
  return PQgetisnull(result_, row, column) != 0;
}

std::string PostgresResult::Text(int row, int column) const {
  return std::string(PQgetvalue(result_, row, column),
                     static_cast<size_t>(PQgetlength(result_, row, column)));
}

int64_t PostgresResult::Int64(int row, int column) const {
  const char* text = PQgetvalue(result_, row, column);
  int64_t value = 0;
  std::from_chars(text, text + PQgetlength(result_, row, column), value);
  return value;
}

double PostgresResult::Double(int row, int column) const {
  if (IsNull(row, column)) return std::nan("");
  // strtod reads the server's "Infinity" and "-Infinity" too.
  return std::strtod(PQgetvalue(result_, row, column), nullptr);
}

bool PostgresResult::Bool(int row, int column) const {
  return PQgetvalue(result_, row, column)[0] == 't';
}

std::optional<int64_t> PostgresResult::OptionalInt64(int row, int column) const {
  if (IsNull(row, column)) return std::nullopt;
  return Int64(row, column);
}

std::optional<std::string> PostgresResult::OptionalText(int row, int column) const {
  if (IsNull(row, column)) return std::nullopt;
  return Text(row, column);
}

// --- PostgresConnection --------------------------------------------------------------------------

Result<PostgresConnection> PostgresConnection::Connect(const std::string& url) {
  std::string where = RedactPostgresUrl(url);
  // Parsed first, so that a malformed URL is told apart from a server that cannot be reached.
  char* parse_error = nullptr;
  PQconninfoOption* parsed = PQconninfoParse(url.c_str(), &parse_error);
  if (parsed == nullptr) {
    std::string message = parse_error != nullptr ? OneLine(parse_error) : "out of memory";
    PQfreemem(parse_error);
    return Status::InvalidArgument(
        where + ": not a valid PostgreSQL URL: " + ReplaceAll(message, PasswordOf(url), kRedacted));
  }
  PQconninfoFree(parsed);

  // connect_timeout first so that the URL's own value wins (later keywords override earlier
  // ones): without one, an unreachable host blocks for the operating system's TCP timeout.
  const char* keywords[] = {"connect_timeout", "dbname", nullptr};
  const char* values[] = {"10", url.c_str(), nullptr};
  pg_conn* conn = PQconnectdbParams(keywords, values, /*expand_dbname=*/1);
  if (conn == nullptr) return Status::Internal(where + ": cannot connect: out of memory");
  PostgresConnection connection(conn, where);
  if (PQstatus(conn) != CONNECTION_OK) {
    return Status::IoError(where + ": cannot connect: " +
                           ReplaceAll(OneLine(PQerrorMessage(conn)), PasswordOf(url), kRedacted));
  }
  if (const int version = PQserverVersion(conn); version < 130000) {
    return Status::FailedPrecondition(where + ": PostgreSQL server version " +
                                      std::to_string(version / 10000) +
                                      " is too old (13 or newer needed)");
  }
  // Timeouts of our own rather than a server or role default that could cut a migration or a
  // lock wait short (settings any user may change; lc_messages, for one, is not).
  SOFTID_RETURN_IF_ERROR(
      connection.Exec("SET statement_timeout TO 0; SET lock_timeout TO 0; "
                      "SET idle_in_transaction_session_timeout TO 0"));
  return connection;
}

PostgresConnection::PostgresConnection(PostgresConnection&& other) noexcept
    : conn_(std::exchange(other.conn_, nullptr)),
      where_(std::move(other.where_)),
      last_sqlstate_(std::move(other.last_sqlstate_)) {}

PostgresConnection& PostgresConnection::operator=(PostgresConnection&& other) noexcept {
  if (this != &other) {
    Close();
    conn_ = std::exchange(other.conn_, nullptr);
    where_ = std::move(other.where_);
    last_sqlstate_ = std::move(other.last_sqlstate_);
  }
  return *this;
}

PostgresConnection::~PostgresConnection() {
  Close();
}

void PostgresConnection::Close() {
  if (conn_ != nullptr) PQfinish(std::exchange(conn_, nullptr));
}

bool PostgresConnection::healthy() const {
  return conn_ != nullptr && PQstatus(conn_) == CONNECTION_OK;
}

bool PostgresConnection::in_transaction() const {
  if (conn_ == nullptr) return false;
  const PGTransactionStatusType status = PQtransactionStatus(conn_);
  return status == PQTRANS_INTRANS || status == PQTRANS_INERROR || status == PQTRANS_ACTIVE;
}

Status PostgresConnection::Exec(std::string_view sql) {
  if (conn_ == nullptr) return Status::FailedPrecondition(where_ + ": connection is closed");
  const std::string text(sql);
  return Check(PQexec(conn_, text.c_str()), "exec", sql).status();
}

Result<PostgresResult> PostgresConnection::Query(std::string_view sql,
                                                 const PostgresParams& params) {
  if (conn_ == nullptr) return Status::FailedPrecondition(where_ + ": connection is closed");
  const std::string text(sql);
  std::vector<const char*> values;
  values.reserve(params.values().size());
  for (const std::optional<std::string>& value : params.values()) {
    values.push_back(value.has_value() ? value->c_str() : nullptr);
  }
  // Types null: the server infers each parameter's type from the statement; text format in and
  // out (lengths and formats null).
  pg_result* result = PQexecParams(conn_, text.c_str(), static_cast<int>(values.size()), nullptr,
                                   values.data(), nullptr, nullptr, /*resultFormat=*/0);
  return Check(result, "query", sql);
}

Result<PostgresResult> PostgresConnection::Check(pg_result* raw, std::string_view action,
                                                 std::string_view sql) {
  PostgresResult result(raw);
  last_sqlstate_.clear();
  if (raw == nullptr) {
    // No result at all: out of memory or the connection broke before an answer came.
    return Status::IoError(where_ + ": " + std::string(action) + " `" + Abbreviate(sql) +
                           "`: " + OneLine(PQerrorMessage(conn_)));
  }
  const ExecStatusType status = PQresultStatus(raw);
  if (status == PGRES_COMMAND_OK || status == PGRES_TUPLES_OK) return result;
  const char* sqlstate = PQresultErrorField(raw, PG_DIAG_SQLSTATE);
  last_sqlstate_ = sqlstate != nullptr ? sqlstate : "";
  std::string message = where_ + ": " + std::string(action) + " `" + Abbreviate(sql) +
                        "`: " + OneLine(PQresultErrorMessage(raw));
  if (!last_sqlstate_.empty()) message += " (SQLSTATE " + last_sqlstate_ + ")";
  // Class 08 (connection exception) and a connection that broke are outside the caller's control;
  // anything else (a constraint the store did not anticipate, bad SQL) is a bug in the store.
  const bool connection_problem = last_sqlstate_.starts_with("08") || !healthy();
  return Status(connection_problem ? StatusCode::kIoError : StatusCode::kInternal, message);
}

}  // namespace softid::server::store
