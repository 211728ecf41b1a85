// softid-server: the gRPC job server. Flags fall back to environment variables so a container
// can be configured without a command line.
#include <pthread.h>
#include <signal.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <cstdlib>
#include <thread>

#include "server/server.h"

namespace {

constexpr int kExitOk = 0;
constexpr int kExitFailure = 1;
constexpr int kExitInvalidInput = 2;

// The sigwait thread, for ForwardToWaiter. A global because a signal handler can reach nothing
// else.
pthread_t g_signal_waiter;

void ForwardToWaiter(int signal) {
  pthread_kill(g_signal_waiter, signal);
}

int DefaultWorkers() {
  const unsigned cores = std::thread::hardware_concurrency();
  return cores == 0 ? 1 : static_cast<int>(cores);
}

}  // namespace

int main(int argc, char** argv) {
  softid::server::ServerOptions options;
  options.num_workers = DefaultWorkers();
  std::string data_dir;
  std::string log_level = "info";

  CLI::App app{"softid-server: queues and runs reconstruction jobs behind a gRPC API"};
  app.add_option("--listen", options.listen_address, "address to listen on, host:port")
      ->envname("SOFTID_LISTEN")
      ->capture_default_str();
  app.add_option("--data", data_dir, "data directory (database and uploaded files)")
      ->envname("SOFTID_DATA")
      ->required();
  app.add_option("--workers", options.num_workers, "jobs run in parallel (default: cores)")
      ->envname("SOFTID_WORKERS")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  app.add_option("--max-queued", options.max_queued_jobs,
                 "queued jobs accepted before CreateJob answers RESOURCE_EXHAUSTED")
      ->envname("SOFTID_MAX_QUEUED")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--max-attempts", options.max_attempts,
                 "starts of a job whose worker was lost before it is FAILED")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--log-level", log_level, "trace, debug, info, warn, error")
      ->envname("SOFTID_LOG_LEVEL")
      ->capture_default_str();
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? kExitOk : kExitInvalidInput;
  }
  options.data_dir = data_dir;
  spdlog::set_level(spdlog::level::from_str(log_level));

  // Block the shutdown signals in this thread and every thread it starts (gRPC's and the
  // workers' inherit the mask) so they reach only the sigwait thread below; Shutdown is not
  // async-signal-safe and never runs in a handler.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGINT);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);
  int received = 0;
  std::thread waiter([&] { sigwait(&signals, &received); });
  // Threads started by library constructors before main (OpenBLAS's pool) did not inherit the
  // mask; a signal the kernel hands to one of them would kill the process with the default
  // action. This handler, which runs only on such threads, passes the signal on to the waiter.
  g_signal_waiter = waiter.native_handle();
  struct sigaction forward = {};
  forward.sa_handler = ForwardToWaiter;
  sigemptyset(&forward.sa_mask);
  sigaction(SIGTERM, &forward, nullptr);
  sigaction(SIGINT, &forward, nullptr);

  softid::Result<std::unique_ptr<softid::server::Server>> server =
      softid::server::Server::Start(options);
  if (!server.ok()) {
    spdlog::error("{}", server.status().message());
    pthread_kill(waiter.native_handle(), SIGTERM);
    waiter.join();
    return server.status().code() == softid::StatusCode::kInvalidArgument ? kExitInvalidInput
                                                                          : kExitFailure;
  }
  waiter.join();
  spdlog::info("received {}", received == SIGTERM ? "SIGTERM" : "SIGINT");
  const softid::Status closed = (*server)->Shutdown();
  if (!closed.ok()) {
    spdlog::error("{}", closed.message());
    return kExitFailure;
  }
  return kExitOk;
}
