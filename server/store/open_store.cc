#include "server/store/open_store.h"

#include <utility>

#include "server/store/postgres_connection.h"
#include "server/store/postgres_job_store.h"
#include "server/store/sqlite_job_store.h"

namespace softid::server::store {

Result<OpenedStore> OpenStore(const std::string& store_url, const std::filesystem::path& data_dir,
                              std::shared_ptr<spdlog::logger> logger, int max_connections) {
  OpenedStore opened;
  if (store_url.empty()) {
    SqliteJobStoreOptions options;
    options.logger = std::move(logger);
    const std::filesystem::path path = data_dir / "softid.db";
    SOFTID_ASSIGN_OR_RETURN(std::unique_ptr<SqliteJobStore> store,
                            SqliteJobStore::Open(path, options));
    opened.tokens = store.get();
    opened.jobs = std::move(store);
    opened.description = "SQLite " + path.string();
    return opened;
  }
  const std::string where = RedactPostgresUrl(store_url);
  if (!IsPostgresUrl(store_url)) {
    return Status::InvalidArgument("--store " + where +
                                   ": must be a postgresql:// URL (leave --store out for the "
                                   "SQLite database under --data)");
  }
  PostgresJobStoreOptions options;
  options.max_connections = max_connections;
  options.logger = std::move(logger);
  Result<std::unique_ptr<PostgresJobStore>> store = PostgresJobStore::Open(store_url, options);
  // The store's messages start with the redacted URL already; the flag tells the operator where
  // it came from.
  if (!store.ok()) return Status(store.status().code(), "--store " + store.status().message());
  opened.tokens = store->get();
  opened.jobs = std::move(store).value();
  opened.description = "PostgreSQL " + where;
  return opened;
}

}  // namespace softid::server::store
