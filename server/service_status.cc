#include "server/service_status.h"

namespace softid::server {

const char* ToString(ServiceCode code) {
  switch (code) {
    case ServiceCode::kOk: return "OK";
    case ServiceCode::kInvalidArgument: return "INVALID_ARGUMENT";
    case ServiceCode::kNotFound: return "NOT_FOUND";
    case ServiceCode::kAlreadyExists: return "ALREADY_EXISTS";
    case ServiceCode::kFailedPrecondition: return "FAILED_PRECONDITION";
    case ServiceCode::kResourceExhausted: return "RESOURCE_EXHAUSTED";
    case ServiceCode::kUnavailable: return "UNAVAILABLE";
    case ServiceCode::kCancelled: return "CANCELLED";
    case ServiceCode::kUnauthenticated: return "UNAUTHENTICATED";
    case ServiceCode::kInternal: return "INTERNAL";
  }
  return "UNKNOWN";
}

ServiceStatus::ServiceStatus(const Status& status) : message_(status.message()) {
  switch (status.code()) {
    case StatusCode::kOk: code_ = ServiceCode::kOk; break;
    case StatusCode::kInvalidArgument: code_ = ServiceCode::kInvalidArgument; break;
    case StatusCode::kNotFound: code_ = ServiceCode::kNotFound; break;
    case StatusCode::kFailedPrecondition:
    case StatusCode::kDeadlineExceeded: code_ = ServiceCode::kFailedPrecondition; break;
    case StatusCode::kIoError:
    case StatusCode::kInternal: code_ = ServiceCode::kInternal; break;
    case StatusCode::kCancelled: code_ = ServiceCode::kCancelled; break;
  }
}

std::string ServiceStatus::ToString() const {
  if (ok()) return "OK";
  return std::string(server::ToString(code_)) + ": " + message_;
}

}  // namespace softid::server
