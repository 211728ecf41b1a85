#include "core/capture/folder_json.h"

#include <fcntl.h>
#include <fmt/format.h>
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <system_error>

#include "core/capture/capture.h"
#include "core/common/json_fields.h"

namespace softid::capture {

using nlohmann::json;

namespace {

// Largest accepted image side [pixels]; keeps width * height far from integer overflow.
constexpr int kMaxImageSide = 1 << 16;

}  // namespace

std::string JoinPath(std::string_view parent, std::string_view key) {
  return parent.empty() ? std::string(key) : fmt::format("{}.{}", parent, key);
}

std::string IndexPath(std::string_view parent, size_t index) {
  return fmt::format("{}[{}]", parent, index);
}

std::string Shown(const json& value) {
  return softid::json::Brief(value);
}

Status JsonReader::Error(std::string_view path, const json& value, std::string_view reason) const {
  return Status::InvalidArgument(
      fmt::format("{}: {} = {}: {}", source_, path, Shown(value), reason));
}

Status JsonReader::Error(std::string_view path, std::string_view reason) const {
  return Status::InvalidArgument(fmt::format("{}: {}: {}", source_, path, reason));
}

Status JsonReader::WithSource(const Status& status) const {
  return status.WithContext(source_);
}

Result<const json*> JsonReader::Require(const json& object, std::string_view parent,
                                        std::string_view key) const {
  const auto it = object.find(key);
  if (it == object.end()) return Error(JoinPath(parent, key), "missing required field");
  return &*it;
}

Status JsonReader::CheckObject(std::string_view path, const json& value) const {
  if (value.is_object()) return Status::Ok();
  return Error(path.empty() ? "(root)" : path, value, "must be a JSON object");
}

Status JsonReader::CheckArray(std::string_view path, const json& value) const {
  if (value.is_array()) return Status::Ok();
  return Error(path, value, "must be a JSON array");
}

Result<double> JsonReader::Number(std::string_view path, const json& value) const {
  if (!value.is_number()) return Error(path, value, "must be a number");
  const double x = value.get<double>();
  if (!std::isfinite(x)) return Error(path, value, "must be finite");
  return x;
}

Result<double> JsonReader::PositiveNumber(std::string_view path, const json& value) const {
  SOFTID_ASSIGN_OR_RETURN(const double x, Number(path, value));
  if (!(x > 0.0)) return Error(path, value, "must be positive and finite");
  return x;
}

Result<int> JsonReader::Integer(std::string_view path, const json& value) const {
  if (!value.is_number()) return Error(path, value, "must be an integer");
  if (value.is_number_float()) {
    const double x = value.get<double>();
    if (!(std::isfinite(x) && x == std::floor(x))) return Error(path, value, "must be an integer");
    if (std::abs(x) > kMaxImageSide) return Error(path, value, "out of range");
    return static_cast<int>(x);
  }
  if (value.is_number_unsigned()) {
    if (value.get<uint64_t>() > static_cast<uint64_t>(kMaxImageSide)) {
      return Error(path, value, "out of range");
    }
    return static_cast<int>(value.get<uint64_t>());
  }
  const int64_t x = value.get<int64_t>();
  if (x > kMaxImageSide || x < -kMaxImageSide) return Error(path, value, "out of range");
  return static_cast<int>(x);
}

Result<std::string> JsonReader::String(std::string_view path, const json& value) const {
  if (!value.is_string()) return Error(path, value, "must be a string");
  return value.get<std::string>();
}

Result<std::string> JsonReader::RelativePath(std::string_view path, const json& value) const {
  SOFTID_ASSIGN_OR_RETURN(std::string file, String(path, value));
  if (file.empty()) return Error(path, value, "must not be empty");
  if (file.find('\\') != std::string::npos || file.find('\0') != std::string::npos) {
    return Error(path, value, "must use '/' as separator (no '\\' or NUL characters)");
  }
  const std::filesystem::path p(file);
  if (p.is_absolute() || p.has_root_directory() || p.has_root_name()) {
    return Error(path, value, fmt::format("must be relative to the {}, not absolute", folder_));
  }
  for (const auto& component : p) {
    if (component == "..") {
      return Error(path, value, fmt::format("must not leave the {} (\"..\")", folder_));
    }
  }
  if (!p.has_filename()) return Error(path, value, "must name a file");
  return file;
}

Result<Eigen::Vector3d> JsonReader::Vector3(std::string_view path, const json& value) const {
  if (!value.is_array() || value.size() != 3) {
    return Error(path, value, "must be an array of 3 numbers");
  }
  Eigen::Vector3d v;
  for (int i = 0; i < 3; ++i) {
    SOFTID_ASSIGN_OR_RETURN(v[i], Number(IndexPath(path, i), value[i]));
  }
  return v;
}

Result<PinholeCamera> ParseIntrinsics(const JsonReader& reader, const json& value,
                                      std::string_view path) {
  SOFTID_RETURN_IF_ERROR(reader.CheckObject(path, value));
  PinholeCamera camera;
  SOFTID_ASSIGN_OR_RETURN(const json* name, reader.Require(value, path, "name"));
  SOFTID_ASSIGN_OR_RETURN(camera.name, reader.String(JoinPath(path, "name"), *name));
  if (camera.name.empty()) return reader.Error(JoinPath(path, "name"), *name, "must not be empty");

  const auto integer_field = [&](std::string_view key, int* out) -> Status {
    SOFTID_ASSIGN_OR_RETURN(const json* field, reader.Require(value, path, key));
    SOFTID_ASSIGN_OR_RETURN(*out, reader.Integer(JoinPath(path, key), *field));
    return Status::Ok();
  };
  const auto number_field = [&](std::string_view key, double* out) -> Status {
    SOFTID_ASSIGN_OR_RETURN(const json* field, reader.Require(value, path, key));
    SOFTID_ASSIGN_OR_RETURN(*out, reader.Number(JoinPath(path, key), *field));
    return Status::Ok();
  };
  SOFTID_RETURN_IF_ERROR(integer_field("width", &camera.width));
  SOFTID_RETURN_IF_ERROR(integer_field("height", &camera.height));
  // A decoded frame must fit in memory whatever its compressed size (a 510 KB PNG can hold
  // 16384 x 16384 zeros, 512 MiB decoded).
  if (camera.width > 0 && camera.height > 0 &&
      static_cast<int64_t>(camera.width) * camera.height > kMaxImagePixels) {
    return reader.Error(JoinPath(path, "width"), value["width"],
                        fmt::format("{} x {} pixels: at most {} pixels per image are accepted",
                                    camera.width, camera.height, kMaxImagePixels));
  }
  SOFTID_RETURN_IF_ERROR(number_field("fx", &camera.fx));
  SOFTID_RETURN_IF_ERROR(number_field("fy", &camera.fy));
  SOFTID_RETURN_IF_ERROR(number_field("cx", &camera.cx));
  SOFTID_RETURN_IF_ERROR(number_field("cy", &camera.cy));
  // Value checks of the intrinsics, with messages "<path>.fx = -1: must be positive and finite".
  SOFTID_RETURN_IF_ERROR(reader.WithSource(camera.Validate(fmt::format("{}.", path))));
  return camera;
}

Result<double> ParseDepthScale(const JsonReader& reader, const json& value, std::string_view path) {
  SOFTID_ASSIGN_OR_RETURN(const json* depth_scale, reader.Require(value, path, "depth_scale"));
  const std::string depth_scale_path = JoinPath(path, "depth_scale");
  SOFTID_ASSIGN_OR_RETURN(const double scale, reader.Number(depth_scale_path, *depth_scale));
  if (!(scale > 0.0)) {
    return reader.Error(depth_scale_path, *depth_scale,
                        "must be positive (metres per unit of the 16-bit PNG)");
  }
  return scale;
}

Result<Eigen::Isometry3d> ParsePose(const JsonReader& reader, const json& pose,
                                    std::string_view pose_path) {
  if (!pose.is_array() || pose.size() != 16) {
    return reader.Error(pose_path, pose, "must be an array of 16 numbers (row-major 4x4)");
  }
  Eigen::Matrix4d X;
  for (int i = 0; i < 16; ++i) {
    SOFTID_ASSIGN_OR_RETURN(X(i / 4, i % 4), reader.Number(IndexPath(pose_path, i), pose[i]));
  }
  SOFTID_RETURN_IF_ERROR(reader.WithSource(ValidateRigidTransform(X, pose_path)));
  X.row(3) << 0, 0, 0, 1;
  Eigen::Isometry3d isometry;
  isometry.matrix() = X;
  return isometry;
}

bool StaysInside(const std::filesystem::path& root, const std::filesystem::path& target) {
  std::error_code error;
  const std::filesystem::path canonical_root = std::filesystem::canonical(root, error);
  if (error) return false;
  const std::filesystem::path resolved = std::filesystem::weakly_canonical(target, error);
  if (error) return false;
  const std::filesystem::path relative = resolved.lexically_relative(canonical_root);
  return !relative.empty() && *relative.begin() != "..";
}

Status CheckInsideFolder(const JsonReader& reader, const std::filesystem::path& directory,
                         std::string_view path, const std::string& file) {
  if (StaysInside(directory, directory / file)) return Status::Ok();
  return reader.Error(path, json(file),
                      fmt::format("resolves outside the {} (symlink)", reader.folder()));
}

Status CheckMeshSize(const JsonReader& reader, const std::string& file,
                     const geometry::TriangleMesh& mesh, std::string_view size_note) {
  const Eigen::Vector3d size = mesh.Bounds().sizes();
  const double longest = size.maxCoeff();
  if (!(longest >= kMinMeshExtent_m && longest <= kMaxMeshExtent_m)) {
    return reader.Error("mesh", json(file),
                        fmt::format("longest side {:.6g} m: must lie in [{}, {}] m ({})", longest,
                                    kMinMeshExtent_m, kMaxMeshExtent_m, size_note));
  }
  // Scanned meshes with holes still enclose most of their volume; a flat or open sheet does not.
  constexpr double kMinBoxFraction = 1e-4;
  const double volume = std::abs(geometry::SignedVolume(mesh));
  if (!(volume > kMinBoxFraction * size.prod())) {
    return reader.Error("mesh", json(file),
                        fmt::format("encloses no volume ({:.3g} m^3 in a {:.3g} x {:.3g} x {:.3g} "
                                    "m box): softid simulates solid objects",
                                    volume, size.x(), size.y(), size.z()));
  }
  return Status::Ok();
}

bool IsSafeFolderName(const std::string& name) {
  if (name.empty() || name == "." || name == "..") return false;
  for (const char c : name) {
    if (c == '/' || c == '\\' || static_cast<unsigned char>(c) < 0x20) return false;
  }
  return true;
}

Result<std::string> ReadTextFile(const std::filesystem::path& path) {
  std::ifstream file(path, std::ios::binary);
  if (!file) return Status::IoError(fmt::format("{}: cannot open file", path.string()));
  std::ostringstream text;
  text << file.rdbuf();
  if (file.bad()) return Status::IoError(fmt::format("{}: read error", path.string()));
  return text.str();
}

Status WriteFileDurably(const std::filesystem::path& path, const std::string& text) {
  std::FILE* file = std::fopen(path.c_str(), "wb");
  if (file == nullptr) return Status::IoError(fmt::format("{}: cannot create file", path.string()));
  bool ok = std::fwrite(text.data(), 1, text.size(), file) == text.size();
  ok = std::fflush(file) == 0 && ok;
  ok = ::fsync(::fileno(file)) == 0 && ok;
  ok = std::fclose(file) == 0 && ok;
  if (!ok) return Status::IoError(fmt::format("{}: write failed", path.string()));
  return Status::Ok();
}

void SyncDirectory(const std::filesystem::path& directory) {
  const int fd = ::open(directory.c_str(), O_RDONLY | O_DIRECTORY);
  if (fd < 0) return;
  ::fsync(fd);
  ::close(fd);
}

Status WriteFileAtomically(const std::filesystem::path& path, const std::string& text) {
  const std::filesystem::path temp_path = path.string() + ".tmp";
  SOFTID_RETURN_IF_ERROR(WriteFileDurably(temp_path, text));
  std::error_code error;
  std::filesystem::rename(temp_path, path, error);
  if (error) {
    return Status::IoError(fmt::format("{}: cannot rename to {}: {}", temp_path.string(),
                                       path.string(), error.message()));
  }
  SyncDirectory(path.parent_path());
  return Status::Ok();
}

}  // namespace softid::capture
