// Blobs no capture lists: left by an upload or an ingest killed between storing its files and
// committing its capture. A single node sweeps them at start (nothing of its own runs yet); nodes
// sharing a store and a data directory sweep periodically, and only blobs older than `min_age`,
// since another process may be between its puts and its commit (seconds, in practice).
#pragma once

#include <spdlog/logger.h>

#include <chrono>
#include <memory>

#include "server/store/blob_store.h"
#include "server/store/job_store.h"

namespace softid::server {

// Removes the blobs no capture lists whose files were last written more than `min_age` ago
// (0: all of them). Returns how many went; a store or listing error is logged and removes
// nothing.
int RemoveOrphanBlobs(store::JobStore& jobs, const store::BlobStore& blobs,
                      std::chrono::seconds min_age, const std::shared_ptr<spdlog::logger>& log);

}  // namespace softid::server
