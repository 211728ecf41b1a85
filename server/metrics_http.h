// Serves GET /metrics over plain HTTP with cpp-httplib, on its own address (a scraper on the
// operators' network, apart from the stations' gRPC port). Other paths answer 404.
#pragma once

#include <functional>
#include <memory>
#include <string>
#include <thread>

#include "core/common/status.h"

namespace httplib {
class Server;
}

namespace softid::server {

class MetricsHttpServer {
 public:
  // Binds `listen_address` ("host:port"; port 0 picks one) and serves `render()` at /metrics
  // from a thread of its own. InvalidArgument naming --metrics-listen when it cannot bind.
  static Result<std::unique_ptr<MetricsHttpServer>> Start(const std::string& listen_address,
                                                          std::function<std::string()> render);
  ~MetricsHttpServer();  // stops serving
  MetricsHttpServer(const MetricsHttpServer&) = delete;
  MetricsHttpServer& operator=(const MetricsHttpServer&) = delete;

  int port() const { return port_; }

 private:
  MetricsHttpServer() = default;
  std::unique_ptr<httplib::Server> http_;
  int port_ = 0;
  std::thread thread_;
};

}  // namespace softid::server
