// Helpers shared by the geometry tests: temporary paths and topology checks.
#pragma once

#include <gtest/gtest.h>

#include <filesystem>
#include <map>
#include <string>
#include <utility>

#include "core/geometry/triangle_mesh.h"

namespace softid::geometry::testing {

// A fresh per-test path in the temp directory (the file is not created).
inline std::filesystem::path TempPath(const std::string& name) {
  const ::testing::TestInfo* info = ::testing::UnitTest::GetInstance()->current_test_info();
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / "softid_geometry_tests";
  std::filesystem::create_directories(dir);
  return dir / (std::string(info->test_suite_name()) + "_" + info->name() + "_" + name);
}

// True when every undirected edge is used by exactly two triangles, once in each direction
// (closed, consistently oriented, manifold at edges).
inline bool IsWatertight(const TriangleMesh& mesh) {
  std::map<std::pair<int, int>, int> directed;
  for (const Eigen::Vector3i& t : mesh.triangles) {
    for (int c = 0; c < 3; ++c) ++directed[{t[c], t[(c + 1) % 3]}];
  }
  for (const auto& [edge, count] : directed) {
    if (count != 1) return false;
    const auto twin = directed.find({edge.second, edge.first});
    if (twin == directed.end() || twin->second != 1) return false;
  }
  return !mesh.triangles.empty();
}

inline double MaxEdgeLength(const TriangleMesh& mesh) {
  double longest = 0.0;
  for (const Eigen::Vector3i& t : mesh.triangles) {
    for (int c = 0; c < 3; ++c) {
      longest = std::max(longest, (mesh.vertices[t[c]] - mesh.vertices[t[(c + 1) % 3]]).norm());
    }
  }
  return longest;
}

// Path of a scanned mesh in the shared data folder (may not exist).
inline std::filesystem::path SharedMesh(const std::string& name) {
  return std::filesystem::path(SOFTID_SHARED_DIR "/data/meshes/") / name;
}

}  // namespace softid::geometry::testing
