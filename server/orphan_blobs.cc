#include "server/orphan_blobs.h"

#include <filesystem>
#include <set>
#include <string>
#include <system_error>
#include <vector>

namespace softid::server {

int RemoveOrphanBlobs(store::JobStore& jobs, const store::BlobStore& blobs,
                      std::chrono::seconds min_age, const std::shared_ptr<spdlog::logger>& log) {
  Result<std::vector<std::string>> hashes = blobs.List();
  if (!hashes.ok()) {
    log->warn("orphan blob sweep skipped: {}", hashes.status().message());
    return 0;
  }
  Result<std::vector<std::string>> listed = jobs.ListReferencedBlobs();
  if (!listed.ok()) {
    log->warn("orphan blob sweep skipped: {}", listed.status().message());
    return 0;
  }
  const std::set<std::string> referenced(listed->begin(), listed->end());
  const auto cutoff = std::filesystem::file_time_type::clock::now() - min_age;
  int removed = 0;
  for (const std::string& sha256 : *hashes) {
    if (referenced.contains(sha256)) continue;
    if (min_age.count() > 0) {
      Result<std::filesystem::path> path = blobs.PathOf(sha256);
      std::error_code error;
      if (!path.ok()) continue;
      const auto written = std::filesystem::last_write_time(*path, error);
      if (error || written > cutoff) continue;  // perhaps an upload about to commit
    }
    if (blobs.Remove(sha256).ok()) ++removed;
  }
  if (removed > 0) log->info("removed {} blob(s) that no capture refers to", removed);
  return removed;
}

}  // namespace softid::server
