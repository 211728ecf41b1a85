#include "server/store/capture.h"

#include <set>
#include <string_view>

#include "core/common/json_fields.h"
#include "proto/capture_file_path.h"
#include "server/store/sha256.h"

namespace softid::server::store {
namespace {

std::string EntryField(size_t index, const char* field) {
  return "manifest[" + std::to_string(index) + "]." + field;
}

// What a file system holds per name and per path; longer names would fail only when staged.
constexpr size_t kMaxSegmentBytes = 255;
constexpr size_t kMaxPathBytes = 1024;

// Why `path` cannot be a file of a capture, or "" when it can.
std::string PathProblem(std::string_view path) {
  if (!api::IsSafeRelativePath(path)) {
    return "must be a relative '/'-separated path without '.' or '..' segments";
  }
  for (const char c : path) {
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) {
      return "must not contain control characters (newline, tab, ...)";
    }
  }
  if (path.size() > kMaxPathBytes) {
    return "must be at most " + std::to_string(kMaxPathBytes) + " bytes long";
  }
  size_t start = 0;
  while (start < path.size()) {
    const size_t end = std::min(path.find('/', start), path.size());
    if (end - start > kMaxSegmentBytes) {
      return "each name in it must be at most " + std::to_string(kMaxSegmentBytes) + " bytes long";
    }
    start = end + 1;
  }
  return "";
}

}  // namespace

Status ValidateManifest(const std::vector<ManifestEntry>& manifest) {
  if (manifest.empty()) {
    return Status::InvalidArgument("manifest = []: must list at least one file");
  }
  std::set<std::string_view> paths;
  for (size_t i = 0; i < manifest.size(); ++i) {
    const ManifestEntry& entry = manifest[i];
    if (const std::string problem = PathProblem(entry.path); !problem.empty()) {
      return json::Invalid(EntryField(i, "path"), entry.path, problem);
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
  // A name cannot be a file and a folder at once ("a" and "a/b").
  for (size_t i = 0; i < manifest.size(); ++i) {
    const std::string_view path = manifest[i].path;
    for (size_t slash = path.find('/'); slash != std::string_view::npos;
         slash = path.find('/', slash + 1)) {
      if (paths.contains(path.substr(0, slash))) {
        return json::Invalid(EntryField(i, "path"), manifest[i].path,
                             "lies in a folder named like the file \"" +
                                 std::string(path.substr(0, slash)) + "\" of the manifest");
      }
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
