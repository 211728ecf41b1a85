// Opens the job store a server is configured with: the embedded SQLite database under the data
// directory (the default), or a PostgreSQL database named by a postgresql:// URL (--store), which
// several servers can share. Either object is both the JobStore and the TokenStore.
#pragma once

#include <filesystem>
#include <memory>
#include <string>

#include "core/common/status.h"
#include "server/store/api_token.h"
#include "server/store/job_store.h"

namespace spdlog {
class logger;
}

namespace softid::server::store {

struct OpenedStore {
  std::unique_ptr<JobStore> jobs;
  TokenStore* tokens = nullptr;  // the same object as `jobs`
  std::string description;       // "SQLite DIR/softid.db" or the URL with its password redacted
};

// `store_url` empty: SQLite at data_dir/softid.db. Otherwise a postgresql:// (or postgres://) URL;
// any other value is InvalidArgument. Errors name the flag and the URL with its password redacted,
// e.g. "--store postgresql://softid:****@db:5432/softid: cannot connect: ...". PostgreSQL:
// `max_connections` (>= 1) bounds the connections this process opens (lazily).
Result<OpenedStore> OpenStore(const std::string& store_url, const std::filesystem::path& data_dir,
                              std::shared_ptr<spdlog::logger> logger = nullptr,
                              int max_connections = 4);

}  // namespace softid::server::store
