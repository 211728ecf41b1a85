// WriteRecording: a recording folder from images in memory (synthetic recordings, tests).
#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <nlohmann/json.hpp>
#include <system_error>

#include "core/capture/capture.h"
#include "core/capture/folder_json.h"
#include "core/recording/recording.h"

namespace softid::recording {

using capture::DepthImage;
using ImageLists = std::vector<std::vector<DepthImage>>;

namespace {

// The lower-case extension of `file` (".obj"), or "".
std::string LowerExtension(const std::string& file) {
  std::string extension = std::filesystem::path(file).extension().string();
  std::transform(extension.begin(), extension.end(), extension.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return extension;
}

// `recording` as it will be written: directory set, mesh file defaulted, file names generated.
Result<Recording> Prepare(const std::string& source, const std::filesystem::path& directory,
                          const Recording& recording, const ImageLists& frames,
                          const ImageLists& background) {
  Recording out = recording;
  out.directory = directory;
  if (out.mesh_file.empty()) out.mesh_file = "scan.ply";
  const std::string extension = LowerExtension(out.mesh_file);
  if (extension != ".obj" && extension != ".ply") {
    return Status::InvalidArgument(fmt::format(
        "{}: mesh = \"{}\": must end in \".obj\" or \".ply\" (the mesh is written as OBJ or PLY)",
        source, out.mesh_file));
  }
  if (frames.size() != out.cameras.size() ||
      (!background.empty() && background.size() != out.cameras.size())) {
    return Status::InvalidArgument(fmt::format(
        "{}: {} frame lists and {} background lists for {} cameras: need one frame list per "
        "camera, and one background list per camera or none",
        source, frames.size(), background.size(), out.cameras.size()));
  }
  for (size_t i = 0; i < out.cameras.size(); ++i) {
    RecordingCamera& camera = out.cameras[i];
    if (camera.frames.size() != frames[i].size()) {
      return Status::InvalidArgument(fmt::format(
          "{}: cameras[{}].frames has {} time stamps but frames_per_camera[{}] holds {} images: "
          "one time stamp per image",
          source, i, camera.frames.size(), i, frames[i].size()));
    }
    for (size_t k = 0; k < camera.frames.size(); ++k) {
      camera.frames[k].file = fmt::format("{}/{:06d}.png", camera.camera.name, k);
    }
    camera.background.clear();
    for (size_t b = 0; !background.empty() && b < background[i].size(); ++b) {
      camera.background.push_back(fmt::format("{}/bg_{:03d}.png", camera.camera.name, b));
    }
  }
  return out;
}

// Every image has its camera's size and data.
Status CheckImageSizes(const std::string& source, const Recording& recording,
                       const ImageLists& images, std::string_view what) {
  for (size_t i = 0; i < images.size(); ++i) {
    const capture::PinholeCamera& camera = recording.cameras[i].camera;
    for (size_t k = 0; k < images[i].size(); ++k) {
      const DepthImage& image = images[i][k];
      if (image.width != camera.width || image.height != camera.height ||
          image.depth.size() != static_cast<size_t>(image.width) * image.height) {
        return Status::InvalidArgument(
            fmt::format("{}: {}[{}][{}] is {}x{} with {} values: camera \"{}\" is {}x{}", source,
                        what, i, k, image.width, image.height, image.depth.size(), camera.name,
                        camera.width, camera.height));
      }
    }
  }
  return Status::Ok();
}

Status CreateFolder(const std::filesystem::path& folder) {
  std::error_code error;
  std::filesystem::create_directories(folder, error);
  if (!error) return Status::Ok();
  return Status::IoError(
      fmt::format("{}: cannot create folder: {}", folder.string(), error.message()));
}

// The mesh, in mesh_unit, as OBJ or PLY.
Status WriteMesh(const Recording& recording, const geometry::TriangleMesh& mesh_m) {
  const std::filesystem::path path = recording.directory / recording.mesh_file;
  SOFTID_RETURN_IF_ERROR(CreateFolder(path.parent_path()));
  geometry::TriangleMesh mesh = mesh_m;
  const double scale = MetresPerUnit(recording.mesh_unit);
  for (Eigen::Vector3d& v : mesh.vertices) v /= scale;
  if (LowerExtension(recording.mesh_file) == ".obj") {
    return geometry::WriteTriangleMeshObj(path, mesh);
  }
  return geometry::WriteTriangleMeshPly(path, mesh);
}

Status WriteImages(const Recording& recording, const ImageLists& frames,
                   const ImageLists& background) {
  for (size_t i = 0; i < recording.cameras.size(); ++i) {
    const RecordingCamera& camera = recording.cameras[i];
    SOFTID_RETURN_IF_ERROR(CreateFolder(recording.directory / camera.camera.name));
    for (size_t k = 0; k < camera.frames.size(); ++k) {
      SOFTID_RETURN_IF_ERROR(capture::WriteDepthPng(recording.directory / camera.frames[k].file,
                                                    frames[i][k], camera.depth_scale));
    }
    for (size_t b = 0; b < camera.background.size(); ++b) {
      SOFTID_RETURN_IF_ERROR(capture::WriteDepthPng(recording.directory / camera.background[b],
                                                    background[i][b], camera.depth_scale));
    }
  }
  return Status::Ok();
}

}  // namespace

Status WriteRecording(const std::filesystem::path& directory, const Recording& recording,
                      const geometry::TriangleMesh& mesh, const ImageLists& frames_per_camera,
                      const ImageLists& background_per_camera) {
  const std::string source = fmt::format("WriteRecording({})", directory.string());
  SOFTID_ASSIGN_OR_RETURN(const Recording out, Prepare(source, directory, recording,
                                                       frames_per_camera, background_per_camera));
  // The rules a reader applies (names, counts, time stamps, poses, limits).
  SOFTID_RETURN_IF_ERROR(RecordingFromJson(ToJson(out), source).status());
  SOFTID_RETURN_IF_ERROR(CheckImageSizes(source, out, frames_per_camera, "frames_per_camera"));
  SOFTID_RETURN_IF_ERROR(
      CheckImageSizes(source, out, background_per_camera, "background_per_camera"));
  if (mesh.vertices.empty() || mesh.triangles.empty()) {
    return Status::InvalidArgument(fmt::format("{}: mesh is empty (no triangles)", source));
  }
  const capture::JsonReader reader(source, "recording folder");
  SOFTID_RETURN_IF_ERROR(capture::CheckMeshSize(reader, out.mesh_file, mesh,
                                                "WriteRecording takes the mesh in metres"));
  std::error_code error;
  if (std::filesystem::exists(directory / capture::kCaptureFileName, error)) {
    return Status::InvalidArgument(
        fmt::format("{}: the folder holds a {}: a folder is either a capture or a recording",
                    source, capture::kCaptureFileName));
  }

  SOFTID_RETURN_IF_ERROR(CreateFolder(directory));
  const std::filesystem::path json_path = directory / kRecordingFileName;
  std::filesystem::remove(json_path, error);
  if (error) {
    return Status::IoError(fmt::format("{}: cannot remove the previous {}: {}", json_path.string(),
                                       kRecordingFileName, error.message()));
  }
  SOFTID_RETURN_IF_ERROR(WriteMesh(out, mesh));
  SOFTID_RETURN_IF_ERROR(WriteImages(out, frames_per_camera, background_per_camera));
  return capture::WriteFileAtomically(json_path, ToJson(out).dump(2) + "\n");
}

}  // namespace softid::recording
