// A running softid server: the data directory (SQLite database, content-addressed blobs, staging
// and work folders), the job service, the worker pool and the gRPC server with health checking
// and reflection, wired together. main.cc adds only flags and signals; tests start it in-process.
//
// Data directory layout:
//   DIR/softid.db            jobs, captures, progress (WAL; schema migrated on start); not used
//                            with a PostgreSQL store (ServerOptions::store_url)
//   DIR/blobs/               uploaded files, content-addressed (blob_store.h)
//   DIR/uploads/, DIR/work/  staging of uploads and per-job capture folders; emptied on start
//   DIR/tls/                 the self-signed certificate and key (--tls-self-signed only)
#pragma once

#include <spdlog/logger.h>

#include <chrono>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <string_view>

#include "core/common/status.h"
#include "server/api_tokens.h"
#include "server/capture_upload.h"
#include "server/job_service.h"
#include "server/transport_security.h"

namespace softid::server {

// What one server process does (--role). Any number of each may share a PostgreSQL store and a
// data directory (one volume every process mounts).
enum class ServerRole {
  kAll,     // takes RPCs and runs jobs: the single-node default
  kApi,     // takes RPCs, never fits (no workers)
  kWorker,  // claims and runs jobs; serves only gRPC health (probes) and metrics
};
const char* ToString(ServerRole role);
// "all", "api" or "worker"; InvalidArgument naming --role and the value otherwise.
Result<ServerRole> ParseServerRole(std::string_view text);

struct ServerOptions {
  // "host:port"; port 0 picks a free port (see Server::port()).
  std::string listen_address = "localhost:50051";
  std::filesystem::path data_dir;
  // Where captures, jobs, progress and tokens live: empty for the SQLite database
  // data_dir/softid.db, or a postgresql:// URL for a PostgreSQL database that several servers may
  // share (--store). Blobs, staging and work folders stay under data_dir either way.
  std::string store_url;
  // Connections to a PostgreSQL store this process may hold at once (opened as needed); 0: the
  // workers plus 4 (a call holds one while it runs; the API's calls are short).
  int store_connections = 0;           // >= 0
  ServerRole role = ServerRole::kAll;  // kApi runs no workers whatever num_workers says
  int num_workers = 1;                 // >= 0; >= 1 for kWorker
  // A job's starts run as tasks any worker of any process sharing the store claims
  // (start_tasks.h); without it each job runs every start in its own worker. Workers run other
  // processes' start tasks either way.
  bool fan_out_starts = false;
  int64_t max_queued_jobs = 1000;  // >= 1
  // A job whose worker was lost (crash, kill -9, or shutdown mid-fit) is re-run until it was
  // started this many times, then FAILED: a job that crashes the server every time must not
  // crash it forever.
  int max_attempts = 3;  // >= 1
  std::chrono::milliseconds lease{60000};
  std::chrono::milliseconds heartbeat_interval{2000};
  std::chrono::milliseconds idle_poll_interval{1000};
  // Shutdown gives open RPCs (watches, uploads) this long before cancelling them.
  std::chrono::milliseconds shutdown_grace{3000};
  UploadLimits upload_limits;
  // Threads gRPC may run RPCs on; an RPC beyond them is answered RESOURCE_EXHAUSTED. Uploads and
  // watches hold one each while they stream.
  int max_rpc_threads = 256;  // >= 4
  // TLS for the port (transport_security.h). Without it the server listens only on a loopback
  // address unless allow_insecure is set.
  TlsOptions tls;
  bool allow_insecure = false;
  // Whether calls need a per-station API token (api_tokens.h). nullopt ("auto"): tokens on any
  // address but loopback, none on loopback.
  std::optional<AuthMode> auth;
  // "host:port" where GET /metrics serves Prometheus metrics (port 0 picks one); empty: off.
  std::string metrics_listen;
  // Jobs that ended and unused captures older than this are deleted (with their files), checked
  // at start and every retention_interval; nullopt: kept until deleted.
  std::optional<std::chrono::seconds> retention;
  std::chrono::milliseconds retention_interval{std::chrono::hours(1)};
  // With a shared store: blobs no capture lists are removed every this long once they are this
  // old (another process may be between storing an upload's files and committing it, which takes
  // seconds). A single node sweeps them at start instead.
  std::chrono::seconds orphan_blob_age{std::chrono::hours(1)};
  // What each station may use (job_service.h).
  StationQuotas quotas;
  // CreateJob refuses a job whose estimated memory exceeds this (inverse::JobResourceLimits).
  double max_job_memory_bytes = 4.0 * (1ull << 30);  // > 0
  // ... and whose estimated wall time exceeds this (an upper estimate: all iterations run).
  std::chrono::seconds max_job_wall_time{std::chrono::hours(24)};  // > 0

  // InvalidArgument naming the field and value.
  Status Validate() const;
};

class Server {
 public:
  // Opens (or creates) the data directory, migrates the schema, requeues jobs left RUNNING by a
  // previous process, starts the workers and listens. `logger` null means spdlog's default.
  static Result<std::unique_ptr<Server>> Start(const ServerOptions& options,
                                               std::shared_ptr<spdlog::logger> logger = nullptr);
  ~Server();  // Shutdown()
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  // The port actually bound.
  int port() const;
  // The port /metrics is served on; 0 when off.
  int metrics_port() const;
  // Drains: health NOT_SERVING, refuse new work, interrupt running fits (their jobs go back to
  // QUEUED without using up an attempt), end open RPCs within shutdown_grace, close the store.
  // Idempotent.
  Status Shutdown();

 private:
  struct Parts;
  explicit Server(std::unique_ptr<Parts> parts);
  std::unique_ptr<Parts> parts_;
};

}  // namespace softid::server
