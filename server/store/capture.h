// An uploaded depth capture as the store keeps it: a manifest of files whose bytes live in the
// BlobStore under their sha256. The manifest is stored as JSON text:
//   [{"path": "frames/cam0_0000.png", "sha256": "<64 hex>", "size": 614400}, ...]
#pragma once

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>
#include <vector>

#include "core/common/status.h"
#include "server/store/timestamp.h"

namespace softid::server::store {

struct ManifestEntry {
  std::string path;    // relative to the capture root, '/'-separated, e.g. "capture.json"
  std::string sha256;  // 64 lowercase hex digits: the blob's name
  int64_t size_bytes = 0;

  bool operator==(const ManifestEntry&) const = default;
};

// The folder formats a stored capture can have: a capture (what a fit reads) or a raw recording
// (a job ingests it into a capture first).
inline constexpr std::string_view kCaptureFormat = "softid-capture/1";
inline constexpr std::string_view kRecordingFormat = "softid-recording/1";

struct Capture {
  std::string id;          // "cap-<16 hex>"
  std::string request_id;  // the client's idempotency key; empty when none was given
  std::vector<ManifestEntry> manifest;
  Timestamp created_at{};
  std::string owner;  // the station that uploaded it; empty without authentication
  std::string format = std::string(kCaptureFormat);  // kCaptureFormat or kRecordingFormat

  bool operator==(const Capture&) const = default;
};

// InvalidArgument naming the entry and field unless the manifest has at least one entry, every
// path is relative, non-empty, free of "." and ".." segments and unique, every sha256 is 64
// lowercase hex digits and every size is non-negative. Paths are checked because a worker
// materialises the capture by writing each blob to <dir>/<path>.
Status ValidateManifest(const std::vector<ManifestEntry>& manifest);

nlohmann::json ManifestToJson(const std::vector<ManifestEntry>& manifest);
// Parses and validates; field paths in messages look like "manifest[2].sha256".
Result<std::vector<ManifestEntry>> ManifestFromJson(const nlohmann::json& json);

}  // namespace softid::server::store
