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

// Where this process stages uploads and runs jobs.
struct NodeFolders {
  bool shared_store = false;  // a PostgreSQL store other processes may share
  std::string node;           // "<host>-<pid>": names this process's folders and workers
  fs::path staging;
  fs::path work;
};

// Creates the data directory (readable by this user only) and this process's empty staging and
// work folders in it.
Result<NodeFolders> PrepareDataDirectory(const ServerOptions& options, spdlog::logger& log) {
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
    log.warn("cannot restrict the data directory's permissions: {}", error.message());
    error.clear();
  }
  // With a shared store several processes may share the data directory: each stages uploads and
  // runs jobs in folders of its own (a crashed process's are left for the operator).
  NodeFolders folders;
  folders.shared_store = !options.store_url.empty();
  folders.node = HostName() + "-" + std::to_string(::getpid());
  folders.staging = options.data_dir / "uploads" / (folders.shared_store ? folders.node : "");
  folders.work = options.data_dir / "work" / (folders.shared_store ? folders.node : "");
  SOFTID_RETURN_IF_ERROR(ResetFolder(folders.staging));
  SOFTID_RETURN_IF_ERROR(ResetFolder(folders.work));
  return folders;
}

// ServerOptions::Validate's checks, in its order: listening, data, workers, queue and lease.
Status ValidateProcessOptions(const ServerOptions& options) {
  if (options.listen_address.empty()) {
    return Status::InvalidArgument("listen = \"\": must be host:port");
  }
  if (options.role == ServerRole::kWorker && options.num_workers < 1) {
    return Status::InvalidArgument(
        "role = worker with workers = " + std::to_string(options.num_workers) +
        ": a worker needs at least one");
  }
  if (options.data_dir.empty()) {
    return Status::InvalidArgument("data = \"\": a data directory is required");
  }
  if (options.num_workers < 0) {
    return Status::InvalidArgument("workers = " + std::to_string(options.num_workers) +
                                   ": must not be negative");
  }
  if (options.store_connections < 0) {
    return Status::InvalidArgument(
        "store_connections = " + std::to_string(options.store_connections) +
        ": must not be negative");
  }
  if (options.max_queued_jobs < 1) {
    return Status::InvalidArgument("max_queued = " + std::to_string(options.max_queued_jobs) +
                                   ": must be at least 1");
  }
  if (options.max_attempts < 1) {
    return Status::InvalidArgument("max_attempts = " + std::to_string(options.max_attempts) +
                                   ": must be at least 1");
  }
  if (options.lease < 2 * options.heartbeat_interval) {
    return Status::InvalidArgument("lease = " + std::to_string(options.lease.count() / 1000.0) +
                                   " s: must be at least twice the " +
                                   std::to_string(options.heartbeat_interval.count() / 1000.0) +
                                   " s heartbeat, or a busy worker loses its jobs");
  }
  return Status::Ok();
}

// TLS, which a non-loopback address needs unless plain text was asked for.
Status ValidateTransport(const ServerOptions& options) {
  SOFTID_RETURN_IF_ERROR(options.tls.Validate());
  if (!options.tls.enabled() && !options.allow_insecure &&
      !IsLoopbackAddress(options.listen_address)) {
    return Status::InvalidArgument(
        "listen = " + options.listen_address +
        ": not a loopback address, and TLS is off: give --tls-cert and --tls-key, or "
        "--tls-self-signed, or --allow-insecure to serve in plain text anyway (only behind a "
        "trusted network)");
  }
  return Status::Ok();
}

// Quotas, RPC threads, uploads and the limits of one job.
Status ValidateResourceLimits(const ServerOptions& options) {
  const StationQuotas& quotas = options.quotas;
  if (quotas.max_queued_jobs < 1 || quotas.max_stored_bytes < 1 ||
      quotas.max_concurrent_uploads < 1) {
    return Status::InvalidArgument(
        "quota-queued-jobs, quota-stored-gib and quota-uploads must be "
        "positive");
  }
  if (options.max_rpc_threads < 4) {
    return Status::InvalidArgument("max_rpc_threads = " + std::to_string(options.max_rpc_threads) +
                                   ": must be at least 4");
  }
  const UploadLimits& upload_limits = options.upload_limits;
  if (upload_limits.max_concurrent < 1) {
    return Status::InvalidArgument("max_uploads = " + std::to_string(upload_limits.max_concurrent) +
                                   ": must be at least 1");
  }
  if (upload_limits.idle_timeout.count() <= 0) {
    return Status::InvalidArgument(
        "upload_idle_timeout = " + std::to_string(upload_limits.idle_timeout.count()) +
        " ms: must be positive");
  }
  if (!(options.max_job_memory_bytes > 0.0)) {
    return Status::InvalidArgument(
        "max_job_memory = " + std::to_string(options.max_job_memory_bytes) +
        " bytes: must be positive");
  }
  if (options.max_job_wall_time.count() <= 0) {
    return Status::InvalidArgument(
        "max_job_hours = " + std::to_string(options.max_job_wall_time.count() / 3600.0) +
        ": must be positive");
  }
  return Status::Ok();
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
  SOFTID_RETURN_IF_ERROR(ValidateProcessOptions(*this));
  SOFTID_RETURN_IF_ERROR(ValidateTransport(*this));
  SOFTID_RETURN_IF_ERROR(ValidateResourceLimits(*this));
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

  // The stages of Server::Start, in its order.
  Status OpenStores(bool shared_store);
  void CreateWorkerPool(const NodeFolders& folders);
  void CreateJobService(const NodeFolders& folders);
  AuthMode CreateGrpcService();
  Status Listen(const TlsOptions& tls);
  Status StartMetricsHttp();
  void StartRetention();
  void StartSharedStoreSweeps();
};

// The job and blob stores, with the jobs a previous process left RUNNING recovered.
Status Server::Parts::OpenStores(bool shared_store) {
  const auto& log = logger;
  SOFTID_ASSIGN_OR_RETURN(
      store::OpenedStore opened,
      store::OpenStore(
          options.store_url, options.data_dir, logger,
          options.store_connections > 0 ? options.store_connections : options.num_workers + 4));
  jobs = std::move(opened.jobs);
  tokens = opened.tokens;
  log->info("job store: {}", opened.description);
  SOFTID_ASSIGN_OR_RETURN(store::BlobStore opened_blobs, store::BlobStore::Open(options.data_dir));
  blobs.emplace(std::move(opened_blobs));
  // No worker of this process runs yet, so every RUNNING job in the embedded store was left by a
  // previous one. A PostgreSQL store may be shared: other servers' workers may be running its
  // RUNNING jobs, and only an expired lease marks a job as lost (StartSharedStoreSweeps).
  SOFTID_ASSIGN_OR_RETURN(
      const store::RecoverySummary recovered,
      jobs->RecoverAfterCrash(options.max_attempts, shared_store
                                                        ? store::RecoveryScope::kExpiredLeasesOnly
                                                        : store::RecoveryScope::kAllRunning));
  if (recovered.total() > 0) {
    log->info("recovered {} job(s) left RUNNING: {} requeued, {} failed, {} cancelled",
              recovered.total(), recovered.num_requeued, recovered.num_failed,
              recovered.num_cancelled);
  }

  // Another process sharing the data directory may be between its blob puts and its commit.
  if (!shared_store) RemoveOrphanBlobs(*jobs, *blobs, std::chrono::seconds(0), log);
  reports.emplace(options.data_dir / "reports");
  return Status::Ok();
}

void Server::Parts::CreateWorkerPool(const NodeFolders& folders) {
  WorkerPoolOptions pool_options;
  pool_options.num_workers = options.num_workers;
  pool_options.lease = options.lease;
  pool_options.max_attempts = options.max_attempts;
  pool_options.heartbeat_interval = options.heartbeat_interval;
  pool_options.idle_poll_interval = options.idle_poll_interval;
  pool_options.work_root = folders.work;
  pool_options.worker_id_prefix = folders.node;
  pool_options.metrics = &metrics;
  pool_options.blob_puts = &blob_puts;
  pool_options.reports = &*reports;
  pool_options.fan_out_starts = options.fan_out_starts;
  pool = std::make_unique<WorkerPool>(jobs.get(), &*blobs, &events, pool_options, logger);
}

void Server::Parts::CreateJobService(const NodeFolders& folders) {
  const auto& log = logger;
  JobServiceOptions service_options;
  service_options.max_queued_jobs = options.max_queued_jobs;
  service_options.upload_limits = options.upload_limits;
  service_options.staging_root = folders.staging;
  service_options.scratch_root = folders.work;
  service_options.quotas = options.quotas;
  service_options.metrics = &metrics;
  service_options.blob_puts = &blob_puts;
  service_options.reports = &*reports;
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
  WorkerPool* workers = pool.get();
  service_options.on_job_queued = [workers] { workers->Wake(); };
  service = std::make_unique<JobService>(jobs.get(), &*blobs, &events, service_options, logger);
}

// The authenticator and the gRPC service over the job service; the authentication it enforces.
AuthMode Server::Parts::CreateGrpcService() {
  const auto& log = logger;
  const AuthMode auth = options.auth.value_or(
      IsLoopbackAddress(options.listen_address) ? AuthMode::kNone : AuthMode::kToken);
  authenticator = std::make_unique<Authenticator>(tokens, auth);
  if (auth == AuthMode::kToken) {
    Result<std::vector<store::ApiToken>> listed = tokens->ListTokens();
    if (listed.ok() && listed->empty()) {
      log->warn(
          "API tokens are required but none exists: create one with `softid-server tokens "
          "create --data {} --station NAME`",
          options.data_dir.string());
    }
  }
  grpc_service = std::make_unique<GrpcReconstructionService>(
      service.get(), authenticator.get(), &metrics, options.data_dir,
      options.upload_limits.idle_timeout, logger);
  return auth;
}

// Builds and starts the gRPC server on the listen address; on failure stops what started.
Status Server::Parts::Listen(const TlsOptions& tls) {
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
  builder.AddListeningPort(options.listen_address, credentials, &port);
  // A worker answers health probes only: stations talk to the API processes.
  if (options.role != ServerRole::kWorker) builder.RegisterService(grpc_service.get());
  grpc_server = builder.BuildAndStart();
  if (grpc_server == nullptr || port == 0) {
    pool.reset();
    (void)jobs->Close();
    return Status::IoError("cannot listen on " + options.listen_address);
  }
  if (options.role != ServerRole::kWorker) {
    grpc_server->GetHealthCheckService()->SetServingStatus(v1::Reconstruction::service_full_name(),
                                                           true);
  }
  return Status::Ok();
}

// Serves /metrics when metrics_listen asks for it.
Status Server::Parts::StartMetricsHttp() {
  if (options.metrics_listen.empty()) return Status::Ok();
  const auto& log = logger;
  store::JobStore* job_store = jobs.get();
  const Metrics* counters = &metrics;
  SOFTID_ASSIGN_OR_RETURN(
      metrics_http, MetricsHttpServer::Start(options.metrics_listen, [job_store, counters] {
        std::map<std::string, int64_t> by_state;
        for (store::JobState state :
             {store::JobState::kQueued, store::JobState::kRunning, store::JobState::kSucceeded,
              store::JobState::kFailed, store::JobState::kCancelled}) {
          Result<int64_t> count = job_store->CountJobs(state);
          if (count.ok()) by_state[store::ToString(state)] = *count;
        }
        return counters->Render(by_state);
      }));
  log->info("metrics on http://{}/metrics (port {})", options.metrics_listen, metrics_http->port());
  return Status::Ok();
}

// Removes old jobs periodically when a retention is set.
void Server::Parts::StartRetention() {
  if (!options.retention.has_value()) return;
  JobService* job_service = service.get();
  const std::chrono::seconds age = *options.retention;
  retention = std::make_unique<PeriodicTask>(
      options.retention_interval, [job_service, age] { (void)job_service->RemoveOlderThan(age); });
}

void Server::Parts::StartSharedStoreSweeps() {
  const auto& log = logger;
  // A job whose worker died (here or on another server) runs again about one lease after its
  // last heartbeat, without waiting for a restart.
  store::JobStore* job_store = jobs.get();
  WorkerPool* workers = pool.get();
  const int max_attempts = options.max_attempts;
  // Blobs an upload or ingest left behind on any process sharing the data directory.
  const store::BlobStore* blob_store = &*blobs;
  std::shared_mutex* puts = &blob_puts;
  const std::chrono::seconds age = options.orphan_blob_age;
  orphan_sweep =
      std::make_unique<PeriodicTask>(std::chrono::duration_cast<std::chrono::milliseconds>(age),
                                     [job_store, blob_store, puts, age, log] {
                                       std::unique_lock lock(*puts);
                                       RemoveOrphanBlobs(*job_store, *blob_store, age, log);
                                     });
  lease_sweep =
      std::make_unique<PeriodicTask>(options.lease, [job_store, workers, max_attempts, log] {
        Result<store::RecoverySummary> swept =
            job_store->RecoverAfterCrash(max_attempts, store::RecoveryScope::kExpiredLeasesOnly);
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

Result<std::unique_ptr<Server>> Server::Start(const ServerOptions& requested,
                                              std::shared_ptr<spdlog::logger> logger) {
  SOFTID_RETURN_IF_ERROR(requested.Validate());
  ServerOptions options = requested;
  if (options.role == ServerRole::kApi) options.num_workers = 0;  // an API process never fits
  auto parts = std::make_unique<Parts>();
  parts->options = options;
  parts->logger = logger ? std::move(logger) : spdlog::default_logger();
  const auto& log = parts->logger;

  SOFTID_ASSIGN_OR_RETURN(const NodeFolders folders, PrepareDataDirectory(options, *log));
  SOFTID_ASSIGN_OR_RETURN(const TlsOptions tls, ResolveTls(options, *log));
  SOFTID_RETURN_IF_ERROR(parts->OpenStores(folders.shared_store));
  parts->CreateWorkerPool(folders);
  parts->CreateJobService(folders);
  const AuthMode auth = parts->CreateGrpcService();
  SOFTID_RETURN_IF_ERROR(parts->Listen(tls));
  SOFTID_RETURN_IF_ERROR(parts->StartMetricsHttp());
  parts->StartRetention();
  if (folders.shared_store) parts->StartSharedStoreSweeps();
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
