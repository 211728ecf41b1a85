// Recording folders: ReadRecording with its checks of the referenced files, the loaders of the
// mesh and the frames, and DetectFolderFormat.
#include <fmt/format.h>

#include <nlohmann/json.hpp>
#include <system_error>

#include "core/capture/capture.h"
#include "core/capture/folder_json.h"
#include "core/common/untrusted_json.h"
#include "core/recording/recording.h"

namespace softid::recording {

using capture::IndexPath;
using capture::JoinPath;
using capture::JsonReader;
using nlohmann::json;

namespace {

// Ends the message of a mesh of implausible size: which unit was applied, and the likely fix.
std::string MeshSizeNote(MeshUnit unit, const geometry::TriangleMesh& mesh_m) {
  const double longest_m = mesh_m.Bounds().sizes().maxCoeff();
  if (unit == MeshUnit::kMetre && longest_m > capture::kMaxMeshExtent_m) {
    return "after \"mesh_unit\": \"m\"; is the file in millimetres? then set \"mesh_unit\": \"mm\"";
  }
  if (unit == MeshUnit::kMillimetre && longest_m < capture::kMinMeshExtent_m) {
    return "after \"mesh_unit\": \"mm\"; is the file in metres? then set \"mesh_unit\": \"m\"";
  }
  return fmt::format("after \"mesh_unit\": \"{}\"", ToString(unit));
}

// The mesh: inside the folder, loads, not empty, of an object's size after mesh_unit, solid.
Status CheckMesh(const JsonReader& reader, const Recording& recording) {
  const std::string& file = recording.mesh_file;
  SOFTID_RETURN_IF_ERROR(capture::CheckInsideFolder(reader, recording.directory, "mesh", file));
  const Result<geometry::TriangleMesh> mesh = LoadRecordingMesh(recording);
  if (!mesh.ok()) {
    return reader.Error("mesh", json(file),
                        fmt::format("cannot load mesh: {}", mesh.status().message()));
  }
  if (mesh->vertices.empty() || mesh->triangles.empty()) {
    return reader.Error("mesh", json(file), "mesh is empty (no triangles)");
  }
  return capture::CheckMeshSize(reader, file, *mesh, MeshSizeNote(recording.mesh_unit, *mesh));
}

// A frame or background PNG at field `path`: inside the folder, a 16-bit single-channel PNG of
// the camera's size (header only).
Status CheckDepthPng(const JsonReader& reader, const Recording& recording,
                     const RecordingCamera& camera, std::string_view path,
                     const std::string& file) {
  SOFTID_RETURN_IF_ERROR(capture::CheckInsideFolder(reader, recording.directory, path, file));
  const Status status = capture::CheckDepthPngHeader(recording.directory / file,
                                                     camera.camera.width, camera.camera.height);
  if (status.ok()) return Status::Ok();
  return reader.Error(path, json(file),
                      fmt::format("camera \"{}\": {}", camera.camera.name, status.message()));
}

Status CheckCameraFiles(const JsonReader& reader, const Recording& recording, size_t i) {
  const RecordingCamera& camera = recording.cameras[i];
  const std::string path = IndexPath("cameras", i);
  for (size_t k = 0; k < camera.frames.size(); ++k) {
    SOFTID_RETURN_IF_ERROR(CheckDepthPng(reader, recording, camera,
                                         JoinPath(IndexPath(JoinPath(path, "frames"), k), "file"),
                                         camera.frames[k].file));
  }
  for (size_t b = 0; b < camera.background.size(); ++b) {
    SOFTID_RETURN_IF_ERROR(CheckDepthPng(reader, recording, camera,
                                         IndexPath(JoinPath(path, "background"), b),
                                         camera.background[b]));
  }
  return Status::Ok();
}

// InvalidArgument "<function>: <what> = <index>: out of range [0, <size>)" unless index fits.
Status CheckIndex(std::string_view function, std::string_view what, int index, size_t size) {
  if (index >= 0 && static_cast<size_t>(index) < size) return Status::Ok();
  return Status::InvalidArgument(
      fmt::format("{}: {} = {}: out of range [0, {})", function, what, index, size));
}

}  // namespace

Result<Recording> ReadRecording(const std::filesystem::path& directory) {
  std::error_code error;
  if (!std::filesystem::is_directory(directory, error)) {
    return Status::NotFound(fmt::format("{}: recording folder not found", directory.string()));
  }
  const std::filesystem::path json_path = directory / kRecordingFileName;
  const std::string source = json_path.string();
  if (!std::filesystem::is_regular_file(json_path, error)) {
    return Status::NotFound(fmt::format(
        "{}: not found (not a recording folder, or the recording was not completely written)",
        source));
  }
  SOFTID_ASSIGN_OR_RETURN(const std::string text, capture::ReadTextFile(json_path));
  SOFTID_ASSIGN_OR_RETURN(
      const json root, softid::json::ParseUntrustedJson(text, source, capture::kCaptureJsonLimits));
  SOFTID_ASSIGN_OR_RETURN(Recording recording, RecordingFromJson(root, source));
  recording.directory = directory;
  const JsonReader reader(source, "recording folder");
  SOFTID_RETURN_IF_ERROR(CheckMesh(reader, recording));
  for (size_t i = 0; i < recording.cameras.size(); ++i) {
    SOFTID_RETURN_IF_ERROR(CheckCameraFiles(reader, recording, i));
  }
  return recording;
}

Result<geometry::TriangleMesh> LoadRecordingMesh(const Recording& recording) {
  SOFTID_ASSIGN_OR_RETURN(
      geometry::TriangleMesh mesh,
      geometry::ReadTriangleMesh(recording.directory / recording.mesh_file, recording.directory));
  const double scale = MetresPerUnit(recording.mesh_unit);
  if (scale != 1.0) {
    for (Eigen::Vector3d& v : mesh.vertices) v *= scale;
  }
  return mesh;
}

Result<capture::DepthImage> LoadRecordingFrame(const Recording& recording, int camera, int frame) {
  SOFTID_RETURN_IF_ERROR(
      CheckIndex("LoadRecordingFrame", "camera", camera, recording.cameras.size()));
  const RecordingCamera& recorded = recording.cameras[camera];
  SOFTID_RETURN_IF_ERROR(CheckIndex("LoadRecordingFrame", "frame", frame, recorded.frames.size()));
  return capture::ReadDepthPng(recording.directory / recorded.frames[frame].file,
                               recorded.depth_scale, recorded.camera.width, recorded.camera.height);
}

Result<capture::DepthImage> LoadBackgroundFrame(const Recording& recording, int camera,
                                                int background) {
  SOFTID_RETURN_IF_ERROR(
      CheckIndex("LoadBackgroundFrame", "camera", camera, recording.cameras.size()));
  const RecordingCamera& recorded = recording.cameras[camera];
  SOFTID_RETURN_IF_ERROR(
      CheckIndex("LoadBackgroundFrame", "background", background, recorded.background.size()));
  return capture::ReadDepthPng(recording.directory / recorded.background[background],
                               recorded.depth_scale, recorded.camera.width, recorded.camera.height);
}

Result<FolderFormat> DetectFolderFormat(const std::filesystem::path& directory) {
  std::error_code error;
  if (!std::filesystem::is_directory(directory, error)) {
    return Status::NotFound(fmt::format("{}: folder not found (looked for {} or {})",
                                        directory.string(), capture::kCaptureFileName,
                                        kRecordingFileName));
  }
  const bool is_capture =
      std::filesystem::is_regular_file(directory / capture::kCaptureFileName, error);
  const bool is_recording = std::filesystem::is_regular_file(directory / kRecordingFileName, error);
  if (is_capture && is_recording) {
    return Status::InvalidArgument(
        fmt::format("{}: holds both {} and {}: ambiguous (a folder is either a capture or a "
                    "recording; remove one of them)",
                    directory.string(), capture::kCaptureFileName, kRecordingFileName));
  }
  if (is_capture) return FolderFormat::kCapture;
  if (is_recording) return FolderFormat::kRecording;
  return Status::NotFound(
      fmt::format("{}: neither {} nor {} found (not a capture or recording folder, or not "
                  "completely written)",
                  directory.string(), capture::kCaptureFileName, kRecordingFileName));
}

}  // namespace softid::recording
