#include "server/server.h"

#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/health_check_service_interface.h>
#include <grpcpp/resource_quota.h>
#include <grpcpp/security/server_credentials.h>
#include <grpcpp/server.h>
#include <grpcpp/server_builder.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <algorithm>
#include <map>
#include <mutex>
#include <set>
#include <shared_mutex>
#include <system_error>
#include <thread>

#include "server/grpc_reconstruction_service.h"
#include "server/job_events.h"
#include "server/job_service.h"
#include "server/metrics_http.h"
#include "server/orphan_blobs.h"
#include "server/periodic_task.h"
#include "server/self_signed_certificate.h"
#include "server/store/blob_store.h"
#include "server/store/open_store.h"
#include "server/worker_pool.h"

namespace softid::server {
namespace {

namespace fs = std::filesystem;

Status ResetFolder(const fs::path& dir) {
  std::error_code error;
  fs::remove_all(dir, error);
  if (!error) fs::create_directories(dir, error);
  if (error) return Status::IoError("cannot prepare " + dir.string() + ": " + error.message());
  return Status::Ok();
}

std::string HostName() {
  char name[256] = {};
  if (::gethostname(name, sizeof(name) - 1) != 0) return "host";
  return name;
}

// `options.tls` with a self-signed certificate's files filled in (made in DATA/tls/ if needed).
Result<TlsOptions> ResolveTls(const ServerOptions& options, spdlog::logger& log) {
  TlsOptions tls = options.tls;
  if (!tls.self_signed || !tls.cert_file.empty()) {
    tls.self_signed = false;  // a certificate of the operator's own takes precedence
    return tls;
  }
  SelfSignedCertificateOptions certificate_options;
  certificate_options.host_names = tls.host_names;
  SOFTID_ASSIGN_OR_RETURN(
      const SelfSignedCertificate certificate,
      EnsureSelfSignedCertificate(options.data_dir / "tls", certificate_options));
  if (!certificate.replaced_because.empty()) {
    log.warn("replaced the self-signed TLS certificate ({}): clients must copy the new {}",
             certificate.replaced_because, certificate.cert_file.string());
  }
  log.info(
      "TLS with the self-signed certificate {} (SHA-256 {}){}; clients trust it with "
      "--tls-ca",
      certificate.cert_file.string(), certificate.sha256_fingerprint,
      certificate.created ? ", made now" : "");
  tls.self_signed = false;
  tls.host_names.clear();
  tls.cert_file = certificate.cert_file;
  tls.key_file = certificate.key_file;
  return tls;
}

}  // namespace

const char* ToString(ServerRole role) {
  switch (role) {
    case ServerRole::kApi: return "api";
    case ServerRole::kWorker: return "worker";
    case ServerRole::kAll: break;
  }
  return "all";
}

Result<ServerRole> ParseServerRole(std::string_view text) {
  for (ServerRole role : {ServerRole::kAll, ServerRole::kApi, ServerRole::kWorker}) {
    if (text == ToString(role)) return role;
  }
  return Status::InvalidArgument("--role " + std::string(text) + ": must be all, api or worker");
}

Status ServerOptions::Validate() const {
  if (listen_address.empty()) return Status::InvalidArgument("listen = \"\": must be host:port");
  if (role == ServerRole::kWorker && num_workers < 1) {
    return Status::InvalidArgument("role = worker with workers = " + std::to_string(num_workers) +
                                   ": a worker needs at least one");
  }
  if (data_dir.empty()) return Status::InvalidArgument("data = \"\": a data directory is required");
  if (num_workers < 0) {
    return Status::InvalidArgument("workers = " + std::to_string(num_workers) +
                                   ": must not be negative");
  }
  if (store_connections < 0) {
    return Status::InvalidArgument("store_connections = " + std::to_string(store_connections) +
                                   ": must not be negative");
  }
  if (max_queued_jobs < 1) {
    return Status::InvalidArgument("max_queued = " + std::to_string(max_queued_jobs) +
                                   ": must be at least 1");
  }
  if (max_attempts < 1) {
    return Status::InvalidArgument("max_attempts = " + std::to_string(max_attempts) +
                                   ": must be at least 1");
  }
  if (lease < 2 * heartbeat_interval) {
    return Status::InvalidArgument("lease = " + std::to_string(lease.count() / 1000.0) +
                                   " s: must be at least twice the " +
                                   std::to_string(heartbeat_interval.count() / 1000.0) +
                                   " s heartbeat, or a busy worker loses its jobs");
  }
  SOFTID_RETURN_IF_ERROR(tls.Validate());
  if (!tls.enabled() && !allow_insecure && !IsLoopbackAddress(listen_address)) {
    return Status::InvalidArgument(
        "listen = " + listen_address +
        ": not a loopback address, and TLS is off: give --tls-cert and --tls-key, or "
        "--tls-self-signed, or --allow-insecure to serve in plain text anyway (only behind a "
        "trusted network)");
  }
  if (quotas.max_queued_jobs < 1 || quotas.max_stored_bytes < 1 ||
      quotas.max_concurrent_uploads < 1) {
    return Status::InvalidArgument(
        "quota-queued-jobs, quota-stored-gib and quota-uploads must be "
        "positive");
  }
  if (max_rpc_threads < 4) {
    return Status::InvalidArgument("max_rpc_threads = " + std::to_string(max_rpc_threads) +
                                   ": must be at least 4");
  }
  if (upload_limits.max_concurrent < 1) {
    return Status::InvalidArgument("max_uploads = " + std::to_string(upload_limits.max_concurrent) +
                                   ": must be at least 1");
  }
  if (upload_limits.idle_timeout.count() <= 0) {
    return Status::InvalidArgument(
        "upload_idle_timeout = " + std::to_string(upload_limits.idle_timeout.count()) +
        " ms: must be positive");
  }
  if (!(max_job_memory_bytes > 0.0)) {
    return Status::InvalidArgument("max_job_memory = " + std::to_string(max_job_memory_bytes) +
                                   " bytes: must be positive");
  }
  if (max_job_wall_time.count() <= 0) {
    return Status::InvalidArgument(
        "max_job_hours = " + std::to_string(max_job_wall_time.count() / 3600.0) +
        ": must be positive");
  }
  if (heartbeat_interval.count() <= 0 || lease <= heartbeat_interval) {
    return Status::InvalidArgument("lease = " + std::to_string(lease.count()) +
                                   " ms: must exceed the heartbeat interval (" +
                                   std::to_string(heartbeat_interval.count()) + " ms)");
  }
  return Status::Ok();
}

// Members in construction order; destroyed in reverse (gRPC before the service it calls).
struct Server::Parts {
  ServerOptions options;
  std::shared_ptr<spdlog::logger> logger;
  std::unique_ptr<store::JobStore> jobs;
  store::TokenStore* tokens = nullptr;  // the same object as `jobs`
  std::optional<store::BlobStore> blobs;
  JobEvents events;
  Metrics metrics;  // before everything that counts into it
  // Orders blob puts (uploads, ingests) with removals of unreferenced blobs.
  std::shared_mutex blob_puts;
  std::optional<JobReports> reports;  // <data>/reports
  std::unique_ptr<WorkerPool> pool;
  std::unique_ptr<JobService> service;
  std::unique_ptr<Authenticator> authenticator;
  std::unique_ptr<GrpcReconstructionService> grpc_service;
  std::unique_ptr<MetricsHttpServer> metrics_http;
  std::unique_ptr<PeriodicTask> retention;
  std::unique_ptr<PeriodicTask> lease_sweep;   // PostgreSQL store only
  std::unique_ptr<PeriodicTask> orphan_sweep;  // PostgreSQL store only
  std::unique_ptr<grpc::Server> grpc_server;
  int port = 0;
  std::mutex shutdown_mutex;
  bool shut_down = false;
};

Result<std::unique_ptr<Server>> Server::Start(const ServerOptions& requested,
                                              std::shared_ptr<spdlog::logger> logger) {
  SOFTID_RETURN_IF_ERROR(requested.Validate());
  ServerOptions options = requested;
  if (options.role == ServerRole::kApi) options.num_workers = 0;  // an API process never fits
  auto parts = std::make_unique<Parts>();
  parts->options = options;
  parts->logger = logger ? std::move(logger) : spdlog::default_logger();
  const auto& log = parts->logger;

  std::error_code error;
  fs::create_directories(options.data_dir, error);
  if (error) {
    return Status::IoError("cannot create data directory " + options.data_dir.string() + ": " +
                           error.message());
  }
  // The database and uploads are the stations' data: readable by this user only, whatever the
  // umask (main sets 077 for the files created later).
  fs::permissions(options.data_dir, fs::perms::owner_all, fs::perm_options::replace, error);
  if (error) {
    log->warn("cannot restrict the data directory's permissions: {}", error.message());
    error.clear();
  }
  // With a shared store several processes may share the data directory: each stages uploads and
  // runs jobs in folders of its own (a crashed process's are left for the operator).
  const bool shared_store = !options.store_url.empty();
  const std::string node = HostName() + "-" + std::to_string(::getpid());
  const fs::path staging = options.data_dir / "uploads" / (shared_store ? node : "");
  const fs::path work = options.data_dir / "work" / (shared_store ? node : "");
  SOFTID_RETURN_IF_ERROR(ResetFolder(staging));
  SOFTID_RETURN_IF_ERROR(ResetFolder(work));
  SOFTID_ASSIGN_OR_RETURN(const TlsOptions tls, ResolveTls(options, *log));

  SOFTID_ASSIGN_OR_RETURN(
      store::OpenedStore opened,
      store::OpenStore(
          options.store_url, options.data_dir, parts->logger,
          options.store_connections > 0 ? options.store_connections : options.num_workers + 4));
  parts->jobs = std::move(opened.jobs);
  parts->tokens = opened.tokens;
  log->info("job store: {}", opened.description);
  SOFTID_ASSIGN_OR_RETURN(store::BlobStore blobs, store::BlobStore::Open(options.data_dir));
  parts->blobs.emplace(std::move(blobs));
  // No worker of this process runs yet, so every RUNNING job in the embedded store was left by a
  // previous one. A PostgreSQL store may be shared: other servers' workers may be running its
  // RUNNING jobs, and only an expired lease marks a job as lost (the lease sweep below).
  SOFTID_ASSIGN_OR_RETURN(
      const store::RecoverySummary recovered,
      parts->jobs->RecoverAfterCrash(options.max_attempts,
                                     shared_store ? store::RecoveryScope::kExpiredLeasesOnly
                                                  : store::RecoveryScope::kAllRunning));
  if (recovered.total() > 0) {
    log->info("recovered {} job(s) left RUNNING: {} requeued, {} failed, {} cancelled",
              recovered.total(), recovered.num_requeued, recovered.num_failed,
              recovered.num_cancelled);
  }

  // Another process sharing the data directory may be between its blob puts and its commit.
  if (!shared_store) RemoveOrphanBlobs(*parts->jobs, *parts->blobs, std::chrono::seconds(0), log);
  parts->reports.emplace(options.data_dir / "reports");

  WorkerPoolOptions pool_options;
  pool_options.num_workers = options.num_workers;
  pool_options.lease = options.lease;
  pool_options.max_attempts = options.max_attempts;
  pool_options.heartbeat_interval = options.heartbeat_interval;
  pool_options.idle_poll_interval = options.idle_poll_interval;
  pool_options.work_root = work;
  pool_options.worker_id_prefix = node;
  pool_options.metrics = &parts->metrics;
  pool_options.blob_puts = &parts->blob_puts;
  pool_options.reports = &*parts->reports;
  pool_options.fan_out_starts = options.fan_out_starts;
  parts->pool = std::make_unique<WorkerPool>(parts->jobs.get(), &*parts->blobs, &parts->events,
                                             pool_options, parts->logger);

  JobServiceOptions service_options;
  service_options.max_queued_jobs = options.max_queued_jobs;
  service_options.upload_limits = options.upload_limits;
  service_options.staging_root = staging;
  service_options.scratch_root = work;
  service_options.quotas = options.quotas;
  service_options.metrics = &parts->metrics;
  service_options.blob_puts = &parts->blob_puts;
  service_options.reports = &*parts->reports;
  service_options.job_limits.max_memory_bytes = options.max_job_memory_bytes;
  service_options.job_limits.max_wall_seconds =
      static_cast<double>(options.max_job_wall_time.count());
  const int cores = static_cast<int>(std::thread::hardware_concurrency());
  service_options.job_limits.cores = std::max(1, cores / std::max(1, options.num_workers));
  if (options.num_workers == 0 && options.role != ServerRole::kApi) {
    log->warn(
        "--workers 0: this process runs no jobs; they stay QUEUED until a server with "
        "workers serves this data directory");
  }
  WorkerPool* pool = parts->pool.get();
  service_options.on_job_queued = [pool] { pool->Wake(); };
  parts->service = std::make_unique<JobService>(parts->jobs.get(), &*parts->blobs, &parts->events,
                                                service_options, parts->logger);
  const AuthMode auth = options.auth.value_or(
      IsLoopbackAddress(options.listen_address) ? AuthMode::kNone : AuthMode::kToken);
  parts->authenticator = std::make_unique<Authenticator>(parts->tokens, auth);
  if (auth == AuthMode::kToken) {
    Result<std::vector<store::ApiToken>> tokens = parts->tokens->ListTokens();
    if (tokens.ok() && tokens->empty()) {
      log->warn(
          "API tokens are required but none exists: create one with `softid-server tokens "
          "create --data {} --station NAME`",
          options.data_dir.string());
    }
  }
  parts->grpc_service = std::make_unique<GrpcReconstructionService>(
      parts->service.get(), parts->authenticator.get(), &parts->metrics, options.data_dir,
      options.upload_limits.idle_timeout, parts->logger);

  grpc::EnableDefaultHealthCheckService(true);
  grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  grpc::ServerBuilder builder;
  // Without SO_REUSEPORT: gRPC otherwise opens a second listener per port, which for port 0 gets
  // a port of its own that nobody is told about, and another process could bind ours.
  builder.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
  grpc::ResourceQuota quota("softid-server");
  quota.SetMaxThreads(options.max_rpc_threads);
  builder.SetResourceQuota(quota);
  SOFTID_ASSIGN_OR_RETURN(std::shared_ptr<grpc::ServerCredentials> credentials,
                          MakeServerCredentials(tls));
  builder.AddListeningPort(options.listen_address, credentials, &parts->port);
  // A worker answers health probes only: stations talk to the API processes.
  if (options.role != ServerRole::kWorker) builder.RegisterService(parts->grpc_service.get());
  parts->grpc_server = builder.BuildAndStart();
  if (parts->grpc_server == nullptr || parts->port == 0) {
    parts->pool.reset();
    (void)parts->jobs->Close();
    return Status::IoError("cannot listen on " + options.listen_address);
  }
  if (options.role != ServerRole::kWorker) {
    parts->grpc_server->GetHealthCheckService()->SetServingStatus(
        v1::Reconstruction::service_full_name(), true);
  }
  if (!options.metrics_listen.empty()) {
    store::JobStore* jobs = parts->jobs.get();
    const Metrics* metrics = &parts->metrics;
    SOFTID_ASSIGN_OR_RETURN(
        parts->metrics_http, MetricsHttpServer::Start(options.metrics_listen, [jobs, metrics] {
          std::map<std::string, int64_t> by_state;
          for (store::JobState state :
               {store::JobState::kQueued, store::JobState::kRunning, store::JobState::kSucceeded,
                store::JobState::kFailed, store::JobState::kCancelled}) {
            Result<int64_t> count = jobs->CountJobs(state);
            if (count.ok()) by_state[store::ToString(state)] = *count;
          }
          return metrics->Render(by_state);
        }));
    log->info("metrics on http://{}/metrics (port {})", options.metrics_listen,
              parts->metrics_http->port());
  }
  if (options.retention.has_value()) {
    JobService* service = parts->service.get();
    const std::chrono::seconds age = *options.retention;
    parts->retention = std::make_unique<PeriodicTask>(
        options.retention_interval, [service, age] { (void)service->RemoveOlderThan(age); });
  }
  if (shared_store) {
    // A job whose worker died (here or on another server) runs again about one lease after its
    // last heartbeat, without waiting for a restart.
    store::JobStore* jobs = parts->jobs.get();
    WorkerPool* workers = parts->pool.get();
    const int max_attempts = options.max_attempts;
    // Blobs an upload or ingest left behind on any process sharing the data directory.
    const store::BlobStore* blobs = &*parts->blobs;
    std::shared_mutex* puts = &parts->blob_puts;
    const std::chrono::seconds age = options.orphan_blob_age;
    parts->orphan_sweep = std::make_unique<PeriodicTask>(
        std::chrono::duration_cast<std::chrono::milliseconds>(age), [jobs, blobs, puts, age, log] {
          std::unique_lock lock(*puts);
          RemoveOrphanBlobs(*jobs, *blobs, age, log);
        });
    parts->lease_sweep =
        std::make_unique<PeriodicTask>(options.lease, [jobs, workers, max_attempts, log] {
          Result<store::RecoverySummary> swept =
              jobs->RecoverAfterCrash(max_attempts, store::RecoveryScope::kExpiredLeasesOnly);
          if (!swept.ok()) {
            log->warn("lease sweep: {}", swept.status().message());
          } else if (swept->total() > 0) {
            log->info(
                "lease sweep: {} job(s) whose lease expired: {} requeued, {} failed, {} "
                "cancelled",
                swept->total(), swept->num_requeued, swept->num_failed, swept->num_cancelled);
            workers->Wake();
          }
        });
  }
  parts->pool->Start();
  log->info(
      "softid-server ({}) listening on {} (port {}, {}, auth {}), data {}, {} worker(s), max {} "
      "queued",
      ToString(options.role), options.listen_address, parts->port,
      options.tls.enabled() ? "TLS" : "plain text", ToString(auth), options.data_dir.string(),
      options.num_workers, options.max_queued_jobs);
  return std::unique_ptr<Server>(new Server(std::move(parts)));
}

Server::Server(std::unique_ptr<Parts> parts) : parts_(std::move(parts)) {}

Server::~Server() {
  if (Status closed = Shutdown(); !closed.ok()) {
    parts_->logger->error("shutdown: {}", closed.message());
  }
}

int Server::port() const {
  return parts_->port;
}

int Server::metrics_port() const {
  return parts_->metrics_http ? parts_->metrics_http->port() : 0;
}

Status Server::Shutdown() {
  std::lock_guard lock(parts_->shutdown_mutex);
  if (parts_->shut_down) return Status::Ok();
  parts_->shut_down = true;
  const auto& log = parts_->logger;
  log->info("shutting down: NOT_SERVING, no new jobs, interrupting running fits");
  parts_->grpc_server->GetHealthCheckService()->SetServingStatus(false);
  parts_->retention.reset();
  parts_->lease_sweep.reset();
  parts_->service->StartDraining();
  parts_->pool->Stop();
  parts_->grpc_server->Shutdown(std::chrono::system_clock::now() + parts_->options.shutdown_grace);
  parts_->grpc_server->Wait();
  parts_->metrics_http.reset();  // scrapes read the store
  Status closed = parts_->jobs->Close();
  log->info("shut down");
  return closed;
}

}  // namespace softid::server
