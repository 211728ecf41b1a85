#include "server/capture_upload.h"

#include <fmt/format.h>

#include <nlohmann/json.hpp>
#include <set>
#include <system_error>

#include "core/capture/capture.h"
#include "core/common/json_fields.h"
#include "core/common/untrusted_json.h"
#include "core/recording/recording.h"
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

// The files a folder description refers to, each with the field that does, e.g.
// {"frames/cam0_0000.png", "capture.json cameras[0].frames[0]"}.
using References = std::vector<std::pair<std::string, std::string>>;

ServiceResult<References> CaptureReferences(const std::string& text) {
  Result<nlohmann::json> json =
      json::ParseUntrustedJson(text, "capture_json", capture::kCaptureJsonLimits);
  if (!json.ok()) return json.status();
  Result<capture::Capture> capture = capture::CaptureFromJson(*json, capture::kCaptureFileName);
  if (!capture.ok()) return capture.status();
  References out = {{capture->mesh_file, "capture.json mesh"}};
  for (size_t c = 0; c < capture->cameras.size(); ++c) {
    const auto& frames = capture->cameras[c].frames;
    for (size_t k = 0; k < frames.size(); ++k) {
      out.emplace_back(frames[k], fmt::format("capture.json cameras[{}].frames[{}]", c, k));
    }
  }
  return out;
}

ServiceResult<References> RecordingReferences(const std::string& text) {
  // recording.json lists one entry per frame like capture.json: the same limits fit.
  Result<nlohmann::json> json =
      json::ParseUntrustedJson(text, "recording_json", capture::kCaptureJsonLimits);
  if (!json.ok()) return json.status();
  Result<recording::Recording> recording =
      recording::RecordingFromJson(*json, recording::kRecordingFileName);
  if (!recording.ok()) return recording.status();
  References out = {{recording->mesh_file, "recording.json mesh"}};
  for (size_t c = 0; c < recording->cameras.size(); ++c) {
    const recording::RecordingCamera& camera = recording->cameras[c];
    for (size_t k = 0; k < camera.frames.size(); ++k) {
      out.emplace_back(camera.frames[k].file,
                       fmt::format("recording.json cameras[{}].frames[{}].file", c, k));
    }
    for (size_t b = 0; b < camera.background.size(); ++b) {
      out.emplace_back(camera.background[b],
                       fmt::format("recording.json cameras[{}].background[{}]", c, b));
    }
  }
  return out;
}

// ReadRecording checks the PNG headers only; decoding every frame and background, as a capture
// upload does, keeps a corrupt PNG from failing a job later.
Status ValidateStagedRecording(const fs::path& dir) {
  SOFTID_ASSIGN_OR_RETURN(const recording::Recording recording, recording::ReadRecording(dir));
  for (int c = 0; c < recording.NumCameras(); ++c) {
    const recording::RecordingCamera& camera = recording.cameras[static_cast<size_t>(c)];
    for (int k = 0; k < static_cast<int>(camera.frames.size()); ++k) {
      SOFTID_RETURN_IF_ERROR(recording::LoadRecordingFrame(recording, c, k).status());
    }
    for (int b = 0; b < static_cast<int>(camera.background.size()); ++b) {
      SOFTID_RETURN_IF_ERROR(recording::LoadBackgroundFrame(recording, c, b).status());
    }
  }
  return Status::Ok();
}

// Exactly one description: capture_json for a capture, recording_json for a raw recording.
ServiceStatus CheckOneDescription(const UploadManifest& manifest) {
  if (!manifest.capture_json.empty() && !manifest.recording_json.empty()) {
    return ServiceStatus(ServiceCode::kInvalidArgument,
                         "capture_json, recording_json: both are set: send exactly one "
                         "(capture_json for a capture, recording_json for a raw recording)");
  }
  if (manifest.capture_json.empty() && manifest.recording_json.empty()) {
    return ServiceStatus(ServiceCode::kInvalidArgument,
                         "capture_json, recording_json: neither is set: send exactly one "
                         "(capture_json for a capture, recording_json for a raw recording)");
  }
  return ServiceStatus::Ok();
}

// The manifest's files within the limits, and every file the description refers to among them.
ServiceStatus CheckManifestFiles(const UploadManifest& manifest, const References& references,
                                 const UploadLimits& limits) {
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
    // Both names: a folder holding both descriptions would be ambiguous.
    if (entry.path == capture::kCaptureFileName || entry.path == recording::kRecordingFileName) {
      return json::Invalid(field + ".path", entry.path,
                           "capture.json and recording.json are sent as capture_json and "
                           "recording_json, not as files");
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
  for (const auto& [path, where] : references) {
    if (!listed.contains(path)) {
      return ServiceStatus(ServiceCode::kInvalidArgument,
                           fmt::format("files: \"{}\" ({}) is not listed", path, where));
    }
  }
  return ServiceStatus::Ok();
}

}  // namespace

ServiceResult<std::unique_ptr<CaptureUpload>> CaptureUpload::Begin(UploadManifest manifest,
                                                                   const fs::path& staging_root,
                                                                   const UploadLimits& limits) {
  if (ServiceStatus one = CheckOneDescription(manifest); !one.ok()) return one;
  // The description first: a malformed one is rejected before any frame is sent.
  ServiceResult<References> references = manifest.recording_json.empty()
                                             ? CaptureReferences(manifest.capture_json)
                                             : RecordingReferences(manifest.recording_json);
  if (!references.ok()) return references.status();
  if (ServiceStatus files = CheckManifestFiles(manifest, *references, limits); !files.ok()) {
    return files;
  }

  std::error_code error;
  const fs::path dir = staging_root / store::NewResourceId("upload-");
  fs::create_directories(dir, error);
  if (error) {
    return ServiceStatus(ServiceCode::kInternal,
                         "cannot create a staging folder: " + error.message());
  }
  std::unique_ptr<CaptureUpload> upload(new CaptureUpload(std::move(manifest), dir, limits));
  // The description is staged at once; empty files are complete without a chunk.
  {
    const std::string name(upload->description_name());
    std::ofstream out(dir / name, std::ios::binary);
    out << upload->description();
    if (!out.flush()) return ServiceStatus(ServiceCode::kInternal, "cannot stage " + name);
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

std::string_view CaptureUpload::description_name() const {
  return is_recording() ? recording::kRecordingFileName : capture::kCaptureFileName;
}

const std::string& CaptureUpload::description() const {
  return is_recording() ? manifest_.recording_json : manifest_.capture_json;
}

CaptureUpload::~CaptureUpload() {
  files_.clear();  // closes open streams before their folder goes
  std::error_code ignored;
  fs::remove_all(staging_dir_, ignored);
}

std::vector<store::ManifestEntry> CaptureUpload::FilesNotStarted() const {
  std::vector<store::ManifestEntry> out;
  for (const store::ManifestEntry& entry : manifest_.files) {
    const auto it = files_.find(entry.path);
    if (it != files_.end() && it->second.received == 0 && !it->second.complete)
      out.push_back(entry);
  }
  return out;
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
  const Status valid =
      is_recording()
          ? ValidateStagedRecording(staging_dir_)
          : capture::ReadCapture(staging_dir_, capture::ReadCaptureOptions{.decode_frames = true})
                .status();
  if (!valid.ok()) {
    // NotFound from the readers would mean a staged file vanished: still the upload's fault only
    // if a listed file is missing, which Begin ruled out, so report it as invalid content.
    return ServiceStatus(ServiceCode::kInvalidArgument, RedactPath(valid.message(), staging_dir_));
  }
  std::vector<store::ManifestEntry> stored;
  stored.push_back({std::string(description_name()), store::Sha256::Hex(description()),
                    static_cast<int64_t>(description().size())});
  stored.insert(stored.end(), manifest_.files.begin(), manifest_.files.end());
  return stored;
}

}  // namespace softid::server
