// One capture upload in progress: the manifest, then the files' bytes in chunks. Bytes go to a
// private staging folder that is laid out exactly like the capture folder, so the complete upload
// is validated by the same code that reads captures everywhere else (capture::ReadCapture: mesh,
// frame PNGs, sizes, paths). A raw recording is uploaded the same way and validated by
// recording::ReadRecording plus a decode of every frame and background PNG. Only a fully validated
// upload reaches the BlobStore and the JobStore (JobService::FinishUpload); destroying the object
// removes the staging folder, so an upload that failed or was cut off leaves nothing behind.
#pragma once

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "server/service_status.h"
#include "server/store/capture.h"
#include "server/store/sha256.h"

namespace softid::server {

struct UploadLimits {
  // gRPC's default message limit is 4 MiB; 1 MiB chunks leave room for framing (service notes).
  int64_t max_chunk_bytes = int64_t{1} << 20;
  // A 640x480 16-bit frame is 600 KiB; a mesh of a few million triangles stays below this.
  int64_t max_file_bytes = int64_t{256} << 20;
  // About 6000 full-size frames: minutes of video from several cameras.
  int64_t max_total_bytes = int64_t{4} << 30;
  int max_files = 100000;
  // Uploads in progress at once; more are answered RESOURCE_EXHAUSTED (each holds an RPC thread
  // and a staging folder).
  int max_concurrent = 16;
  // An upload stream that sends nothing for this long is cancelled and its staged files removed.
  std::chrono::milliseconds idle_timeout{60000};
};

// What the first message of an upload declares.
struct UploadManifest {
  std::string request_id;
  std::string capture_json;                 // contents of capture.json, or
  std::string recording_json;               // contents of recording.json: exactly one is set
  std::vector<store::ManifestEntry> files;  // every other file; sizes and sha256 as declared
};

// Not thread-safe: one upload stream feeds one object.
class CaptureUpload {
 public:
  // Checks the manifest (capture.json parses and validates with capture::CaptureFromJson, or
  // recording.json with recording::RecordingFromJson; every file it references is listed; paths,
  // sizes and hashes are well formed and within `limits`) and creates the staging folder
  // <staging_root>/<random>. InvalidArgument naming the field.
  static ServiceResult<std::unique_ptr<CaptureUpload>> Begin(
      UploadManifest manifest, const std::filesystem::path& staging_root,
      const UploadLimits& limits);
  ~CaptureUpload();
  CaptureUpload(const CaptureUpload&) = delete;
  CaptureUpload& operator=(const CaptureUpload&) = delete;

  // Appends bytes [offset, offset + data.size()) of a listed file. InvalidArgument for an unknown
  // path, an offset other than the bytes received so far, an oversized chunk, more bytes than
  // declared, or (when the file is complete) a sha256 that differs from the declared one.
  ServiceStatus AddChunk(const std::string& path, int64_t offset_bytes, std::string_view data);

  // Listed files none of whose bytes have arrived (empty files arrive with the manifest): the
  // caller may add them from a copy it holds (AddChunk) before Finish.
  std::vector<store::ManifestEntry> FilesNotStarted() const;

  // Checks every file arrived complete and validates the staged capture as a whole
  // (capture::ReadCapture, or recording::ReadRecording; decoding every frame). Returns the
  // manifest to store: capture.json (recording.json) first, then the listed files.
  ServiceResult<std::vector<store::ManifestEntry>> Finish();

  const std::string& request_id() const { return manifest_.request_id; }
  // store::kCaptureFormat or store::kRecordingFormat, after which JSON the manifest carried.
  std::string_view format() const {
    return is_recording() ? store::kRecordingFormat : store::kCaptureFormat;
  }
  // Bytes of the listed files as declared (checked by Begin against the limits).
  int64_t declared_bytes() const;
  // Keeps `slot` (a count of uploads in progress, say) until the upload is destroyed.
  void HoldSlot(std::shared_ptr<void> slot) { slot_ = std::move(slot); }
  // Where the validated files lie: <dir>/<manifest path>.
  const std::filesystem::path& staging_dir() const { return staging_dir_; }

 private:
  struct FileState {
    int64_t declared_size = 0;
    std::string declared_sha256;
    int64_t received = 0;
    store::Sha256 hasher;
    std::ofstream out;  // open while the file is being received
    bool complete = false;
  };

  CaptureUpload(UploadManifest manifest, std::filesystem::path staging_dir, UploadLimits limits);
  ServiceStatus CompleteFile(const std::string& path, FileState& file);
  bool is_recording() const { return !manifest_.recording_json.empty(); }
  // The name and contents of the folder's description: capture.json or recording.json.
  std::string_view description_name() const;
  const std::string& description() const;

  UploadManifest manifest_;
  std::filesystem::path staging_dir_;
  UploadLimits limits_;
  std::map<std::string, FileState> files_;
  std::shared_ptr<void> slot_;
};

}  // namespace softid::server
