// Helpers shared by the readers and writers of softid's folder formats (capture.json,
// recording.json): typed reads of JSON fields whose errors read
// "<source>: <field path> = <value>: <reason>", relative paths that stay inside the folder, the
// common camera fields, mesh plausibility, and durable file writes.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstddef>
#include <filesystem>
#include <nlohmann/json_fwd.hpp>
#include <string>
#include <string_view>

#include "core/capture/camera.h"
#include "core/common/status.h"
#include "core/geometry/triangle_mesh.h"

namespace softid::capture {

// The field path of member `key` of the value at `parent`: "parent.key", or "key" at the root.
std::string JoinPath(std::string_view parent, std::string_view key);
// The field path of element `index` of the array at `parent`: "parent[index]".
std::string IndexPath(std::string_view parent, size_t index);
// A JSON value for an error message, shortened when long.
std::string Shown(const nlohmann::json& value);

// Typed reads of the fields of one JSON document. Errors are InvalidArgument
// "<source>: <path> = <value>: <reason>" (or "<source>: <path>: <reason>" without a value).
class JsonReader {
 public:
  // `source` names the document in messages ("<dir>/capture.json"); `folder` names the folder
  // its relative paths refer to ("capture folder", "recording folder").
  explicit JsonReader(std::string_view source, std::string_view folder = "capture folder")
      : source_(source), folder_(folder) {}

  const std::string& source() const { return source_; }
  const std::string& folder() const { return folder_; }

  Status Error(std::string_view path, const nlohmann::json& value, std::string_view reason) const;
  Status Error(std::string_view path, std::string_view reason) const;
  // `status` with its message prefixed by "<source>: ".
  Status WithSource(const Status& status) const;

  // The member `key` of `object` (at `parent`), or "missing required field".
  Result<const nlohmann::json*> Require(const nlohmann::json& object, std::string_view parent,
                                        std::string_view key) const;
  // OK when `value` is a JSON object (the root is named "(root)").
  Status CheckObject(std::string_view path, const nlohmann::json& value) const;
  // OK when `value` is a JSON array.
  Status CheckArray(std::string_view path, const nlohmann::json& value) const;
  // A finite number.
  Result<double> Number(std::string_view path, const nlohmann::json& value) const;
  // A finite number > 0.
  Result<double> PositiveNumber(std::string_view path, const nlohmann::json& value) const;
  // An integer of magnitude <= 65536; integral floating-point values such as 640.0 are accepted.
  Result<int> Integer(std::string_view path, const nlohmann::json& value) const;
  // A JSON string.
  Result<std::string> String(std::string_view path, const nlohmann::json& value) const;
  // A non-empty '/'-separated path relative to the folder that does not leave it lexically (not
  // absolute, no "..", no '\\' or NUL) and names a file.
  Result<std::string> RelativePath(std::string_view path, const nlohmann::json& value) const;
  // An array of 3 finite numbers.
  Result<Eigen::Vector3d> Vector3(std::string_view path, const nlohmann::json& value) const;

 private:
  std::string source_;
  std::string folder_;
};

// Reads the camera object `value` (a JSON object, else an error) at `path`: its name (a non-empty
// string), width and height (at most kMaxImagePixels together), fx, fy, cx, cy, checked with
// PinholeCamera::Validate. X_WC is left at identity.
Result<PinholeCamera> ParseIntrinsics(const JsonReader& reader, const nlohmann::json& value,
                                      std::string_view path);
// Reads the required "depth_scale" of the camera object `value` at `path` [m per PNG unit], > 0.
Result<double> ParseDepthScale(const JsonReader& reader, const nlohmann::json& value,
                               std::string_view path);
// Reads `pose` (at `pose_path`): 16 finite numbers, a row-major rigid 4x4 transform.
Result<Eigen::Isometry3d> ParsePose(const JsonReader& reader, const nlohmann::json& pose,
                                    std::string_view pose_path);

// Whether `target` resolves (following symlinks) to a location inside `root`.
bool StaysInside(const std::filesystem::path& root, const std::filesystem::path& target);
// OK when directory / file resolves inside `directory`; otherwise the error
// "<path> = "<file>": resolves outside the <folder> (symlink)".
Status CheckInsideFolder(const JsonReader& reader, const std::filesystem::path& directory,
                         std::string_view path, const std::string& file);

// A mesh softid can simulate (`mesh` in metres): longest side in [kMinMeshExtent_m,
// kMaxMeshExtent_m] and enclosing a volume. Errors name the field "mesh" and `file`;
// `size_note` ends the message of a size out of range (e.g. "capture meshes are in metres").
Status CheckMeshSize(const JsonReader& reader, const std::string& file,
                     const geometry::TriangleMesh& mesh, std::string_view size_note);

// Whether `name` can be used as a single folder name: not empty, not "." or "..", no '/', '\\' or
// control characters.
bool IsSafeFolderName(const std::string& name);

// The whole file at `path`; IoError naming it when it cannot be read.
Result<std::string> ReadTextFile(const std::filesystem::path& path);
// Writes `text` to `path` and flushes it to the disk; IoError naming the path.
Status WriteFileDurably(const std::filesystem::path& path, const std::string& text);
// Flushes a folder's entries (a rename into it) to the disk; best effort.
void SyncDirectory(const std::filesystem::path& directory);
// Writes `text` to "<path>.tmp", flushes it, renames it to `path` and flushes the folder, so that
// `path` is either absent or complete after a crash. IoError naming the file that failed.
Status WriteFileAtomically(const std::filesystem::path& path, const std::string& text);

}  // namespace softid::capture
