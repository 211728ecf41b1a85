// The one place where service outcomes become gRPC status codes (style guide rule 7).
#pragma once

#include <grpcpp/support/status.h>

#include "server/service_status.h"

namespace softid::server {

grpc::Status ToGrpcStatus(const ServiceStatus& status);

}  // namespace softid::server
