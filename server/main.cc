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

// The command line as typed: the server's options, and the flags converted into them once parsed
// (names, GiB, hours, seconds).
struct CommandLine {
  softid::server::ServerOptions options;
  std::string data_dir;
  std::string store_url;
  std::string role = "all";
  double lease_seconds = 0.0;
  double max_job_memory_gib = 0.0;
  double max_job_hours = 24.0;
  double upload_idle_timeout_s = 0.0;
  std::string tls_cert, tls_key, tls_client_ca;
  softid::server::TlsOptions self_signed_tls;
  std::string auth = "auto";
  double retention_days = 0.0;
  double quota_stored_gib = 0.0;
  softid::server::TokensCommand tokens;
  std::string port_file;
  std::string log_format = "text";
  std::string log_level = "info";
};

void AddListenAndStorageFlags(CLI::App& app, CommandLine& flags) {
  softid::server::ServerOptions& options = flags.options;
  app.add_option("--listen", options.listen_address, "address to listen on, host:port")
      ->envname("SOFTID_LISTEN")
      ->capture_default_str();
  app.add_option("--data", flags.data_dir, "data directory (database and uploaded files)")
      ->envname("SOFTID_DATA");
  app.add_option("--store", flags.store_url,
                 "a postgresql://user:password@host:port/database URL: keep jobs, captures and "
                 "tokens there instead of the SQLite database under --data (uploaded files stay "
                 "under --data)")
      ->envname("SOFTID_STORE");
  app.add_option("--store-connections", options.store_connections,
                 "connections to the --store PostgreSQL database this process may hold at once "
                 "(default: workers + 4)")
      ->envname("SOFTID_STORE_CONNECTIONS")
      ->check(CLI::PositiveNumber);
}

// Who runs jobs, how many are queued, and how a lost worker's work is retried.
void AddJobRunningFlags(CLI::App& app, CommandLine& flags) {
  softid::server::ServerOptions& options = flags.options;
  app.add_option("--role", flags.role,
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
  flags.lease_seconds = options.lease.count() / 1000.0;
  app.add_option("--lease-seconds", flags.lease_seconds,
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
}

// What one job and the uploads may take.
void AddLimitFlags(CLI::App& app, CommandLine& flags) {
  softid::server::ServerOptions& options = flags.options;
  flags.max_job_memory_gib = options.max_job_memory_bytes / (1ull << 30);
  app.add_option("--max-job-memory-gib", flags.max_job_memory_gib,
                 "jobs whose estimated memory exceeds this many GiB are refused at CreateJob")
      ->envname("SOFTID_MAX_JOB_MEMORY_GIB")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--max-job-hours", flags.max_job_hours,
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
  flags.upload_idle_timeout_s = options.upload_limits.idle_timeout.count() / 1000.0;
  app.add_option("--upload-idle-timeout", flags.upload_idle_timeout_s,
                 "seconds an upload may send nothing before it is cancelled")
      ->envname("SOFTID_UPLOAD_IDLE_TIMEOUT")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
}

// TLS and API tokens.
void AddSecurityFlags(CLI::App& app, CommandLine& flags) {
  app.add_option("--tls-cert", flags.tls_cert, "server certificate chain (PEM): serve over TLS")
      ->envname("SOFTID_TLS_CERT");
  app.add_option("--tls-key", flags.tls_key, "the certificate's private key (PEM)")
      ->envname("SOFTID_TLS_KEY");
  app.add_option("--tls-client-ca", flags.tls_client_ca,
                 "require client certificates signed by this CA (PEM): mutual TLS")
      ->envname("SOFTID_TLS_CLIENT_CA");
  app.add_flag("--tls-self-signed", flags.self_signed_tls.self_signed,
               "without --tls-cert, serve TLS with a certificate made on first start and kept "
               "in DATA/tls/ (clients: --tls-ca DATA/tls/server.crt)")
      ->envname("SOFTID_TLS_SELF_SIGNED");
  app.add_option("--tls-hostnames", flags.self_signed_tls.host_names,
                 "names or addresses clients connect by, for the self-signed certificate "
                 "(besides localhost); comma-separated")
      ->envname("SOFTID_TLS_HOSTNAMES")
      ->delimiter(',');
  app.add_flag("--allow-insecure", flags.options.allow_insecure,
               "serve without TLS on a non-loopback address (only behind a trusted network)")
      ->envname("SOFTID_ALLOW_INSECURE");
  app.add_option("--auth", flags.auth,
                 "require per-station API tokens: token, none, or auto (token unless the listen "
                 "address is loopback)")
      ->envname("SOFTID_AUTH")
      ->check(CLI::IsMember({"auto", "token", "none"}))
      ->capture_default_str();
}

// Metrics and the removal of old jobs.
void AddOperationsFlags(CLI::App& app, CommandLine& flags) {
  app.add_option("--metrics-listen", flags.options.metrics_listen,
                 "serve Prometheus metrics at http://HOST:PORT/metrics (default: off)")
      ->envname("SOFTID_METRICS_LISTEN");
  app.add_option("--retention-days", flags.retention_days,
                 "delete ended jobs and unused captures older than this (checked hourly); 0: keep")
      ->envname("SOFTID_RETENTION_DAYS")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
}

void AddQuotaFlags(CLI::App& app, CommandLine& flags) {
  softid::server::StationQuotas& quotas = flags.options.quotas;
  app.add_option("--quota-queued-jobs", quotas.max_queued_jobs,
                 "jobs one station may have QUEUED at once")
      ->envname("SOFTID_QUOTA_QUEUED_JOBS")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  flags.quota_stored_gib = static_cast<double>(quotas.max_stored_bytes) / (1ull << 30);
  app.add_option("--quota-stored-gib", flags.quota_stored_gib,
                 "GiB of captures one station may store")
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
}

// What the process writes: the port file and its log.
void AddOutputFlags(CLI::App& app, CommandLine& flags) {
  app.add_option("--port-file", flags.port_file,
                 "once listening, write the bound port here (for --listen host:0)");
  app.add_option("--log-format", flags.log_format, "text, or json (one object per line)")
      ->envname("SOFTID_LOG_FORMAT")
      ->check(CLI::IsMember({"text", "json"}))
      ->capture_default_str();
  app.add_option("--log-level", flags.log_level, "trace, debug, info, warn, error")
      ->envname("SOFTID_LOG_LEVEL")
      ->capture_default_str();
}

// The flags that go into the options as they are or by name; false (after saying why on
// stderr) when one is missing or unknown.
bool CopyFlagsIntoOptions(CommandLine& flags) {
  softid::server::ServerOptions& options = flags.options;
  if (flags.data_dir.empty()) {
    std::fprintf(stderr, "softid-server: --data is required (or SOFTID_DATA)\n");
    return false;
  }
  options.data_dir = flags.data_dir;
  options.store_url = flags.store_url;
  softid::Result<softid::server::ServerRole> parsed_role =
      softid::server::ParseServerRole(flags.role);
  if (!parsed_role.ok()) {
    std::fprintf(stderr, "softid-server: %s\n", parsed_role.status().message().c_str());
    return false;
  }
  options.role = *parsed_role;
  if (flags.auth != "auto") {
    options.auth =
        flags.auth == "token" ? softid::server::AuthMode::kToken : softid::server::AuthMode::kNone;
  }
  options.tls = flags.self_signed_tls;
  options.tls.cert_file = flags.tls_cert;
  options.tls.key_file = flags.tls_key;
  options.tls.client_ca_file = flags.tls_client_ca;
  return true;
}

// The flags given in GiB, hours, days or seconds, into the options' units.
void ConvertUnitFlags(CommandLine& flags) {
  softid::server::ServerOptions& options = flags.options;
  softid::server::StationQuotas& quotas = options.quotas;
  options.max_job_memory_bytes = flags.max_job_memory_gib * (1ull << 30);
  options.max_job_wall_time = std::chrono::seconds(
      std::max<int64_t>(1, static_cast<int64_t>(flags.max_job_hours * 3600.0)));
  quotas.max_stored_bytes = static_cast<int64_t>(flags.quota_stored_gib * (1ull << 30));
  quotas.request_burst = 4.0 * quotas.requests_per_second;
  if (flags.retention_days > 0) {
    options.retention = std::chrono::seconds(static_cast<int64_t>(flags.retention_days * 86400.0));
  }
  options.upload_limits.idle_timeout =
      std::chrono::milliseconds(static_cast<int64_t>(flags.upload_idle_timeout_s * 1000.0));
  options.lease = std::chrono::milliseconds(static_cast<int64_t>(flags.lease_seconds * 1000.0));
}

// Logs at the level and in the format asked for; the returned capture turns stderr into log
// lines while it lives.
std::unique_ptr<softid::server::StderrCapture> StartLogging(const CommandLine& flags) {
  spdlog::set_level(spdlog::level::from_str(flags.log_level));
  softid::server::ConfigureLogging(*softid::server::LogFormatFromString(flags.log_format));
  // libpng (through OpenCV) and others write warnings to stderr: logged as lines instead.
  return softid::server::CaptureStderr();
}

// The thread that waits for SIGTERM or SIGINT, and the signal it received.
struct SignalWaiter {
  sigset_t signals{};
  int received = 0;
  std::thread thread;
};

void StartSignalWaiter(SignalWaiter& waiter) {
  // Block the shutdown signals in this thread and every thread it starts (gRPC's and the
  // workers' inherit the mask) so they reach only the sigwait thread below; Shutdown is not
  // async-signal-safe and never runs in a handler.
  sigemptyset(&waiter.signals);
  sigaddset(&waiter.signals, SIGTERM);
  sigaddset(&waiter.signals, SIGINT);
  pthread_sigmask(SIG_BLOCK, &waiter.signals, nullptr);
  waiter.thread = std::thread([&waiter] { sigwait(&waiter.signals, &waiter.received); });
  // Threads started by library constructors before main (OpenBLAS's pool) did not inherit the
  // mask; a signal the kernel hands to one of them would kill the process with the default
  // action. This handler, which runs only on such threads, passes the signal on to the waiter.
  g_signal_waiter = waiter.thread.native_handle();
  struct sigaction forward = {};
  forward.sa_handler = ForwardToWaiter;
  sigemptyset(&forward.sa_mask);
  sigaction(SIGTERM, &forward, nullptr);
  sigaction(SIGINT, &forward, nullptr);
}

// Serves until `waiter` receives a signal (or the port file cannot be written), then shuts the
// server down; the process's exit code.
int RunServer(const softid::server::ServerOptions& options, const std::string& port_file,
              SignalWaiter& waiter) {
  softid::Result<std::unique_ptr<softid::server::Server>> server =
      softid::server::Server::Start(options);
  if (!server.ok()) {
    spdlog::error("{}", server.status().message());
    pthread_kill(waiter.thread.native_handle(), SIGTERM);
    waiter.thread.join();
    return server.status().code() == softid::StatusCode::kInvalidArgument ? kExitInvalidInput
                                                                          : kExitFailure;
  }
  bool port_file_failed = false;
  if (!port_file.empty()) {
    if (const softid::Status written = WritePortFile(port_file, (*server)->port()); !written.ok()) {
      spdlog::error("{}", written.message());
      port_file_failed = true;
      pthread_kill(waiter.thread.native_handle(), SIGTERM);
    }
  }
  waiter.thread.join();
  if (!port_file_failed) {
    spdlog::info("received {}", waiter.received == SIGTERM ? "SIGTERM" : "SIGINT");
  }
  const softid::Status closed = (*server)->Shutdown();
  if (!closed.ok()) {
    spdlog::error("{}", closed.message());
    return kExitFailure;
  }
  return port_file_failed ? kExitFailure : kExitOk;
}

}  // namespace

int main(int argc, char** argv) {
  // Links the start-up check that this CPU runs the build's instruction set.
  if (!softid::CpuSupportsBuild()) return 2;
  softid::fem::ConfigureNumericRuntime();  // CHOLMOD's OpenMP serialised, BLAS single-threaded
  CommandLine flags;
  flags.options.num_workers = DefaultWorkers();

  CLI::App app{"softid-server: queues and runs reconstruction jobs behind a gRPC API"};
  AddListenAndStorageFlags(app, flags);
  AddJobRunningFlags(app, flags);
  AddLimitFlags(app, flags);
  AddSecurityFlags(app, flags);
  AddOperationsFlags(app, flags);
  AddQuotaFlags(app, flags);
  softid::server::AddTokensCommand(app, &flags.tokens);
  AddOutputFlags(app, flags);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? kExitOk : kExitInvalidInput;
  }
  if (flags.tokens.command->parsed()) {
    return softid::server::RunTokensCommand(flags.tokens, flags.data_dir, flags.store_url);
  }
  if (!CopyFlagsIntoOptions(flags)) return kExitInvalidInput;
  // Files of the data directory (database, blobs) are private to the server's user.
  ::umask(077);
  ConvertUnitFlags(flags);
  const std::unique_ptr<softid::server::StderrCapture> stderr_capture = StartLogging(flags);

  SignalWaiter waiter;
  StartSignalWaiter(waiter);
  return RunServer(flags.options, flags.port_file, waiter);
}
