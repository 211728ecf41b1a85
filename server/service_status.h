// The outcome of a JobService call, in the vocabulary of the API rather than of core: core's
// Status has no codes for a full queue, a draining server or a reused request id, which the API
// must tell apart (service notes: status codes). Converted to gRPC in one place, grpc_status.cc.
#pragma once

#include <string>
#include <utility>
#include <variant>

#include "core/common/status.h"

namespace softid::server {

enum class ServiceCode {
  kOk = 0,
  kInvalidArgument,     // malformed input: the message names the field or file and the value
  kNotFound,            // unknown capture or job id
  kAlreadyExists,       // a request_id reused with different arguments
  kFailedPrecondition,  // the resource is in the wrong state (result before done, ...)
  kResourceExhausted,   // queue full
  kUnavailable,         // the server is draining
  kCancelled,           // the caller went away
  kUnauthenticated,     // no valid API token
  kInternal,            // I/O or store failure: not the caller's fault
};

const char* ToString(ServiceCode code);

class [[nodiscard]] ServiceStatus {
 public:
  ServiceStatus() = default;
  ServiceStatus(ServiceCode code, std::string message)
      : code_(code), message_(std::move(message)) {}
  // Core and store errors: IoError and Internal become kInternal; the rest keep their meaning.
  ServiceStatus(const Status& status);  // NOLINT: implicit by design, like Result<T>

  static ServiceStatus Ok() { return {}; }

  bool ok() const { return code_ == ServiceCode::kOk; }
  ServiceCode code() const { return code_; }
  const std::string& message() const { return message_; }
  // "<CODE>: <message>", or "OK".
  std::string ToString() const;

 private:
  ServiceCode code_ = ServiceCode::kOk;
  std::string message_;
};

// A value or a non-OK ServiceStatus (core's Result; a core Status converts as above).
template <typename T>
using ServiceResult = Result<T, ServiceStatus>;

}  // namespace softid::server
