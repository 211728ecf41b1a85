#include "core/geometry/hole_caps.h"

#include <gtest/gtest.h>

#include <filesystem>

#include "core/geometry/primitives.h"
#include "tests/core/geometry/mesh_test_util.h"

namespace softid::geometry {
namespace {

// `mesh` without the triangles whose vertices all satisfy `cut`.
template <typename Cut>
TriangleMesh WithoutFaces(const TriangleMesh& mesh, Cut cut) {
  TriangleMesh out = mesh;
  out.triangles.clear();
  for (const Eigen::Vector3i& t : mesh.triangles) {
    if (!(cut(mesh.vertices[t[0]]) && cut(mesh.vertices[t[1]]) && cut(mesh.vertices[t[2]]))) {
      out.triangles.push_back(t);
    }
  }
  return out;
}

TEST(HoleCaps, ClosedMeshHasNoHoles) {
  const TriangleMesh sphere = MakeSphere(0.1, 2);
  EXPECT_TRUE(FindHoleLoops(sphere).empty());
  const TriangleMesh capped = WithHolesCapped(sphere, FindHoleLoops(sphere));
  EXPECT_EQ(capped.vertices.size(), sphere.vertices.size());
  EXPECT_EQ(capped.triangles.size(), sphere.triangles.size());
}

// A box opened at the top and the bottom has two holes; the caps close it with the orientation of
// its sides, so the capped box encloses the whole box's volume.
TEST(HoleCaps, CapsCloseAnOpenBoxWithItsOrientation) {
  const Eigen::Vector3d size(0.2, 0.1, 0.05);
  const TriangleMesh box = MakeBox(size, 0.03);
  const TriangleMesh open =
      WithoutFaces(box, [&](const Eigen::Vector3d& v) { return std::abs(v.z()) > 0.0249; });
  ASSERT_LT(open.triangles.size(), box.triangles.size());
  ASSERT_FALSE(testing::IsWatertight(open));
  const HoleLoops holes = FindHoleLoops(open);
  ASSERT_EQ(holes.loops.size(), 2u);
  for (const auto& loop : holes.loops) EXPECT_GE(loop.size(), 4u);
  const TriangleMesh capped = WithHolesCapped(open, holes);
  EXPECT_EQ(capped.vertices.size(), open.vertices.size() + 2);
  EXPECT_TRUE(testing::IsWatertight(capped));
  EXPECT_NEAR(SignedVolume(capped), size.prod(), 1e-9);
}

// A deformed copy reuses the rest mesh's loops: the caps follow the moved vertices.
TEST(HoleCaps, CapsFollowADeformedCopy) {
  const TriangleMesh box = MakeBox(Eigen::Vector3d(0.1, 0.1, 0.1), 0.05);
  const TriangleMesh open =
      WithoutFaces(box, [](const Eigen::Vector3d& v) { return v.z() > 0.0499; });
  const HoleLoops holes = FindHoleLoops(open);
  ASSERT_EQ(holes.loops.size(), 1u);
  TriangleMesh moved = open;
  for (Eigen::Vector3d& v : moved.vertices) v += Eigen::Vector3d(1.0, 2.0, 3.0);
  const TriangleMesh capped = WithHolesCapped(moved, holes);
  EXPECT_TRUE(capped.vertices.back().isApprox(Eigen::Vector3d(1.0, 2.0, 3.05), 1e-12));
}

// The scanned bunny's holes (its base, a few concave spots) all close.
TEST(HoleCaps, ClosesTheScannedBunny) {
  const auto path = testing::SharedMesh("stanford_bunny_res3.ply");
  if (!std::filesystem::exists(path)) GTEST_SKIP() << path << " not available";
  const Result<TriangleMesh> bunny = ReadTriangleMesh(path);
  ASSERT_TRUE(bunny.ok()) << bunny.status().ToString();
  const HoleLoops holes = FindHoleLoops(*bunny);
  EXPECT_GE(holes.loops.size(), 2u);
  const TriangleMesh capped = WithHolesCapped(*bunny, holes);
  EXPECT_TRUE(FindHoleLoops(capped).empty());
  EXPECT_GT(std::abs(SignedVolume(capped)), std::abs(SignedVolume(*bunny)));
}

}  // namespace
}  // namespace softid::geometry
