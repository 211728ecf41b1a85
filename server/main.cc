// softid-server: the gRPC job server. Flags fall back to environment variables so a container
// can be configured without a command line.
#include <pthread.h>
#include <signal.h>
#include <spdlog/spdlog.h>
#include <sys/stat.h>

#include <CLI/CLI.hpp>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <thread>

#include "core/common/cpu_support.h"
#include "core/fem/numeric_runtime.h"
#include "server/log_context.h"
#include "server/server.h"
#include "server/tokens_command.h"

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

// Through a temporary file renamed into place: whoever polls for the file never reads half a
// number.
softid::Status WritePortFile(const std::string& path, int port) {
  const std::string temporary = path + ".tmp";
  {
    std::ofstream out(temporary);
    out << port << "\n";
    if (!out.flush()) return softid::Status::IoError("--port-file " + path + ": cannot write");
  }
  std::error_code error;
  std::filesystem::rename(temporary, path, error);
  if (error) return softid::Status::IoError("--port-file " + path + ": " + error.message());
  return softid::Status::Ok();
}

int DefaultWorkers() {
  const unsigned cores = std::thread::hardware_concurrency();
  return cores == 0 ? 1 : static_cast<int>(cores);
}

}  // namespace

int main(int argc, char** argv) {
  // Links the start-up check that this CPU runs the build's instruction set.
  if (!softid::CpuSupportsBuild()) return 2;
  softid::fem::ConfigureNumericRuntime();  // CHOLMOD's OpenMP serialised, BLAS single-threaded
  softid::server::ServerOptions options;
  options.num_workers = DefaultWorkers();
  std::string data_dir;
  std::string port_file;
  std::string log_level = "info";

  CLI::App app{"softid-server: queues and runs reconstruction jobs behind a gRPC API"};
  app.add_option("--listen", options.listen_address, "address to listen on, host:port")
      ->envname("SOFTID_LISTEN")
      ->capture_default_str();
  app.add_option("--data", data_dir, "data directory (database and uploaded files)")
      ->envname("SOFTID_DATA");
  std::string store_url;
  app.add_option("--store", store_url,
                 "a postgresql://user:password@host:port/database URL: keep jobs, captures and "
                 "tokens there instead of the SQLite database under --data (uploaded files stay "
                 "under --data)")
      ->envname("SOFTID_STORE");
  app.add_option("--store-connections", options.store_connections,
                 "connections to the --store PostgreSQL database this process may hold at once "
                 "(default: workers + 4)")
      ->envname("SOFTID_STORE_CONNECTIONS")
      ->check(CLI::PositiveNumber);
  std::string role = "all";
  app.add_option("--role", role,
                 "all: take RPCs and run jobs; api: take RPCs only; worker: run jobs only "
                 "(answers health probes); api and worker processes share a --store")
      ->envname("SOFTID_ROLE")
      ->capture_default_str();
  app.add_option("--workers", options.num_workers, "jobs run in parallel (default: cores)")
      ->envname("SOFTID_WORKERS")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  app.add_flag("--fan-out-starts", options.fan_out_starts,
               "run each job's random starts as tasks that any worker sharing the --store "
               "claims, so a many-start job runs on several workers at once")
      ->envname("SOFTID_FAN_OUT_STARTS");
  double lease_seconds = options.lease.count() / 1000.0;
  app.add_option("--lease-seconds", lease_seconds,
                 "a job (or start task) whose worker stops renewing its lease this long runs "
                 "again elsewhere: how soon a dead worker's work is retried")
      ->envname("SOFTID_LEASE_SECONDS")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--max-queued", options.max_queued_jobs,
                 "queued jobs accepted before CreateJob answers RESOURCE_EXHAUSTED")
      ->envname("SOFTID_MAX_QUEUED")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--max-attempts", options.max_attempts,
                 "starts of a job whose worker was lost before it is FAILED")
      ->envname("SOFTID_MAX_ATTEMPTS")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  double max_job_memory_gib = options.max_job_memory_bytes / (1ull << 30);
  app.add_option("--max-job-memory-gib", max_job_memory_gib,
                 "jobs whose estimated memory exceeds this many GiB are refused at CreateJob")
      ->envname("SOFTID_MAX_JOB_MEMORY_GIB")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  double max_job_hours = 24.0;
  app.add_option("--max-job-hours", max_job_hours,
                 "jobs whose estimated time (all iterations run) exceeds this many hours are "
                 "refused at CreateJob")
      ->envname("SOFTID_MAX_JOB_HOURS")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--max-uploads", options.upload_limits.max_concurrent,
                 "uploads in progress at once; more are answered RESOURCE_EXHAUSTED")
      ->envname("SOFTID_MAX_UPLOADS")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  double upload_idle_timeout_s = options.upload_limits.idle_timeout.count() / 1000.0;
  app.add_option("--upload-idle-timeout", upload_idle_timeout_s,
                 "seconds an upload may send nothing before it is cancelled")
      ->envname("SOFTID_UPLOAD_IDLE_TIMEOUT")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  std::string tls_cert, tls_key, tls_client_ca;
  app.add_option("--tls-cert", tls_cert, "server certificate chain (PEM): serve over TLS")
      ->envname("SOFTID_TLS_CERT");
  app.add_option("--tls-key", tls_key, "the certificate's private key (PEM)")
      ->envname("SOFTID_TLS_KEY");
  app.add_option("--tls-client-ca", tls_client_ca,
                 "require client certificates signed by this CA (PEM): mutual TLS")
      ->envname("SOFTID_TLS_CLIENT_CA");
  softid::server::TlsOptions self_signed_tls;
  app.add_flag("--tls-self-signed", self_signed_tls.self_signed,
               "without --tls-cert, serve TLS with a certificate made on first start and kept "
               "in DATA/tls/ (clients: --tls-ca DATA/tls/server.crt)")
      ->envname("SOFTID_TLS_SELF_SIGNED");
  app.add_option("--tls-hostnames", self_signed_tls.host_names,
                 "names or addresses clients connect by, for the self-signed certificate "
                 "(besides localhost); comma-separated")
      ->envname("SOFTID_TLS_HOSTNAMES")
      ->delimiter(',');
  app.add_flag("--allow-insecure", options.allow_insecure,
               "serve without TLS on a non-loopback address (only behind a trusted network)")
      ->envname("SOFTID_ALLOW_INSECURE");
  std::string auth = "auto";
  app.add_option("--auth", auth,
                 "require per-station API tokens: token, none, or auto (token unless the listen "
                 "address is loopback)")
      ->envname("SOFTID_AUTH")
      ->check(CLI::IsMember({"auto", "token", "none"}))
      ->capture_default_str();
  app.add_option("--metrics-listen", options.metrics_listen,
                 "serve Prometheus metrics at http://HOST:PORT/metrics (default: off)")
      ->envname("SOFTID_METRICS_LISTEN");
  double retention_days = 0.0;
  app.add_option("--retention-days", retention_days,
                 "delete ended jobs and unused captures older than this (checked hourly); 0: keep")
      ->envname("SOFTID_RETENTION_DAYS")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  softid::server::StationQuotas& quotas = options.quotas;
  app.add_option("--quota-queued-jobs", quotas.max_queued_jobs,
                 "jobs one station may have QUEUED at once")
      ->envname("SOFTID_QUOTA_QUEUED_JOBS")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  double quota_stored_gib = static_cast<double>(quotas.max_stored_bytes) / (1ull << 30);
  app.add_option("--quota-stored-gib", quota_stored_gib, "GiB of captures one station may store")
      ->envname("SOFTID_QUOTA_STORED_GIB")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--quota-uploads", quotas.max_concurrent_uploads,
                 "uploads one station may have in progress at once")
      ->envname("SOFTID_QUOTA_UPLOADS")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--quota-rate", quotas.requests_per_second,
                 "calls per second one station may make (bursts of 4x); 0: unlimited")
      ->envname("SOFTID_QUOTA_RATE")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  softid::server::TokensCommand tokens;
  softid::server::AddTokensCommand(app, &tokens);
  app.add_option("--port-file", port_file,
                 "once listening, write the bound port here (for --listen host:0)");
  std::string log_format = "text";
  app.add_option("--log-format", log_format, "text, or json (one object per line)")
      ->envname("SOFTID_LOG_FORMAT")
      ->check(CLI::IsMember({"text", "json"}))
      ->capture_default_str();
  app.add_option("--log-level", log_level, "trace, debug, info, warn, error")
      ->envname("SOFTID_LOG_LEVEL")
      ->capture_default_str();
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? kExitOk : kExitInvalidInput;
  }
  if (tokens.command->parsed()) {
    return softid::server::RunTokensCommand(tokens, data_dir, store_url);
  }
  if (data_dir.empty()) {
    std::fprintf(stderr, "softid-server: --data is required (or SOFTID_DATA)\n");
    return kExitInvalidInput;
  }
  options.data_dir = data_dir;
  options.store_url = store_url;
  softid::Result<softid::server::ServerRole> parsed_role = softid::server::ParseServerRole(role);
  if (!parsed_role.ok()) {
    std::fprintf(stderr, "softid-server: %s\n", parsed_role.status().message().c_str());
    return kExitInvalidInput;
  }
  options.role = *parsed_role;
  if (auth != "auto") {
    options.auth =
        auth == "token" ? softid::server::AuthMode::kToken : softid::server::AuthMode::kNone;
  }
  options.tls = self_signed_tls;
  options.tls.cert_file = tls_cert;
  options.tls.key_file = tls_key;
  options.tls.client_ca_file = tls_client_ca;
  // Files of the data directory (database, blobs) are private to the server's user.
  ::umask(077);
  options.max_job_memory_bytes = max_job_memory_gib * (1ull << 30);
  options.max_job_wall_time =
      std::chrono::seconds(std::max<int64_t>(1, static_cast<int64_t>(max_job_hours * 3600.0)));
  quotas.max_stored_bytes = static_cast<int64_t>(quota_stored_gib * (1ull << 30));
  quotas.request_burst = 4.0 * quotas.requests_per_second;
  if (retention_days > 0) {
    options.retention = std::chrono::seconds(static_cast<int64_t>(retention_days * 86400.0));
  }
  options.upload_limits.idle_timeout =
      std::chrono::milliseconds(static_cast<int64_t>(upload_idle_timeout_s * 1000.0));
  options.lease = std::chrono::milliseconds(static_cast<int64_t>(lease_seconds * 1000.0));
  spdlog::set_level(spdlog::level::from_str(log_level));
  softid::server::ConfigureLogging(*softid::server::LogFormatFromString(log_format));
  // libpng (through OpenCV) and others write warnings to stderr: logged as lines instead.
  const std::unique_ptr<softid::server::StderrCapture> stderr_capture =
      softid::server::CaptureStderr();

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
  bool port_file_failed = false;
  if (!port_file.empty()) {
    if (const softid::Status written = WritePortFile(port_file, (*server)->port()); !written.ok()) {
      spdlog::error("{}", written.message());
      port_file_failed = true;
      pthread_kill(waiter.native_handle(), SIGTERM);
    }
  }
  waiter.join();
  if (!port_file_failed) {
    spdlog::info("received {}", received == SIGTERM ? "SIGTERM" : "SIGINT");
  }
  const softid::Status closed = (*server)->Shutdown();
  if (!closed.ok()) {
    spdlog::error("{}", closed.message());
    return kExitFailure;
  }
  return port_file_failed ? kExitFailure : kExitOk;
}
