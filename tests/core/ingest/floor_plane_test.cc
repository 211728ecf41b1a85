// The floor of a raw recording's static scene: found beside a wall and a box, through a distorted
// lens with depth noise, to within 0.5 degrees and 1 mm of the truth.
#include "core/ingest/floor_plane.h"

#include <gtest/gtest.h>

#include <numbers>
#include <random>

#include "core/ingest/static_scene.h"
#include "tests/core/ingest/raw_scene_util.h"

namespace softid::ingest {
namespace {

double Degrees(double radians) {
  return radians * 180.0 / std::numbers::pi;
}

TEST(FloorPlane, FloorBesideAWallWithinHalfADegreeAndAMillimetre) {
  const testing::RawScene s = testing::MakeRawScene();
  const Result<StaticScene> scene = EstimateStaticScene(s.frames);
  ASSERT_TRUE(scene.ok());
  std::vector<Eigen::Vector3d> points;
  std::vector<float> sigmas;
  StaticScenePoints(*scene, s.rays, &points, &sigmas);
  ASSERT_GT(points.size(), 10000u);
  // An upright camera: image up is -y.
  const Result<FloorPlane> floor = FindFloorPlane(points, sigmas, Eigen::Vector3d(0, -1, 0));
  ASSERT_TRUE(floor.ok()) << floor.status().ToString();
  // In the world frame: the floor's top is z = 0, normal +z.
  const Eigen::Isometry3d& X_WC = s.camera.X_WC;
  const Eigen::Vector3d normal_W = X_WC.linear() * floor->normal_C;
  const double offset_W = floor->offset_m + normal_W.dot(X_WC.translation());
  EXPECT_LT(Degrees(std::acos(std::min(1.0, normal_W.z()))), 0.5);
  EXPECT_NEAR(offset_W, 0.0, 1e-3);
  EXPECT_GT(floor->inlier_share, 0.3);
  EXPECT_LT(floor->rms_m, 0.01);
  std::printf("floor: %.3f deg, offset %.2f mm, %d inliers (%.0f %%), rms %.2f mm\n",
              Degrees(std::acos(std::min(1.0, normal_W.z()))), 1e3 * offset_W, floor->inliers,
              100 * floor->inlier_share, 1e3 * floor->rms_m);
}

// A 640 x 480 view gives 10^5 static points: RANSAC runs on an even share of them, and the inliers
// are then every floor point within the threshold, so the count and the fit use them all.
TEST(FloorPlane, ManyPointsFoundFromAShareWithEveryInlierCounted) {
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0.0, 0.002);
  std::vector<Eigen::Vector3d> points;
  std::vector<float> sigmas;
  // Camera frame of a camera looking down at 30 degrees: floor 1.2 m below, a wall ahead.
  const Eigen::Vector3d up = Eigen::AngleAxisd(-std::numbers::pi / 6, Eigen::Vector3d::UnitX()) *
                             Eigen::Vector3d(0, -1, 0);
  const Eigen::Vector3d e1 = Eigen::Vector3d::UnitX(), e2 = up.cross(e1);
  const Eigen::Vector3d below = -1.2 * up + 1.0 * e2;
  for (int i = 0; i < 300; ++i) {
    for (int j = 0; j < 300; ++j) {
      points.push_back(below + (-1.0 + i / 150.0) * e1 + (j / 150.0) * e2 + noise(rng) * up);
      sigmas.push_back(0.002f);
    }
  }
  const int floor_points = static_cast<int>(points.size());
  for (int i = 0; i < 200; ++i) {
    for (int j = 0; j < 150; ++j) {
      points.push_back(below + 2.0 * e2 + (-1.0 + i / 100.0) * e1 + (j / 100.0) * up +
                       noise(rng) * e2);
      sigmas.push_back(0.002f);
    }
  }
  const Result<FloorPlane> floor = FindFloorPlane(points, sigmas, Eigen::Vector3d(0, -1, 0));
  ASSERT_TRUE(floor.ok()) << floor.status().ToString();
  EXPECT_LT(Degrees(std::acos(std::min(1.0, floor->normal_C.dot(up)))), 0.5);
  EXPECT_NEAR(floor->offset_m, up.dot(below), 1e-3);
  // The threshold, 3 sigma, holds 99.7 % of them; the wall's foot adds a few points.
  EXPECT_GT(floor->inliers, 0.99 * floor_points);
  EXPECT_LT(floor->inliers, 1.02 * floor_points);
}

// A camera looking at a wall only: no plane faces up, and the message lists what was seen.
TEST(FloorPlane, NoFloorNamesThePlanesSeen) {
  std::vector<Eigen::Vector3d> wall;
  for (int i = 0; i < 60; ++i) {
    for (int j = 0; j < 60; ++j) wall.emplace_back(-0.3 + 0.01 * i, -0.3 + 0.01 * j, 1.0);
  }
  const Result<FloorPlane> floor = FindFloorPlane(wall, {}, Eigen::Vector3d(0, -1, 0));
  ASSERT_FALSE(floor.ok());
  EXPECT_EQ(floor.status().code(), StatusCode::kNotFound);
  EXPECT_NE(floor.status().message().find("3600 points at 90 deg from up"), std::string::npos)
      << floor.status().message();
}

}  // namespace
}  // namespace softid::ingest
