#include "server/store/capture.h"

#include <set>
#include <string_view>

#include "core/common/json_fields.h"
#include "server/store/sha256.h"

namespace softid::server::store {
namespace {

std::string EntryField(size_t index, const char* field) {
  return "manifest[" + std::to_string(index) + "]." + field;
}

// A relative '/'-separated path that cannot escape the directory it is written into.
bool IsSafeRelativePath(std::string_view path) {
  if (path.empty() || path.front() == '/' || path.find('\\') != std::string_view::npos ||
      path.find('\0') != std::string_view::npos) {
    return false;
  }
  size_t start = 0;
  while (start <= path.size()) {
    const size_t end = std::min(path.find('/', start), path.size());
    const std::string_view segment = path.substr(start, end - start);
    if (segment.empty() || segment == "." || segment == "..") return false;
    start = end + 1;
  }
  return true;
}

}  // namespace

Status ValidateManifest(const std::vector<ManifestEntry>& manifest) {
  if (manifest.empty()) {
    return Status::InvalidArgument("manifest = []: must list at least one file");
  }
  std::set<std::string_view> paths;
  for (size_t i = 0; i < manifest.size(); ++i) {
    const ManifestEntry& entry = manifest[i];
    if (!IsSafeRelativePath(entry.path)) {
      return json::Invalid(EntryField(i, "path"), entry.path,
                           "must be a relative '/'-separated path without '.' or '..' segments");
    }
    if (!paths.insert(entry.path).second) {
      return json::Invalid(EntryField(i, "path"), entry.path, "appears twice in the manifest");
    }
    if (!Sha256::IsValidHex(entry.sha256)) {
      return json::Invalid(EntryField(i, "sha256"), entry.sha256,
                           "must be 64 lowercase hex digits");
    }
    if (entry.size_bytes < 0) {
      return json::Invalid(EntryField(i, "size"), entry.size_bytes, "must be non-negative");
    }
  }
  return Status::Ok();
}

nlohmann::json ManifestToJson(const std::vector<ManifestEntry>& manifest) {
  nlohmann::json out = nlohmann::json::array();
  for (const ManifestEntry& entry : manifest) {
    out.push_back({{"path", entry.path}, {"sha256", entry.sha256}, {"size", entry.size_bytes}});
  }
  return out;
}

Result<std::vector<ManifestEntry>> ManifestFromJson(const nlohmann::json& json) {
  if (!json.is_array()) return json::Invalid("manifest", json, "must be an array");
  std::vector<ManifestEntry> manifest;
  for (size_t i = 0; i < json.size(); ++i) {
    const nlohmann::json& item = json[i];
    if (!item.is_object()) {
      return json::Invalid("manifest[" + std::to_string(i) + "]", item, "must be an object");
    }
    ManifestEntry entry;
    for (const char* key : {"path", "sha256", "size"}) {
      if (!item.contains(key)) {
        return json::Invalid(EntryField(i, key), nullptr, "is required");
      }
    }
    SOFTID_ASSIGN_OR_RETURN(entry.path, json::ToString(item["path"], EntryField(i, "path")));
    SOFTID_ASSIGN_OR_RETURN(entry.sha256, json::ToString(item["sha256"], EntryField(i, "sha256")));
    const nlohmann::json& size = item["size"];
    if (!size.is_number_integer()) {
      return json::Invalid(EntryField(i, "size"), size, "must be an integer number of bytes");
    }
    entry.size_bytes = size.get<int64_t>();
    manifest.push_back(std::move(entry));
  }
  SOFTID_RETURN_IF_ERROR(ValidateManifest(manifest));
  return manifest;
}

}  // namespace softid::server::store
