#include "core/geometry/mesh_distance.h"

#include <gtest/gtest.h>

#include <random>

#include "core/geometry/closest_point.h"
#include "core/geometry/primitives.h"

namespace softid::geometry {
namespace {

double BruteForceDistance(const TriangleMesh& mesh, const Eigen::Vector3d& p) {
  double best = std::numeric_limits<double>::infinity();
  for (const Eigen::Vector3i& t : mesh.triangles) {
    best = std::min(best, (ClosestPointOnTriangle(p, mesh.vertices[t[0]], mesh.vertices[t[1]],
                                                  mesh.vertices[t[2]]) -
                           p)
                              .norm());
  }
  return best;
}

// Embree point queries agree with brute force over all triangles, near and far.
TEST(MeshDistance, MatchesBruteForce) {
  const TriangleMesh torus = MakeTorus(0.1, 0.03, 48, 24);
  const Result<MeshDistance> distance = MeshDistance::Create(torus);
  ASSERT_TRUE(distance.ok()) << distance.status().ToString();
  std::mt19937 rng(13);
  std::uniform_real_distribution<double> u(-0.2, 0.2);
  for (int trial = 0; trial < 500; ++trial) {
    const Eigen::Vector3d p(u(rng), u(rng), u(rng) * (trial % 2 ? 0.2 : 3.0));
    const ClosestPoint closest = distance->Closest(p);
    ASSERT_NEAR(closest.distance, BruteForceDistance(torus, p), 1e-12) << p.transpose();
    ASSERT_GE(closest.triangle, 0);
    const Eigen::Vector3i& t = torus.triangles[closest.triangle];
    EXPECT_NEAR((ClosestPointOnTriangle(p, torus.vertices[t[0]], torus.vertices[t[1]],
                                        torus.vertices[t[2]]) -
                 closest.point)
                    .norm(),
                0.0, 1e-12);
  }
}

// Points on the surface have distance 0; far points the distance to the nearest vertex.
TEST(MeshDistance, OnSurfaceAndFar) {
  const TriangleMesh box = MakeBox(Eigen::Vector3d(0.2, 0.1, 0.1), 0.05);
  const Result<MeshDistance> distance = MeshDistance::Create(box);
  ASSERT_TRUE(distance.ok());
  EXPECT_NEAR(distance->Distance({0.1, 0.01, 0.02}), 0.0, 1e-15);
  EXPECT_NEAR(distance->Distance({0.0, 0.0, 0.0}), 0.05, 1e-15);  // centre: nearest faces y, z
  EXPECT_NEAR(distance->Distance({1.1, 0.05, 0.05}), 1.0, 1e-12);
  EXPECT_NEAR(distance->Distance({100.1, 100.05, 0.0}), std::sqrt(2.0) * 100.0, 1e-9);
}

// Empty meshes, bad indices and NaN vertices are rejected with a message.
TEST(MeshDistance, RejectsBrokenMeshes) {
  EXPECT_EQ(MeshDistance::Create(TriangleMesh()).status().code(), StatusCode::kInvalidArgument);
  TriangleMesh mesh = MakeBox(Eigen::Vector3d::Constant(0.1), 1.0);
  mesh.triangles[3][1] = 8;
  const Status bad_index = MeshDistance::Create(mesh).status();
  EXPECT_NE(bad_index.message().find("triangle 3"), std::string::npos) << bad_index.message();
  mesh = MakeBox(Eigen::Vector3d::Constant(0.1), 1.0);
  mesh.vertices[2].x() = std::numeric_limits<double>::quiet_NaN();
  const Status nan = MeshDistance::Create(mesh).status();
  EXPECT_NE(nan.message().find("vertex 2"), std::string::npos) << nan.message();
}

}  // namespace
}  // namespace softid::geometry
