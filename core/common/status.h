// Status and Result<T>: expected failures (bad input, I/O) travel as values, never as exceptions.
// Modelled on Arrow's Status/Result: a Status is OK or carries a code and a message that names the
// offending field and value, e.g. "capture.json: cameras[0].fx = -1: must be positive".
#pragma once

#include <optional>
#include <string>
#include <type_traits>
#include <utility>
#include <variant>

namespace softid {

enum class StatusCode {
  kOk = 0,
  kInvalidArgument,  // malformed input: names the field and the value
  kNotFound,         // a file or resource that does not exist
  kIoError,          // a read or write that failed for reasons outside the input
  kFailedPrecondition,
  kInternal,
  kCancelled,         // stopped because the caller asked (a cancel flag was set)
  kDeadlineExceeded,  // not done: the time limit given cannot hold the work (names the limit)
};

const char* ToString(StatusCode code);

class [[nodiscard]] Status {
 public:
  Status() = default;
  Status(StatusCode code, std::string message) : code_(code), message_(std::move(message)) {}

  static Status Ok() { return {}; }
  static Status InvalidArgument(std::string message) {
    return {StatusCode::kInvalidArgument, std::move(message)};
  }
  static Status NotFound(std::string message) {
    return {StatusCode::kNotFound, std::move(message)};
  }
  static Status IoError(std::string message) { return {StatusCode::kIoError, std::move(message)}; }
  static Status FailedPrecondition(std::string message) {
    return {StatusCode::kFailedPrecondition, std::move(message)};
  }
  static Status Internal(std::string message) {
    return {StatusCode::kInternal, std::move(message)};
  }
  static Status Cancelled(std::string message) {
    return {StatusCode::kCancelled, std::move(message)};
  }
  static Status DeadlineExceeded(std::string message) {
    return {StatusCode::kDeadlineExceeded, std::move(message)};
  }

  bool ok() const { return code_ == StatusCode::kOk; }
  StatusCode code() const { return code_; }
  const std::string& message() const { return message_; }
  // "INVALID_ARGUMENT: <message>", or "OK".
  std::string ToString() const;

  // Returns a copy whose message is "<context>: <message>" (for nesting file and field names).
  Status WithContext(const std::string& context) const;

 private:
  StatusCode code_ = StatusCode::kOk;
  std::string message_;
};

// Holds a value or a non-OK status. `StatusT` is Status in core; the server speaks the API's
// vocabulary (server::ServiceStatus, which has codes core does not need) through the same
// template, and such a Result also takes a core Status, converted by StatusT's constructor.
template <typename T, typename StatusT = Status>
class [[nodiscard]] Result {
 public:
  Result(T value) : storage_(std::move(value)) {}          // NOLINT: implicit by design
  Result(StatusT status) : storage_(std::move(status)) {}  // NOLINT: implicit by design
  Result(const Status& status)                             // NOLINT: implicit by design
      requires(!std::is_same_v<StatusT, Status>)
      : storage_(StatusT(status)) {}

  bool ok() const { return std::holds_alternative<T>(storage_); }
  const StatusT& status() const {
    static const StatusT kOkStatus;
    return ok() ? kOkStatus : std::get<StatusT>(storage_);
  }
  // @pre ok()
  const T& value() const& { return std::get<T>(storage_); }
  T& value() & { return std::get<T>(storage_); }
  T&& value() && { return std::get<T>(std::move(storage_)); }
  const T& operator*() const& { return value(); }
  T& operator*() & { return value(); }
  // By value: `for (auto& x : *Load())` then iterates a live object, not a destroyed temporary.
  T operator*() && { return std::move(*this).value(); }
  const T* operator->() const { return &value(); }
  T* operator->() { return &value(); }

 private:
  std::variant<T, StatusT> storage_;
};

}  // namespace softid

// Returns early from the enclosing function when `expr` (a Status) is not OK.
#define SOFTID_RETURN_IF_ERROR(expr)                 \
  do {                                               \
    ::softid::Status softid_status_ = (expr);        \
    if (!softid_status_.ok()) return softid_status_; \
  } while (false)

#define SOFTID_CONCAT_INNER(a, b) a##b
#define SOFTID_CONCAT(a, b) SOFTID_CONCAT_INNER(a, b)
// Declares `lhs` from a Result<T> expression, or returns its Status from the enclosing function.
#define SOFTID_ASSIGN_OR_RETURN(lhs, expr)                   \
  auto SOFTID_CONCAT(softid_result_, __LINE__) = (expr);     \
  if (!SOFTID_CONCAT(softid_result_, __LINE__).ok())         \
    return SOFTID_CONCAT(softid_result_, __LINE__).status(); \
  lhs = std::move(SOFTID_CONCAT(softid_result_, __LINE__)).value()
