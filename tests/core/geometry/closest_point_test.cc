#include "core/geometry/closest_point.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <limits>
#include <random>

namespace softid::geometry {
namespace {

// Barycentric coordinates of q in triangle (a, b, c) (q assumed in the plane).
Eigen::Vector3d Barycentric(const Eigen::Vector3d& q, const Eigen::Vector3d& a,
                            const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d n = (b - a).cross(c - a);
  const double area2 = n.squaredNorm();
  return Eigen::Vector3d((b - q).cross(c - q).dot(n), (c - q).cross(a - q).dot(n),
                         (a - q).cross(b - q).dot(n)) /
         area2;
}

// Vertex, edge and face regions give the expected points.
TEST(ClosestPoint, Regions) {
  const Eigen::Vector3d a(0, 0, 0), b(1, 0, 0), c(0, 1, 0);
  EXPECT_TRUE(ClosestPointOnTriangle({-1, -1, 0.5}, a, b, c).isApprox(a));
  EXPECT_TRUE(ClosestPointOnTriangle({2, -0.5, -1}, a, b, c).isApprox(b));
  EXPECT_TRUE(ClosestPointOnTriangle({-0.2, 3, 0}, a, b, c).isApprox(c));
  EXPECT_TRUE(ClosestPointOnTriangle({0.5, -2, 1}, a, b, c).isApprox(Eigen::Vector3d(0.5, 0, 0)));
  EXPECT_TRUE(ClosestPointOnTriangle({1, 1, 0}, a, b, c).isApprox(Eigen::Vector3d(0.5, 0.5, 0)));
  EXPECT_TRUE(
      ClosestPointOnTriangle({0.2, 0.3, -4}, a, b, c).isApprox(Eigen::Vector3d(0.2, 0.3, 0)));
}

// On random triangles the result lies on the triangle and beats dense barycentric sampling.
TEST(ClosestPoint, MatchesBruteForceSampling) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  auto random = [&] { return Eigen::Vector3d(u(rng), u(rng), u(rng)); };
  for (int trial = 0; trial < 200; ++trial) {
    const Eigen::Vector3d a = random(), b = random(), c = random(), p = 2.0 * random();
    const Eigen::Vector3d q = ClosestPointOnTriangle(p, a, b, c);
    const Eigen::Vector3d bary = Barycentric(q, a, b, c);
    EXPECT_GT(bary.minCoeff(), -1e-9);
    EXPECT_NEAR(bary.sum(), 1.0, 1e-9);
    EXPECT_NEAR((b - a).cross(c - a).normalized().dot(q - a), 0.0, 1e-12);
    double best = std::numeric_limits<double>::infinity();
    const int n = 60;
    for (int i = 0; i <= n; ++i) {
      for (int j = 0; i + j <= n; ++j) {
        const Eigen::Vector3d s = a + (b - a) * (double(i) / n) + (c - a) * (double(j) / n);
        best = std::min(best, (s - p).norm());
      }
    }
    EXPECT_LE((q - p).norm(), best + 1e-12);
  }
}

// Degenerate triangles (collinear corners) fall back to the closest edge point.
TEST(ClosestPoint, DegenerateTriangle) {
  const Eigen::Vector3d a(0, 0, 0), b(1, 0, 0), c(2, 0, 0);
  const Eigen::Vector3d q = ClosestPointOnTriangle({1.5, 1, 0}, a, b, c);
  EXPECT_TRUE(q.isApprox(Eigen::Vector3d(1.5, 0, 0))) << q.transpose();
  EXPECT_TRUE(ClosestPointOnTriangle({3, 1, 0}, a, a, a).isApprox(a));
  EXPECT_TRUE(ClosestPointOnSegment({3, 1, 0}, a, c).isApprox(c));
}

}  // namespace
}  // namespace softid::geometry
