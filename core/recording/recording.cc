// recording.json: ToJson and its parser RecordingFromJson (no file access).
#include "core/recording/recording.h"

#include <fmt/format.h>

#include <algorithm>
#include <iterator>
#include <nlohmann/json.hpp>
#include <set>

#include "core/capture/capture.h"
#include "core/capture/folder_json.h"

namespace softid::recording {

using capture::IndexPath;
using capture::JoinPath;
using capture::JsonReader;
using nlohmann::json;

double MetresPerUnit(MeshUnit unit) {
  return unit == MeshUnit::kMillimetre ? 1e-3 : 1.0;
}

std::string_view ToString(MeshUnit unit) {
  return unit == MeshUnit::kMillimetre ? "mm" : "m";
}

namespace {

// "format": exactly kRecordingFormat.
Status CheckFormat(const JsonReader& reader, const json& root) {
  SOFTID_ASSIGN_OR_RETURN(const json* format, reader.Require(root, "", "format"));
  SOFTID_ASSIGN_OR_RETURN(const std::string value, reader.String("format", *format));
  if (value == kRecordingFormat) return Status::Ok();
  if (value.starts_with("softid-recording/")) {
    return reader.Error(
        "format", *format,
        fmt::format("unsupported version (this reader supports \"{}\")", kRecordingFormat));
  }
  return reader.Error("format", *format,
                      fmt::format("not a softid recording (expected \"{}\")", kRecordingFormat));
}

Result<MeshUnit> ParseMeshUnit(const JsonReader& reader, const json& value) {
  SOFTID_ASSIGN_OR_RETURN(const std::string unit, reader.String("mesh_unit", value));
  if (unit == "m") return MeshUnit::kMetre;
  if (unit == "mm") return MeshUnit::kMillimetre;
  return reader.Error("mesh_unit", value,
                      "must be \"m\" or \"mm\" (the unit of the mesh file's coordinates)");
}

// "distortion": OpenCV's coefficients, 4, 5, 8, 12 or 14 finite numbers.
Result<std::vector<double>> ParseDistortion(const JsonReader& reader, const json& value,
                                            std::string_view path) {
  SOFTID_RETURN_IF_ERROR(reader.CheckArray(path, value));
  if (std::none_of(std::begin(kDistortionSizes), std::end(kDistortionSizes),
                   [&](int n) { return value.size() == static_cast<size_t>(n); })) {
    return reader.Error(path, value,
                        fmt::format("has {} coefficients: OpenCV's model takes 4, 5, 8, 12 or 14 "
                                    "(k1, k2, p1, p2[, k3[, k4, k5, k6[, s1..s4[, tx, ty]]]])",
                                    value.size()));
  }
  std::vector<double> coefficients;
  for (size_t i = 0; i < value.size(); ++i) {
    SOFTID_ASSIGN_OR_RETURN(const double c, reader.Number(IndexPath(path, i), value[i]));
    coefficients.push_back(c);
  }
  return coefficients;
}

// "frames": 1..kMaxFramesPerCamera objects {"file", "t"} with strictly increasing t.
Result<std::vector<RecordingFrame>> ParseFrames(const JsonReader& reader, const json& camera,
                                                std::string_view camera_path) {
  const std::string path = JoinPath(camera_path, "frames");
  SOFTID_ASSIGN_OR_RETURN(const json* frames, reader.Require(camera, camera_path, "frames"));
  SOFTID_RETURN_IF_ERROR(reader.CheckArray(path, *frames));
  if (frames->empty()) return reader.Error(path, *frames, "must list at least one frame");
  if (frames->size() > static_cast<size_t>(capture::kMaxFramesPerCamera)) {
    return reader.Error(path, fmt::format("{} frames: at most {} frames per camera are accepted",
                                          frames->size(), capture::kMaxFramesPerCamera));
  }
  std::vector<RecordingFrame> out;
  out.reserve(frames->size());
  for (size_t k = 0; k < frames->size(); ++k) {
    const std::string frame_path = IndexPath(path, k);
    const json& frame = (*frames)[k];
    SOFTID_RETURN_IF_ERROR(reader.CheckObject(frame_path, frame));
    SOFTID_ASSIGN_OR_RETURN(const json* file, reader.Require(frame, frame_path, "file"));
    SOFTID_ASSIGN_OR_RETURN(const json* t, reader.Require(frame, frame_path, "t"));
    RecordingFrame parsed;
    SOFTID_ASSIGN_OR_RETURN(parsed.file, reader.RelativePath(JoinPath(frame_path, "file"), *file));
    SOFTID_ASSIGN_OR_RETURN(parsed.time_s, reader.Number(JoinPath(frame_path, "t"), *t));
    if (k > 0 && !(parsed.time_s > out.back().time_s)) {
      return reader.Error(
          JoinPath(frame_path, "t"), *t,
          fmt::format("must be greater than {}.t = {} (time stamps strictly "
                      "increasing)",
                      IndexPath(path, k - 1), capture::Shown((*frames)[k - 1]["t"])));
    }
    out.push_back(std::move(parsed));
  }
  return out;
}

// "background": at most kMaxBackgroundFrames relative paths.
Result<std::vector<std::string>> ParseBackground(const JsonReader& reader, const json& value,
                                                 std::string_view path) {
  SOFTID_RETURN_IF_ERROR(reader.CheckArray(path, value));
  if (value.size() > static_cast<size_t>(kMaxBackgroundFrames)) {
    return reader.Error(path, fmt::format("{} frames: at most {} background frames per camera are "
                                          "accepted",
                                          value.size(), kMaxBackgroundFrames));
  }
  std::vector<std::string> files;
  for (size_t b = 0; b < value.size(); ++b) {
    SOFTID_ASSIGN_OR_RETURN(std::string file, reader.RelativePath(IndexPath(path, b), value[b]));
    files.push_back(std::move(file));
  }
  return files;
}

// One camera; `num_cameras` > 1 makes world_from_camera required.
Result<RecordingCamera> ParseCamera(const JsonReader& reader, const json& value,
                                    std::string_view path, size_t num_cameras) {
  RecordingCamera out;
  SOFTID_ASSIGN_OR_RETURN(out.camera, capture::ParseIntrinsics(reader, value, path));
  if (!capture::IsSafeFolderName(out.camera.name)) {
    return reader.Error(JoinPath(path, "name"), value["name"],
                        "must be usable as a folder name (no '/', '\\' or control characters, "
                        "not \".\" or \"..\")");
  }
  if (const auto it = value.find("distortion"); it != value.end()) {
    SOFTID_ASSIGN_OR_RETURN(out.distortion,
                            ParseDistortion(reader, *it, JoinPath(path, "distortion")));
  }
  SOFTID_ASSIGN_OR_RETURN(out.depth_scale, capture::ParseDepthScale(reader, value, path));
  const std::string pose_path = JoinPath(path, "world_from_camera");
  if (const auto it = value.find("world_from_camera"); it != value.end()) {
    SOFTID_ASSIGN_OR_RETURN(out.camera.X_WC, capture::ParsePose(reader, *it, pose_path));
    out.has_world_from_camera = true;
  } else if (num_cameras > 1) {
    return reader.Error(pose_path,
                        fmt::format("missing required field: the recording has {} cameras, so "
                                    "every camera needs its pose in a common world frame",
                                    num_cameras));
  }
  SOFTID_ASSIGN_OR_RETURN(out.frames, ParseFrames(reader, value, path));
  if (const auto it = value.find("background"); it != value.end()) {
    SOFTID_ASSIGN_OR_RETURN(out.background,
                            ParseBackground(reader, *it, JoinPath(path, "background")));
  }
  return out;
}

Result<std::vector<RecordingCamera>> ParseCameras(const JsonReader& reader, const json& root) {
  SOFTID_ASSIGN_OR_RETURN(const json* cameras, reader.Require(root, "", "cameras"));
  SOFTID_RETURN_IF_ERROR(reader.CheckArray("cameras", *cameras));
  if (cameras->empty()) return reader.Error("cameras", *cameras, "must list at least one camera");
  if (cameras->size() > static_cast<size_t>(capture::kMaxCameras)) {
    return reader.Error("cameras", fmt::format("{} cameras: at most {} are accepted",
                                               cameras->size(), capture::kMaxCameras));
  }
  std::vector<RecordingCamera> out;
  std::set<std::string> names;
  for (size_t i = 0; i < cameras->size(); ++i) {
    const std::string path = IndexPath("cameras", i);
    SOFTID_ASSIGN_OR_RETURN(RecordingCamera camera,
                            ParseCamera(reader, (*cameras)[i], path, cameras->size()));
    if (!names.insert(camera.camera.name).second) {
      return reader.Error(JoinPath(path, "name"), json(camera.camera.name),
                          "duplicate camera name");
    }
    out.push_back(std::move(camera));
  }
  return out;
}

json CameraToJson(const RecordingCamera& recording) {
  const capture::PinholeCamera& camera = recording.camera;
  json out = {{"name", camera.name},     {"width", camera.width},
              {"height", camera.height}, {"fx", camera.fx},
              {"fy", camera.fy},         {"cx", camera.cx},
              {"cy", camera.cy},         {"depth_scale", recording.depth_scale}};
  if (!recording.distortion.empty()) out["distortion"] = recording.distortion;
  if (recording.has_world_from_camera) {
    json pose = json::array();
    for (int i = 0; i < 16; ++i) pose.push_back(camera.X_WC.matrix()(i / 4, i % 4));
    out["world_from_camera"] = std::move(pose);
  }
  json frames = json::array();
  for (const RecordingFrame& frame : recording.frames) {
    frames.push_back({{"file", frame.file}, {"t", frame.time_s}});
  }
  out["frames"] = std::move(frames);
  if (!recording.background.empty()) out["background"] = recording.background;
  return out;
}

}  // namespace

json ToJson(const Recording& recording) {
  json out = json::object();
  out["format"] = std::string(kRecordingFormat);
  out["mesh"] = recording.mesh_file;
  out["mesh_unit"] = std::string(ToString(recording.mesh_unit));
  if (recording.mass_kg) out["mass_kg"] = *recording.mass_kg;
  json cameras = json::array();
  for (const RecordingCamera& camera : recording.cameras) cameras.push_back(CameraToJson(camera));
  out["cameras"] = std::move(cameras);
  return out;
}

Result<Recording> RecordingFromJson(const json& root, std::string_view source) {
  const JsonReader reader(source, "recording folder");
  SOFTID_RETURN_IF_ERROR(reader.CheckObject("", root));
  // Format first, so that another version's differing fields are reported as a version mismatch.
  SOFTID_RETURN_IF_ERROR(CheckFormat(reader, root));
  Recording recording;
  SOFTID_ASSIGN_OR_RETURN(const json* mesh, reader.Require(root, "", "mesh"));
  SOFTID_ASSIGN_OR_RETURN(recording.mesh_file, reader.RelativePath("mesh", *mesh));
  if (const auto it = root.find("mesh_unit"); it != root.end()) {
    SOFTID_ASSIGN_OR_RETURN(recording.mesh_unit, ParseMeshUnit(reader, *it));
  }
  if (const auto it = root.find("mass_kg"); it != root.end()) {
    SOFTID_ASSIGN_OR_RETURN(recording.mass_kg, reader.PositiveNumber("mass_kg", *it));
  }
  SOFTID_ASSIGN_OR_RETURN(recording.cameras, ParseCameras(reader, root));
  return recording;
}

}  // namespace softid::recording
