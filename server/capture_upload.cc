#include "server/capture_upload.h"

#include <fmt/format.h>

#include <nlohmann/json.hpp>
#include <set>
#include <system_error>

#include "core/capture/capture.h"
#include "core/common/json_fields.h"
#include "core/common/untrusted_json.h"
#include "server/redact_paths.h"
#include "server/store/resource_id.h"

namespace softid::server {
namespace {

namespace fs = std::filesystem;

// ValidateManifest speaks of "manifest[i].size"; the API's field is "files[i].size_bytes".
std::string InApiTerms(std::string message) {
  if (message.rfind("manifest", 0) == 0) message.replace(0, 8, "files");
  const size_t size = message.find("].size ");
  if (size != std::string::npos) message.replace(size, 7, "].size_bytes ");
  return message;
}

std::string CaptureReference(const capture::Capture& capture, const std::string& path) {
  if (capture.mesh_file == path) return "capture.json mesh";
  for (size_t c = 0; c < capture.cameras.size(); ++c) {
    const auto& frames = capture.cameras[c].frames;
    for (size_t k = 0; k < frames.size(); ++k) {
      if (frames[k] == path) return fmt::format("capture.json cameras[{}].frames[{}]", c, k);
    }
  }
  return "capture.json";
}

}  // namespace

ServiceResult<std::unique_ptr<CaptureUpload>> CaptureUpload::Begin(UploadManifest manifest,
                                                                   const fs::path& staging_root,
                                                                   const UploadLimits& limits) {
  // capture.json first: a malformed capture is rejected before any frame is sent.
  Result<nlohmann::json> capture_json =
      json::ParseUntrustedJson(manifest.capture_json, "capture_json", capture::kCaptureJsonLimits);
  if (!capture_json.ok()) return capture_json.status();
  Result<capture::Capture> capture =
      capture::CaptureFromJson(*capture_json, capture::kCaptureFileName);
  if (!capture.ok()) return capture.status();

  if (static_cast<int64_t>(manifest.files.size()) > limits.max_files) {
    return ServiceStatus(ServiceCode::kInvalidArgument,
                         fmt::format("files: {} files: at most {} are accepted",
                                     manifest.files.size(), limits.max_files));
  }
  if (Status valid = store::ValidateManifest(manifest.files); !valid.ok()) {
    return ServiceStatus(ServiceCode::kInvalidArgument, InApiTerms(valid.message()));
  }
  int64_t total = 0;
  std::set<std::string> listed;
  for (size_t i = 0; i < manifest.files.size(); ++i) {
    const store::ManifestEntry& entry = manifest.files[i];
    const std::string field = "files[" + std::to_string(i) + "]";
    if (entry.path == capture::kCaptureFileName) {
      return json::Invalid(field + ".path", entry.path,
                           "capture.json is sent as capture_json, not as a file");
    }
    if (entry.size_bytes > limits.max_file_bytes) {
      return json::Invalid(field + ".size_bytes", entry.size_bytes,
                           fmt::format("exceeds the limit of {} bytes", limits.max_file_bytes));
    }
    total += entry.size_bytes;
    listed.insert(entry.path);
  }
  if (total > limits.max_total_bytes) {
    return json::Invalid("files", fmt::format("{} bytes in total", total),
                         fmt::format("exceeds the limit of {} bytes", limits.max_total_bytes));
  }
  std::vector<std::string> referenced = {capture->mesh_file};
  for (const auto& camera : capture->cameras) {
    referenced.insert(referenced.end(), camera.frames.begin(), camera.frames.end());
  }
  for (const std::string& path : referenced) {
    if (!listed.contains(path)) {
      return ServiceStatus(
          ServiceCode::kInvalidArgument,
          fmt::format("files: \"{}\" ({}) is not listed", path, CaptureReference(*capture, path)));
    }
  }

  std::error_code error;
  const fs::path dir = staging_root / store::NewResourceId("upload-");
  fs::create_directories(dir, error);
  if (error) {
    return ServiceStatus(ServiceCode::kInternal,
                         "cannot create a staging folder: " + error.message());
  }
  std::unique_ptr<CaptureUpload> upload(new CaptureUpload(std::move(manifest), dir, limits));
  // capture.json is staged at once; empty files are complete without a chunk.
  {
    std::ofstream out(dir / capture::kCaptureFileName, std::ios::binary);
    out << upload->manifest_.capture_json;
    if (!out.flush()) {
      return ServiceStatus(ServiceCode::kInternal, "cannot stage capture.json");
    }
  }
  for (const store::ManifestEntry& entry : upload->manifest_.files) {
    FileState& file = upload->files_[entry.path];
    file.declared_size = entry.size_bytes;
    file.declared_sha256 = entry.sha256;
    if (entry.size_bytes == 0) {
      if (ServiceStatus done = upload->CompleteFile(entry.path, file); !done.ok()) return done;
    }
  }
  return upload;
}

CaptureUpload::CaptureUpload(UploadManifest manifest, fs::path staging_dir, UploadLimits limits)
    : manifest_(std::move(manifest)), staging_dir_(std::move(staging_dir)), limits_(limits) {}

CaptureUpload::~CaptureUpload() {
  files_.clear();  // closes open streams before their folder goes
  std::error_code ignored;
  fs::remove_all(staging_dir_, ignored);
}

ServiceStatus CaptureUpload::AddChunk(const std::string& path, int64_t offset_bytes,
                                      std::string_view data) {
  auto it = files_.find(path);
  if (it == files_.end()) {
    return json::Invalid("chunk.path", path, "is not a file of the manifest");
  }
  FileState& file = it->second;
  const int64_t size = static_cast<int64_t>(data.size());
  if (size > limits_.max_chunk_bytes) {
    return json::Invalid("chunk.data", fmt::format("{} bytes of \"{}\"", size, path),
                         fmt::format("a chunk holds at most {} bytes", limits_.max_chunk_bytes));
  }
  if (file.complete) {
    return json::Invalid("chunk.path", path, "the file is already complete");
  }
  if (offset_bytes != file.received) {
    return json::Invalid("chunk.offset_bytes", offset_bytes,
                         fmt::format("\"{}\" continues at byte {}", path, file.received));
  }
  if (file.received + size > file.declared_size) {
    return json::Invalid("files[\"" + path + "\"].size_bytes", file.declared_size,
                         fmt::format("at least {} bytes were sent for it", file.received + size));
  }
  if (!file.out.is_open()) {
    const fs::path target = staging_dir_ / path;
    std::error_code error;
    fs::create_directories(target.parent_path(), error);
    file.out.open(target, std::ios::binary | std::ios::trunc);
    if (error || !file.out) {
      return ServiceStatus(ServiceCode::kInternal, "cannot stage \"" + path + "\"");
    }
  }
  file.out.write(data.data(), size);
  if (!file.out) return ServiceStatus(ServiceCode::kInternal, "cannot write staged " + path);
  file.hasher.Update(data);
  file.received += size;
  if (file.received == file.declared_size) return CompleteFile(path, file);
  return ServiceStatus::Ok();
}

ServiceStatus CaptureUpload::CompleteFile(const std::string& path, FileState& file) {
  if (file.declared_size == 0) {  // ReadCapture will reject it, naming the file
    const fs::path target = staging_dir_ / path;
    std::error_code error;
    fs::create_directories(target.parent_path(), error);
    std::ofstream touch(target, std::ios::binary);
    if (error || !touch) {
      return ServiceStatus(ServiceCode::kInternal, "cannot stage \"" + path + "\"");
    }
  }
  if (file.out.is_open()) {
    file.out.close();
    if (file.out.fail())
      return ServiceStatus(ServiceCode::kInternal, "cannot close staged " + path);
  }
  file.complete = true;
  const std::string actual = file.hasher.FinishHex();
  if (actual != file.declared_sha256) {
    return json::Invalid("files[\"" + path + "\"].sha256", file.declared_sha256,
                         "the received bytes hash to " + actual);
  }
  return ServiceStatus::Ok();
}

int64_t CaptureUpload::declared_bytes() const {
  int64_t total = 0;
  for (const store::ManifestEntry& entry : manifest_.files) total += entry.size_bytes;
  return total;
}

ServiceResult<std::vector<store::ManifestEntry>> CaptureUpload::Finish() {
  for (const auto& [path, file] : files_) {
    if (!file.complete) {
      return json::Invalid("files[\"" + path + "\"].size_bytes", file.declared_size,
                           fmt::format("the upload ended after {} bytes", file.received));
    }
  }
  Result<capture::Capture> capture =
      capture::ReadCapture(staging_dir_, capture::ReadCaptureOptions{.decode_frames = true});
  if (!capture.ok()) {
    // NotFound from ReadCapture would mean a staged file vanished: still the upload's fault only
    // if a listed file is missing, which Begin ruled out, so report it as invalid content.
    return ServiceStatus(ServiceCode::kInvalidArgument,
                         RedactPath(capture.status().message(), staging_dir_));
  }
  std::vector<store::ManifestEntry> stored;
  stored.push_back({std::string(capture::kCaptureFileName),
                    store::Sha256::Hex(manifest_.capture_json),
                    static_cast<int64_t>(manifest_.capture_json.size())});
  stored.insert(stored.end(), manifest_.files.begin(), manifest_.files.end());
  return stored;
}

}  // namespace softid::server
