#include "core/geometry/primitives.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <stdexcept>

#include "tests/core/geometry/mesh_test_util.h"

namespace softid::geometry {
namespace {

using std::numbers::pi;
using testing::IsWatertight;
using testing::MaxEdgeLength;

// The icosphere is closed, outward and within 1 % of the ball volume and sphere area.
TEST(Primitives, SphereVolumeAndArea) {
  const double r = 0.1;
  const TriangleMesh sphere = MakeSphere(r, 4);
  EXPECT_EQ(sphere.triangles.size(), 20u * 256u);
  EXPECT_EQ(sphere.vertices.size(), 10u * 256u + 2u);
  EXPECT_TRUE(IsWatertight(sphere));
  for (const Eigen::Vector3d& v : sphere.vertices) ASSERT_NEAR(v.norm(), r, 1e-12);
  EXPECT_NEAR(SignedVolume(sphere), 4.0 / 3.0 * pi * r * r * r, 0.01 * 4.0 / 3.0 * pi * r * r * r);
  EXPECT_LT(SignedVolume(sphere), 4.0 / 3.0 * pi * r * r * r);  // inscribed polyhedron
  EXPECT_NEAR(SurfaceArea(sphere), 4.0 * pi * r * r, 0.01 * 4.0 * pi * r * r);
}

// The torus is closed, outward and within 1 % of 2 pi^2 R r^2.
TEST(Primitives, TorusVolume) {
  const double R = 0.2, r = 0.05;
  const TriangleMesh torus = MakeTorus(R, r, 64, 32);
  EXPECT_TRUE(IsWatertight(torus));
  const double expected = 2.0 * pi * pi * R * r * r;
  EXPECT_NEAR(SignedVolume(torus), expected, 0.01 * expected);
  EXPECT_NEAR(SurfaceArea(torus), 4.0 * pi * pi * R * r, 0.01 * 4.0 * pi * pi * R * r);
  const Eigen::AlignedBox3d box = torus.Bounds();
  EXPECT_NEAR(box.max().z(), r, 1e-12);
  EXPECT_NEAR(box.max().x(), R + r, 1e-12);
}

// The box is closed, outward, centred, exact in volume and area, with bounded edges.
TEST(Primitives, BoxIsExactAndWatertight) {
  const Eigen::Vector3d size(0.2, 0.1, 0.05);
  const TriangleMesh box = MakeBox(size, 0.02);
  EXPECT_TRUE(IsWatertight(box));
  EXPECT_LE(MaxEdgeLength(box), 0.02 + 1e-15);
  EXPECT_NEAR(SignedVolume(box), size.prod(), 1e-15);
  EXPECT_NEAR(SurfaceArea(box), 2.0 * (0.2 * 0.1 + 0.1 * 0.05 + 0.05 * 0.2), 1e-15);
  EXPECT_TRUE(box.Bounds().min().isApprox(-0.5 * size));
  EXPECT_TRUE(box.Bounds().max().isApprox(0.5 * size));
  // Surface lattice: (nx+1)(ny+1)(nz+1) - (nx-1)(ny-1)(nz-1) vertices, 4(nx ny + ny nz + nz nx)
  // tris.
  const int nx = 15, ny = 8, nz = 4;  // ceil(size * sqrt(2) / 0.02)
  EXPECT_EQ(box.vertices.size(),
            static_cast<size_t>((nx + 1) * (ny + 1) * (nz + 1) - (nx - 1) * (ny - 1) * (nz - 1)));
  EXPECT_EQ(box.triangles.size(), static_cast<size_t>(4 * (nx * ny + ny * nz + nz * nx)));
}

// A coarse box is a 12-triangle cube; bad arguments throw.
TEST(Primitives, CoarseBoxAndBadArguments) {
  const TriangleMesh cube = MakeBox(Eigen::Vector3d::Constant(0.1), 1.0);
  EXPECT_EQ(cube.vertices.size(), 8u);
  EXPECT_EQ(cube.triangles.size(), 12u);
  EXPECT_NEAR(SignedVolume(cube), 1e-3, 1e-15);
  EXPECT_THROW(MakeBox(Eigen::Vector3d(0.1, 0.0, 0.1), 0.01), std::invalid_argument);
  EXPECT_THROW(MakeSphere(-1.0, 2), std::invalid_argument);
  EXPECT_THROW(MakeTorus(0.1, 0.2, 8, 8), std::invalid_argument);
}

}  // namespace
}  // namespace softid::geometry
