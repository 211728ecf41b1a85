#include "core/geometry/winding_number.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <numbers>
#include <random>

#include "core/geometry/primitives.h"
#include "tests/core/geometry/mesh_test_util.h"

namespace softid::geometry {
namespace {

// A closed sphere has w = 1 inside and 0 outside, also close to the surface.
TEST(WindingNumber, SphereInsideOneOutsideZero) {
  const TriangleMesh sphere = MakeSphere(0.1, 3);
  const WindingNumber w(sphere);
  for (const Eigen::Vector3d& p : {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(0.05, -0.03, 0.02),
                                   Eigen::Vector3d(0, 0, 0.098)}) {
    EXPECT_NEAR(w(p), 1.0, 1e-3) << p.transpose();
    EXPECT_NEAR(w.Exact(p), 1.0, 1e-9) << p.transpose();
  }
  for (const Eigen::Vector3d& p :
       {Eigen::Vector3d(0.2, 0, 0), Eigen::Vector3d(0, 0, -0.102), Eigen::Vector3d(3, 4, 5)}) {
    EXPECT_NEAR(w(p), 0.0, 1e-3) << p.transpose();
    EXPECT_NEAR(w.Exact(p), 0.0, 1e-9) << p.transpose();
  }
}

// Reversing the orientation negates w.
TEST(WindingNumber, OrientationFlipsSign) {
  TriangleMesh sphere = MakeSphere(0.1, 2);
  for (Eigen::Vector3i& t : sphere.triangles) std::swap(t[1], t[2]);
  EXPECT_NEAR(WindingNumber(sphere)(Eigen::Vector3d(0.01, 0.02, 0.0)), -1.0, 1e-3);
}

// With a few triangles deleted (a hole) w stays ~1 inside and ~0 outside away from the hole.
TEST(WindingNumber, SphereWithHoleStaysRobust) {
  TriangleMesh sphere = MakeSphere(0.1, 4);
  // Delete the triangles whose centroid is near the north pole (a hole of radius ~1.5 cm).
  std::vector<Eigen::Vector3i> kept;
  for (const Eigen::Vector3i& t : sphere.triangles) {
    const Eigen::Vector3d c =
        (sphere.vertices[t[0]] + sphere.vertices[t[1]] + sphere.vertices[t[2]]) / 3.0;
    if ((c - Eigen::Vector3d(0, 0, 0.1)).norm() > 0.015) kept.push_back(t);
  }
  ASSERT_LT(kept.size(), sphere.triangles.size());
  ASSERT_GT(kept.size(), sphere.triangles.size() - 60);
  sphere.triangles = kept;
  const WindingNumber w(sphere);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int inside_checked = 0, outside_checked = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    const Eigen::Vector3d p = 0.15 * Eigen::Vector3d(u(rng), u(rng), u(rng));
    if ((p - Eigen::Vector3d(0, 0, 0.1)).norm() < 0.05) continue;  // near the hole
    if (std::abs(p.norm() - 0.1) < 0.005) continue;                // near the surface
    if (p.norm() < 0.1) {
      EXPECT_GT(w(p), 0.9) << p.transpose();
      ++inside_checked;
    } else {
      EXPECT_LT(w(p), 0.1) << p.transpose();
      ++outside_checked;
    }
  }
  EXPECT_GT(inside_checked, 200);
  EXPECT_GT(outside_checked, 200);
  // In the middle of the hole w is about halfway.
  const double at_hole = w(Eigen::Vector3d(0, 0, 0.1));
  EXPECT_GT(at_hole, 0.3);
  EXPECT_LT(at_hole, 0.7);
}

// The hierarchical evaluation agrees with brute force to 1e-3 on random points near a torus.
TEST(WindingNumber, FastAgreesWithBruteForce) {
  const TriangleMesh torus = MakeTorus(0.1, 0.04, 96, 48);
  const WindingNumber w(torus);
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-0.16, 0.16);
  double max_error = 0.0;
  for (int trial = 0; trial < 2000; ++trial) {
    const Eigen::Vector3d p(u(rng), u(rng), 0.4 * u(rng));
    max_error = std::max(max_error, std::abs(w(p) - w.Exact(p)));
  }
  EXPECT_LT(max_error, 1e-3);
}

// ~100k queries against an 80k-triangle mesh take about a second (10 s bound for loaded CI).
TEST(WindingNumber, FastEnoughForGrids) {
  const TriangleMesh sphere = MakeSphere(0.1, 6);  // 81920 triangles
  const WindingNumber w(sphere);
  const int n = 46;  // 97336 queries on a grid around the sphere
  const double spacing = 0.24 / (n - 1);
  const auto start = std::chrono::steady_clock::now();
  int inside = 0;
  for (int k = 0; k < n; ++k) {
    for (int j = 0; j < n; ++j) {
      for (int i = 0; i < n; ++i) {
        const Eigen::Vector3d p =
            -0.12 * Eigen::Vector3d::Ones() + spacing * Eigen::Vector3d(i, j, k);
        inside += w(p) >= 0.5;
      }
    }
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  // Each node stands for a cube of edge `spacing`: the inside count measures the ball volume.
  const double ball = 4.0 / 3.0 * std::numbers::pi * 1e-3;
  EXPECT_NEAR(inside * spacing * spacing * spacing, ball, 0.01 * ball);
  EXPECT_LT(seconds, 10.0) << "took " << seconds << " s";  // brute force: minutes
  RecordProperty("seconds", std::to_string(seconds));
  std::printf("100k winding number queries, 82k triangles: %.3f s\n", seconds);
}

// The scanned bunny (with holes) gets w ~ 1 deep inside and ~ 0 far outside.
TEST(WindingNumber, ScannedBunnyHasAnInside) {
  const auto path = testing::SharedMesh("stanford_bunny_res3.ply");
  if (!std::filesystem::exists(path)) GTEST_SKIP() << path << " not available";
  const Result<TriangleMesh> bunny = ReadTriangleMesh(path);
  ASSERT_TRUE(bunny.ok()) << bunny.status().ToString();
  const WindingNumber w(*bunny);
  const Eigen::AlignedBox3d box = bunny->Bounds();
  EXPECT_NEAR(w(box.max() + box.sizes()), 0.0, 1e-3);
  // Fraction of a fine grid of the bounding box that is inside ~ volume / box volume.
  const int n = 30;
  int inside = 0;
  for (int k = 0; k < n; ++k) {
    for (int j = 0; j < n; ++j) {
      for (int i = 0; i < n; ++i) {
        const Eigen::Vector3d t = (Eigen::Vector3d(i, j, k) + Eigen::Vector3d::Constant(0.5)) / n;
        inside += w(box.min() + box.sizes().cwiseProduct(t)) >= 0.5;
      }
    }
  }
  const double fraction = inside / double(n * n * n);
  EXPECT_NEAR(fraction, SignedVolume(*bunny) / box.volume(), 0.05 * fraction);
}

}  // namespace
}  // namespace softid::geometry
