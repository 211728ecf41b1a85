#include "server/grpc_status.h"

namespace softid::server {

grpc::Status ToGrpcStatus(const ServiceStatus& status) {
  grpc::StatusCode code = grpc::StatusCode::UNKNOWN;
  switch (status.code()) {
    case ServiceCode::kOk: return grpc::Status::OK;
    case ServiceCode::kInvalidArgument: code = grpc::StatusCode::INVALID_ARGUMENT; break;
    case ServiceCode::kNotFound: code = grpc::StatusCode::NOT_FOUND; break;
    case ServiceCode::kAlreadyExists: code = grpc::StatusCode::ALREADY_EXISTS; break;
    case ServiceCode::kFailedPrecondition: code = grpc::StatusCode::FAILED_PRECONDITION; break;
    case ServiceCode::kResourceExhausted: code = grpc::StatusCode::RESOURCE_EXHAUSTED; break;
    case ServiceCode::kUnavailable: code = grpc::StatusCode::UNAVAILABLE; break;
    case ServiceCode::kCancelled: code = grpc::StatusCode::CANCELLED; break;
    case ServiceCode::kUnauthenticated: code = grpc::StatusCode::UNAUTHENTICATED; break;
    case ServiceCode::kInternal: code = grpc::StatusCode::INTERNAL; break;
  }
  return grpc::Status(code, status.message());
}

}  // namespace softid::server
