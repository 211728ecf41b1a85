#include "core/capture/capture_writer.h"

#include <fmt/format.h>

#include <cctype>
#include <system_error>
#include <utility>

#include "core/capture/folder_json.h"

namespace softid::capture {
namespace {

// Where a writer stages its files inside the capture folder until it finishes.
constexpr const char* kStagingFolder = ".capture-writing";

bool EndsWithObj(const std::string& file) {
  if (file.size() < 4) return false;
  std::string extension = file.substr(file.size() - 4);
  for (char& c : extension) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return extension == ".obj";
}

Status MakeFolder(const std::filesystem::path& folder) {
  std::error_code error;
  std::filesystem::create_directories(folder, error);
  if (error) {
    return Status::IoError(
        fmt::format("{}: cannot create folder: {}", folder.string(), error.message()));
  }
  return Status::Ok();
}

// `capture` as it is written: its directory, the mesh file (object.obj unless named) and the
// frames' file names <camera>/%06d.png, frame_counts[i] for camera i. InvalidArgument (naming
// `source`) for a mesh file that is not OBJ, a wrong number of counts or a camera name that cannot
// be a folder name.
Result<Capture> NameCaptureFiles(const std::string& source, const std::filesystem::path& directory,
                                 const Capture& capture, const std::vector<size_t>& frame_counts) {
  Capture out = capture;
  out.directory = directory;
  if (out.mesh_file.empty()) out.mesh_file = "object.obj";
  if (!EndsWithObj(out.mesh_file)) {
    return Status::InvalidArgument(
        fmt::format("{}: mesh = \"{}\": must end in \".obj\" (the mesh is written as OBJ)", source,
                    out.mesh_file));
  }
  if (frame_counts.size() != out.cameras.size()) {
    return Status::InvalidArgument(
        fmt::format("{}: {} image lists for {} cameras: need one per camera", source,
                    frame_counts.size(), out.cameras.size()));
  }
  for (size_t i = 0; i < out.cameras.size(); ++i) {
    CameraRecording& recording = out.cameras[i];
    const std::string& name = recording.camera.name;
    if (!IsSafeFolderName(name)) {
      return Status::InvalidArgument(fmt::format(
          "{}: cameras[{}].name = \"{}\": must be usable as a folder name (not empty, no '/', "
          "'\\' or control characters, not \".\" or \"..\")",
          source, i, name));
    }
    recording.frames.clear();
    for (size_t k = 0; k < frame_counts[i]; ++k)
      recording.frames.push_back(fmt::format("{}/{:06d}.png", name, k));
  }
  return out;
}

// InvalidArgument unless `image` has the camera's size.
Status CheckImageSize(const std::string& source, const PinholeCamera& camera, int i, int k,
                      const DepthImage& image) {
  if (image.width != camera.width || image.height != camera.height ||
      image.depth.size() != static_cast<size_t>(image.width) * image.height) {
    return Status::InvalidArgument(
        fmt::format("{}: frames_per_camera[{}][{}] is {}x{} with {} values: camera \"{}\" is {}x{}",
                    source, i, k, image.width, image.height, image.depth.size(), camera.name,
                    camera.width, camera.height));
  }
  return Status::Ok();
}

// InvalidArgument unless `capture`'s cameras are `named`'s (names, sizes, depth scales).
Status CheckSameCameras(const Capture& named, const Capture& capture) {
  if (capture.cameras.size() != named.cameras.size()) {
    return Status::InvalidArgument(fmt::format("CaptureWriter: {} cameras, created with {}",
                                               capture.cameras.size(), named.cameras.size()));
  }
  for (size_t i = 0; i < named.cameras.size(); ++i) {
    const CameraRecording &a = named.cameras[i], &b = capture.cameras[i];
    if (a.camera.name != b.camera.name || a.camera.width != b.camera.width ||
        a.camera.height != b.camera.height || a.depth_scale != b.depth_scale) {
      return Status::InvalidArgument(fmt::format(
          "CaptureWriter: cameras[{}] is \"{}\" {}x{} at {} m per unit, created as \"{}\" {}x{} "
          "at {}",
          i, b.camera.name, b.camera.width, b.camera.height, b.depth_scale, a.camera.name,
          a.camera.width, a.camera.height, a.depth_scale));
    }
  }
  return Status::Ok();
}

Status MoveInto(const std::filesystem::path& from, const std::filesystem::path& to) {
  std::error_code error;
  std::filesystem::rename(from, to, error);
  if (error) {
    return Status::IoError(
        fmt::format("{}: cannot move into place: {}", to.string(), error.message()));
  }
  return Status::Ok();
}

}  // namespace

Result<CaptureWriter> CaptureWriter::Create(const std::filesystem::path& directory,
                                            const Capture& capture, int num_frames) {
  const std::string source = fmt::format("CaptureWriter({})", directory.string());
  if (num_frames < 1) {
    return Status::InvalidArgument(
        fmt::format("{}: num_frames = {}: must be >= 1", source, num_frames));
  }
  CaptureWriter writer;
  SOFTID_ASSIGN_OR_RETURN(
      writer.named_, NameCaptureFiles(source, directory, capture,
                                      std::vector<size_t>(capture.cameras.size(), num_frames)));
  writer.directory_ = directory;
  writer.staging_ = directory / kStagingFolder;
  writer.num_frames_ = num_frames;
  std::error_code error;
  writer.made_directory_ = !std::filesystem::exists(directory, error);
  std::filesystem::remove_all(writer.staging_, error);  // a writer that died unfinished
  for (const CameraRecording& recording : writer.named_.cameras)
    SOFTID_RETURN_IF_ERROR(MakeFolder(writer.staging_ / recording.camera.name));
  writer.written_.assign(writer.named_.cameras.size(), std::vector<uint8_t>(num_frames, 0));
  return writer;
}

CaptureWriter::CaptureWriter(CaptureWriter&& other) noexcept
    : directory_(std::move(other.directory_)),
      staging_(std::move(other.staging_)),
      named_(std::move(other.named_)),
      num_frames_(other.num_frames_),
      written_(std::move(other.written_)),
      made_directory_(other.made_directory_),
      finished_(other.finished_) {
  other.staging_.clear();
}

CaptureWriter::~CaptureWriter() {
  if (staging_.empty()) return;  // moved from
  std::error_code ignored;       // nothing to report from a destructor
  std::filesystem::remove_all(staging_, ignored);
  if (!finished_ && made_directory_ && std::filesystem::is_empty(directory_, ignored))
    std::filesystem::remove(directory_, ignored);
}

Status CaptureWriter::WriteFrame(int camera, int frame, const DepthImage& image) {
  const std::string source = fmt::format("CaptureWriter({})", directory_.string());
  if (camera < 0 || camera >= static_cast<int>(named_.cameras.size()) || frame < 0 ||
      frame >= num_frames_) {
    return Status::InvalidArgument(
        fmt::format("{}: camera {} frame {}: out of range ({} cameras, {} frames)", source, camera,
                    frame, named_.cameras.size(), num_frames_));
  }
  const CameraRecording& recording = named_.cameras[camera];
  SOFTID_RETURN_IF_ERROR(CheckImageSize(source, recording.camera, camera, frame, image));
  SOFTID_RETURN_IF_ERROR(
      WriteDepthPng(staging_ / recording.frames[frame], image, recording.depth_scale));
  written_[camera][frame] = 1;
  return Status::Ok();
}

Status CaptureWriter::Finish(const Capture& capture, const geometry::TriangleMesh& mesh) {
  const std::string source = fmt::format("CaptureWriter({})", directory_.string());
  for (size_t i = 0; i < written_.size(); ++i) {
    for (int k = 0; k < num_frames_; ++k) {
      if (!written_[i][k]) {
        return Status::FailedPrecondition(fmt::format("{}: camera \"{}\" frame {} was not written",
                                                      source, named_.cameras[i].camera.name, k));
      }
    }
  }
  SOFTID_RETURN_IF_ERROR(CheckSameCameras(named_, capture));
  Capture out = capture;
  out.directory = directory_;
  out.mesh_file = named_.mesh_file;
  for (size_t i = 0; i < out.cameras.size(); ++i) out.cameras[i].frames = named_.cameras[i].frames;
  SOFTID_RETURN_IF_ERROR(CaptureFromJson(ToJson(out), source).status());
  if (mesh.vertices.empty() || mesh.triangles.empty())
    return Status::InvalidArgument(fmt::format("{}: mesh is empty (no triangles)", source));
  // The previous capture stops looking complete before any of its files is replaced.
  const std::filesystem::path json_path = directory_ / kCaptureFileName;
  std::error_code error;
  std::filesystem::remove(json_path, error);
  if (error) {
    return Status::IoError(fmt::format("{}: cannot remove the previous capture.json: {}",
                                       json_path.string(), error.message()));
  }
  const std::filesystem::path mesh_path = directory_ / out.mesh_file;
  SOFTID_RETURN_IF_ERROR(MakeFolder(mesh_path.parent_path()));
  SOFTID_RETURN_IF_ERROR(geometry::WriteTriangleMeshObj(mesh_path, mesh));
  for (const CameraRecording& recording : out.cameras) {
    SOFTID_RETURN_IF_ERROR(MakeFolder(directory_ / recording.camera.name));
    for (const std::string& frame : recording.frames)
      SOFTID_RETURN_IF_ERROR(MoveInto(staging_ / frame, directory_ / frame));
  }
  SOFTID_RETURN_IF_ERROR(WriteFileAtomically(json_path, ToJson(out).dump(2) + "\n"));
  finished_ = true;
  return Status::Ok();
}

Status WriteCapture(const std::filesystem::path& directory, const Capture& capture,
                    const geometry::TriangleMesh& mesh,
                    const std::vector<std::vector<DepthImage>>& frames_per_camera) {
  const std::string source = fmt::format("WriteCapture({})", directory.string());
  std::vector<size_t> counts;
  for (const std::vector<DepthImage>& images : frames_per_camera) counts.push_back(images.size());
  SOFTID_ASSIGN_OR_RETURN(const Capture named,
                          NameCaptureFiles(source, directory, capture, counts));
  // The same rules a reader applies (also catches empty or unequal frame lists).
  SOFTID_RETURN_IF_ERROR(CaptureFromJson(ToJson(named), source).status());
  for (size_t i = 0; i < named.cameras.size(); ++i) {
    for (size_t k = 0; k < frames_per_camera[i].size(); ++k) {
      SOFTID_RETURN_IF_ERROR(CheckImageSize(source, named.cameras[i].camera, static_cast<int>(i),
                                            static_cast<int>(k), frames_per_camera[i][k]));
    }
  }
  if (mesh.vertices.empty() || mesh.triangles.empty())
    return Status::InvalidArgument(fmt::format("{}: mesh is empty (no triangles)", source));
  SOFTID_ASSIGN_OR_RETURN(
      CaptureWriter writer,
      CaptureWriter::Create(directory, capture, static_cast<int>(counts.front())));
  for (size_t i = 0; i < frames_per_camera.size(); ++i) {
    for (size_t k = 0; k < frames_per_camera[i].size(); ++k) {
      SOFTID_RETURN_IF_ERROR(
          writer.WriteFrame(static_cast<int>(i), static_cast<int>(k), frames_per_camera[i][k]));
    }
  }
  return writer.Finish(capture, mesh);
}

}  // namespace softid::capture
