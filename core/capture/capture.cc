#include "core/capture/capture.h"

#include <fmt/format.h>

#include <nlohmann/json.hpp>
#include <set>
#include <system_error>

#include "core/capture/folder_json.h"

namespace softid::capture {

using nlohmann::json;

double Capture::FrameTime(int frame) const {
  return frame_times.empty() ? frame / fps : frame_times[frame];
}

int Capture::NumFrames() const {
  return cameras.empty() ? 0 : static_cast<int>(cameras.front().frames.size());
}

namespace {

Result<CameraRecording> ParseCamera(const JsonReader& reader, const json& value,
                                    std::string_view path) {
  CameraRecording recording;
  SOFTID_ASSIGN_OR_RETURN(recording.camera, ParseIntrinsics(reader, value, path));
  SOFTID_ASSIGN_OR_RETURN(recording.depth_scale, ParseDepthScale(reader, value, path));

  const std::string pose_path = JoinPath(path, "world_from_camera");
  SOFTID_ASSIGN_OR_RETURN(const json* pose, reader.Require(value, path, "world_from_camera"));
  SOFTID_ASSIGN_OR_RETURN(recording.camera.X_WC, ParsePose(reader, *pose, pose_path));

  const std::string frames_path = JoinPath(path, "frames");
  SOFTID_ASSIGN_OR_RETURN(const json* frames, reader.Require(value, path, "frames"));
  SOFTID_RETURN_IF_ERROR(reader.CheckArray(frames_path, *frames));
  if (frames->empty()) return reader.Error(frames_path, *frames, "must list at least one frame");
  if (frames->size() > static_cast<size_t>(kMaxFramesPerCamera)) {
    return reader.Error(frames_path,
                        fmt::format("{} frames: at most {} frames per camera are accepted",
                                    frames->size(), kMaxFramesPerCamera));
  }
  for (size_t k = 0; k < frames->size(); ++k) {
    SOFTID_ASSIGN_OR_RETURN(std::string frame,
                            reader.RelativePath(IndexPath(frames_path, k), (*frames)[k]));
    recording.frames.push_back(std::move(frame));
  }
  return recording;
}

// "frame_times": one time per frame [s], finite, >= 0, strictly increasing and within
// kMaxFramePeriods.
Result<std::vector<double>> ParseFrameTimes(const JsonReader& reader, const json& value,
                                            int num_frames, double fps) {
  SOFTID_RETURN_IF_ERROR(reader.CheckArray("frame_times", value));
  if (value.size() != static_cast<size_t>(num_frames)) {
    return reader.Error("frame_times", fmt::format("has {} times but the cameras have {} frames: "
                                                   "one time per frame",
                                                   value.size(), num_frames));
  }
  std::vector<double> times;
  times.reserve(value.size());
  for (size_t k = 0; k < value.size(); ++k) {
    const std::string path = IndexPath("frame_times", k);
    SOFTID_ASSIGN_OR_RETURN(const double t, reader.Number(path, value[k]));
    if (t < 0.0) return reader.Error(path, value[k], "must be >= 0 (the rest pose is at t = 0)");
    if (t * fps > kMaxFramePeriods) {
      return reader.Error(path, value[k],
                          fmt::format("more than {} frame periods (1 / fps = {:g} s) after t = 0: "
                                      "the simulation would be too long",
                                      kMaxFramePeriods, 1.0 / fps));
    }
    if (k > 0 && !(t > times.back())) {
      return reader.Error(path, value[k],
                          fmt::format("must be greater than frame_times[{}] = {} (strictly "
                                      "increasing)",
                                      k - 1, times.back()));
    }
    times.push_back(t);
  }
  return times;
}

// "format" first, so that another version's differing fields are reported as a version mismatch.
Status CheckFormat(const JsonReader& reader, const json& root) {
  SOFTID_ASSIGN_OR_RETURN(const json* format, reader.Require(root, "", "format"));
  SOFTID_ASSIGN_OR_RETURN(const std::string format_string, reader.String("format", *format));
  if (format_string != kCaptureFormat) {
    constexpr std::string_view kFamily = "softid-capture/";
    if (format_string.starts_with(kFamily)) {
      return reader.Error(
          "format", *format,
          fmt::format("unsupported version (this reader supports \"{}\")", kCaptureFormat));
    }
    return reader.Error("format", *format,
                        fmt::format("not a softid capture (expected \"{}\")", kCaptureFormat));
  }
  return Status::Ok();
}

// "fixed_region": {"min": [3], "max": [3]} with min <= max in every coordinate.
Result<Eigen::AlignedBox3d> ParseFixedRegion(const JsonReader& reader, const json& value) {
  SOFTID_RETURN_IF_ERROR(reader.CheckObject("fixed_region", value));
  SOFTID_ASSIGN_OR_RETURN(const json* min_json, reader.Require(value, "fixed_region", "min"));
  SOFTID_ASSIGN_OR_RETURN(const json* max_json, reader.Require(value, "fixed_region", "max"));
  SOFTID_ASSIGN_OR_RETURN(const Eigen::Vector3d min, reader.Vector3("fixed_region.min", *min_json));
  SOFTID_ASSIGN_OR_RETURN(const Eigen::Vector3d max, reader.Vector3("fixed_region.max", *max_json));
  for (int i = 0; i < 3; ++i) {
    if (min[i] > max[i]) {
      return reader.Error(fmt::format("fixed_region.min[{}]", i), (*min_json)[i],
                          fmt::format("greater than fixed_region.max[{}] = {}: min must be <= "
                                      "max in every coordinate",
                                      i, Shown((*max_json)[i])));
    }
  }
  return Eigen::AlignedBox3d(min, max);
}

// "floor": {"normal": [3] (not zero; normalised), "offset": d}.
Result<Capture::Floor> ParseFloor(const JsonReader& reader, const json& value) {
  SOFTID_RETURN_IF_ERROR(reader.CheckObject("floor", value));
  SOFTID_ASSIGN_OR_RETURN(const json* normal, reader.Require(value, "floor", "normal"));
  SOFTID_ASSIGN_OR_RETURN(const json* offset, reader.Require(value, "floor", "offset"));
  Capture::Floor floor;
  SOFTID_ASSIGN_OR_RETURN(floor.normal, reader.Vector3("floor.normal", *normal));
  if (!(floor.normal.norm() > 1e-9)) {
    return reader.Error("floor.normal", *normal, "must not be zero");
  }
  floor.normal.normalize();
  SOFTID_ASSIGN_OR_RETURN(floor.offset_m, reader.Number("floor.offset", *offset));
  return floor;
}

// "cameras": 1 to kMaxCameras cameras with distinct names and equally many frames.
Status ParseCameras(const JsonReader& reader, const json& root,
                    std::vector<CameraRecording>* recordings) {
  SOFTID_ASSIGN_OR_RETURN(const json* cameras, reader.Require(root, "", "cameras"));
  SOFTID_RETURN_IF_ERROR(reader.CheckArray("cameras", *cameras));
  if (cameras->empty()) return reader.Error("cameras", *cameras, "must list at least one camera");
  if (cameras->size() > static_cast<size_t>(kMaxCameras)) {
    return reader.Error("cameras", fmt::format("{} cameras: at most {} are accepted",
                                               cameras->size(), kMaxCameras));
  }
  std::set<std::string> names;
  for (size_t i = 0; i < cameras->size(); ++i) {
    const std::string path = IndexPath("cameras", i);
    SOFTID_ASSIGN_OR_RETURN(CameraRecording recording, ParseCamera(reader, (*cameras)[i], path));
    if (!names.insert(recording.camera.name).second) {
      return reader.Error(JoinPath(path, "name"), json(recording.camera.name),
                          "duplicate camera name");
    }
    if (i > 0 && recording.frames.size() != recordings->front().frames.size()) {
      return reader.Error(JoinPath(path, "frames"),
                          fmt::format("has {} frames but cameras[0].frames has {}: all cameras "
                                      "must have the same number of frames",
                                      recording.frames.size(), recordings->front().frames.size()));
    }
    recordings->push_back(std::move(recording));
  }
  return Status::Ok();
}

}  // namespace

json ToJson(const Capture& capture) {
  json out = json::object();
  out["format"] = std::string(kCaptureFormat);
  out["mesh"] = capture.mesh_file;
  out["fps"] = capture.fps;
  if (capture.mass_kg) out["mass_kg"] = *capture.mass_kg;
  if (capture.fixed_region) {
    const Eigen::Vector3d& min = capture.fixed_region->min();
    const Eigen::Vector3d& max = capture.fixed_region->max();
    out["fixed_region"] = {{"min", {min.x(), min.y(), min.z()}},
                           {"max", {max.x(), max.y(), max.z()}}};
  }
  json cameras = json::array();
  for (const CameraRecording& recording : capture.cameras) {
    const PinholeCamera& camera = recording.camera;
    json pose = json::array();
    for (int i = 0; i < 16; ++i) pose.push_back(camera.X_WC.matrix()(i / 4, i % 4));
    cameras.push_back({{"name", camera.name},
                       {"width", camera.width},
                       {"height", camera.height},
                       {"fx", camera.fx},
                       {"fy", camera.fy},
                       {"cx", camera.cx},
                       {"cy", camera.cy},
                       {"depth_scale", recording.depth_scale},
                       {"world_from_camera", std::move(pose)},
                       {"frames", recording.frames}});
  }
  out["cameras"] = std::move(cameras);
  if (!capture.frame_times.empty()) out["frame_times"] = capture.frame_times;
  if (capture.floor) {
    const Eigen::Vector3d& n = capture.floor->normal;
    out["floor"] = {{"normal", {n.x(), n.y(), n.z()}}, {"offset", capture.floor->offset_m}};
  }
  return out;
}

Result<Capture> CaptureFromJson(const json& root, std::string_view source) {
  const JsonReader reader(source);
  SOFTID_RETURN_IF_ERROR(reader.CheckObject("", root));
  Capture capture;
  SOFTID_RETURN_IF_ERROR(CheckFormat(reader, root));

  SOFTID_ASSIGN_OR_RETURN(const json* mesh, reader.Require(root, "", "mesh"));
  SOFTID_ASSIGN_OR_RETURN(capture.mesh_file, reader.RelativePath("mesh", *mesh));

  SOFTID_ASSIGN_OR_RETURN(const json* fps, reader.Require(root, "", "fps"));
  SOFTID_ASSIGN_OR_RETURN(capture.fps, reader.PositiveNumber("fps", *fps));

  if (const auto it = root.find("mass_kg"); it != root.end()) {
    SOFTID_ASSIGN_OR_RETURN(capture.mass_kg, reader.PositiveNumber("mass_kg", *it));
  }
  if (const auto it = root.find("fixed_region"); it != root.end()) {
    SOFTID_ASSIGN_OR_RETURN(capture.fixed_region, ParseFixedRegion(reader, *it));
  }
  if (const auto it = root.find("floor"); it != root.end()) {
    SOFTID_ASSIGN_OR_RETURN(capture.floor, ParseFloor(reader, *it));
  }
  SOFTID_RETURN_IF_ERROR(ParseCameras(reader, root, &capture.cameras));
  if (const auto it = root.find("frame_times"); it != root.end()) {
    SOFTID_ASSIGN_OR_RETURN(capture.frame_times,
                            ParseFrameTimes(reader, *it, capture.NumFrames(), capture.fps));
  }
  return capture;
}

Result<Capture> ReadCapture(const std::filesystem::path& directory,
                            const ReadCaptureOptions& options) {
  SOFTID_RETURN_IF_ERROR(options.Validate());
  std::error_code error;
  if (!std::filesystem::is_directory(directory, error)) {
    return Status::NotFound(fmt::format("{}: capture folder not found", directory.string()));
  }
  const std::filesystem::path json_path = directory / kCaptureFileName;
  const std::string source = json_path.string();
  if (!std::filesystem::is_regular_file(json_path, error)) {
    return Status::NotFound(fmt::format(
        "{}: not found (not a capture folder, or the capture was not completely written)", source));
  }
  SOFTID_ASSIGN_OR_RETURN(const std::string text, ReadTextFile(json_path));
  SOFTID_ASSIGN_OR_RETURN(const json root,
                          softid::json::ParseUntrustedJson(text, source, kCaptureJsonLimits));
  SOFTID_ASSIGN_OR_RETURN(Capture capture, CaptureFromJson(root, source));
  capture.directory = directory;
  const JsonReader reader(source);

  // The mesh: inside the folder, loads, not empty.
  SOFTID_RETURN_IF_ERROR(CheckInsideFolder(reader, directory, "mesh", capture.mesh_file));
  {
    const Result<geometry::TriangleMesh> mesh = LoadCaptureMesh(capture);
    if (!mesh.ok()) {
      return reader.Error("mesh", json(capture.mesh_file),
                          fmt::format("cannot load mesh: {}", mesh.status().message()));
    }
    if (mesh->vertices.empty() || mesh->triangles.empty()) {
      return reader.Error("mesh", json(capture.mesh_file), "mesh is empty (no triangles)");
    }
    SOFTID_RETURN_IF_ERROR(
        CheckMeshSize(reader, capture.mesh_file, *mesh, "capture meshes are in metres"));
  }

  // Every frame: inside the folder, a 16-bit single-channel PNG of the camera's size.
  for (size_t i = 0; i < capture.cameras.size(); ++i) {
    const CameraRecording& recording = capture.cameras[i];
    const PinholeCamera& camera = recording.camera;
    for (size_t k = 0; k < recording.frames.size(); ++k) {
      const std::string path = fmt::format("cameras[{}].frames[{}]", i, k);
      const std::string& file = recording.frames[k];
      SOFTID_RETURN_IF_ERROR(CheckInsideFolder(reader, directory, path, file));
      const std::filesystem::path frame_path = directory / file;
      Status status;
      if (options.decode_frames) {
        status =
            ReadDepthPng(frame_path, recording.depth_scale, camera.width, camera.height).status();
      } else {
        status = CheckDepthPngHeader(frame_path, camera.width, camera.height);
      }
      if (!status.ok()) return reader.Error(path, json(file), status.message());
    }
  }
  return capture;
}

Result<geometry::TriangleMesh> LoadCaptureMesh(const Capture& capture) {
  return geometry::ReadTriangleMesh(capture.directory / capture.mesh_file, capture.directory);
}

Result<DepthImage> LoadFrame(const Capture& capture, int camera, int frame) {
  if (camera < 0 || camera >= capture.NumCameras()) {
    return Status::InvalidArgument(
        fmt::format("LoadFrame: camera = {}: out of range [0, {})", camera, capture.NumCameras()));
  }
  const CameraRecording& recording = capture.cameras[camera];
  if (frame < 0 || frame >= static_cast<int>(recording.frames.size())) {
    return Status::InvalidArgument(
        fmt::format("LoadFrame: frame = {}: out of range [0, {})", frame, recording.frames.size()));
  }
  return ReadDepthPng(capture.directory / recording.frames[frame], recording.depth_scale,
                      recording.camera.width, recording.camera.height);
}

}  // namespace softid::capture
