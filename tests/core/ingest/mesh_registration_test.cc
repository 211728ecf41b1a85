// The scanned mesh found in a first frame from any starting pose: one side of the object seen
// through a depth camera with noise, the mesh given in an unrelated scanner frame.
#include "core/ingest/mesh_registration.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <numbers>
#include <random>

#include "core/capture/depth_renderer.h"
#include "core/geometry/primitives.h"
#include "tests/core/ingest/raw_scene_util.h"

namespace softid::ingest {
namespace {

// A body without symmetries: a box with a ball on one corner and a bar on another.
geometry::TriangleMesh LopsidedBody() {
  return testing::Merged(
      {geometry::MakeBox(Eigen::Vector3d(0.16, 0.10, 0.06), 0.02),
       testing::Moved(geometry::MakeSphere(0.035, 3), Eigen::Vector3d(0.08, 0.05, 0.04)),
       testing::Moved(geometry::MakeBox(Eigen::Vector3d(0.02, 0.02, 0.08), 0.01),
                      Eigen::Vector3d(-0.07, -0.04, 0.06))});
}

Eigen::Isometry3d RandomPose(std::mt19937& rng, double max_translation) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const Eigen::Vector3d axis = Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized();
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = Eigen::AngleAxisd(std::numbers::pi * u(rng), axis).toRotationMatrix();
  X.translation() = max_translation * Eigen::Vector3d(u(rng), u(rng), u(rng));
  return X;
}

struct PoseError {
  double rms_m = 0.0;
  double angle_deg = 0.0;
};

PoseError Compare(const geometry::TriangleMesh& mesh_S, const Eigen::Isometry3d& a,
                  const Eigen::Isometry3d& b) {
  PoseError e;
  for (const Eigen::Vector3d& v : mesh_S.vertices) e.rms_m += (a * v - b * v).squaredNorm();
  e.rms_m = std::sqrt(e.rms_m / mesh_S.vertices.size());
  e.angle_deg =
      Eigen::AngleAxisd(a.linear().transpose() * b.linear()).angle() * 180.0 / std::numbers::pi;
  return e;
}

// The object's points as a 320 x 240 depth camera 0.7 m away sees them (1.5 mm + 0.2 % noise,
// 1 mm quantum), with the object at X_CS_true.
std::vector<Eigen::Vector3d> Observe(const geometry::TriangleMesh& mesh_S,
                                     const Eigen::Isometry3d& X_CS_true, std::mt19937& rng) {
  capture::PinholeCamera camera;
  camera.name = "cam0";
  camera.width = 320;
  camera.height = 240;
  camera.fx = camera.fy = 280.0;
  camera.cx = 159.5;
  camera.cy = 119.5;
  geometry::TriangleMesh mesh_C = mesh_S;
  for (Eigen::Vector3d& v : mesh_C.vertices) v = X_CS_true * v;
  const capture::DepthImage image = capture::DepthRenderer().Render(mesh_C, camera);
  std::normal_distribution<double> unit(0.0, 1.0);
  std::vector<Eigen::Vector3d> points;
  for (int row = 0; row < camera.height; ++row) {
    for (int col = 0; col < camera.width; ++col) {
      double z = image.at(col, row);
      if (z <= 0.0) continue;
      z = std::round((z + (0.0015 + 0.002 * z) * unit(rng)) * 1000.0) / 1000.0;
      points.push_back(camera.Unproject(col, row, z));
    }
  }
  return points;
}

void ExpectRegistered(const geometry::TriangleMesh& mesh_S, int trials, const char* name) {
  std::mt19937 rng(11);
  for (int trial = 0; trial < trials; ++trial) {
    Eigen::Isometry3d X_CS_true = RandomPose(rng, 0.5);
    X_CS_true.translation() +=
        Eigen::Vector3d(0.0, 0.0, 0.7) - X_CS_true * mesh_S.Bounds().center();
    const std::vector<Eigen::Vector3d> observed = Observe(mesh_S, X_CS_true, rng);
    ASSERT_GT(observed.size(), 500u);
    const Result<MeshRegistration> found = RegisterMesh(mesh_S, observed);
    ASSERT_TRUE(found.ok()) << found.status().ToString();
    const PoseError error = Compare(mesh_S, found->X_CS, X_CS_true);
    std::printf(
        "%s trial %d: %zu points, vertex RMS %.3f mm, %.3f deg, overlap %.3f, ICP RMS %.2f mm\n",
        name, trial, observed.size(), 1e3 * error.rms_m, error.angle_deg, found->overlap,
        1e3 * found->rms_m);
    EXPECT_LT(error.rms_m, 1e-3) << "trial " << trial;
    EXPECT_LT(error.angle_deg, 0.5) << "trial " << trial;
  }
}

TEST(MeshRegistration, LopsidedBodyFromRandomPosesWithinAMillimetreAndHalfADegree) {
  ExpectRegistered(LopsidedBody(), 3, "lopsided");
}

// The Stanford bunny as scanned (holes and all), when the shared meshes are present.
TEST(MeshRegistration, ScannedBunnyFromRandomPoses) {
  const std::filesystem::path file =
      std::filesystem::path(SOFTID_SHARED_DIR) / "data/meshes/stanford_bunny_res3.ply";
  if (!std::filesystem::exists(file)) GTEST_SKIP() << file << " is absent";
  Result<geometry::TriangleMesh> bunny = geometry::ReadTriangleMesh(file);
  ASSERT_TRUE(bunny.ok()) << bunny.status().ToString();
  ExpectRegistered(*bunny, 2, "bunny");
}

// Points that are not the mesh (a flat patch for a lopsided body): the registration says it did
// not converge and how far it got.
// The final ICP alone brings a pose 3 mm and 2 degrees off back to what a full registration
// reaches on one noisy side of the body (half a millimetre, a quarter of a degree), and reports
// the overlap it reached.
TEST(MeshRegistration, RefineFromANearbyPose) {
  std::mt19937 rng(11);
  const geometry::TriangleMesh mesh_S = LopsidedBody();
  Eigen::Isometry3d X_CS_true = RandomPose(rng, 0.05);
  X_CS_true.translation() += Eigen::Vector3d(0.0, 0.0, 0.7);
  const std::vector<Eigen::Vector3d> points = Observe(mesh_S, X_CS_true, rng);
  Eigen::Isometry3d start = X_CS_true;
  start.translation() += Eigen::Vector3d(0.002, -0.002, 0.001);
  start.linear() =
      Eigen::AngleAxisd(2.0 * std::numbers::pi / 180.0, Eigen::Vector3d(1, 1, 0).normalized()) *
      start.linear();
  ASSERT_GT(Compare(mesh_S, start, X_CS_true).rms_m, 0.003);
  const Result<MeshRegistration> refined = RefineMeshPose(mesh_S, points, start);
  ASSERT_TRUE(refined.ok()) << refined.status().ToString();
  const PoseError error = Compare(mesh_S, refined->X_CS, X_CS_true);
  std::printf("refined: vertex RMS %.3f mm, %.3f deg\n", 1e3 * error.rms_m, error.angle_deg);
  EXPECT_LT(error.rms_m, 5e-4);
  EXPECT_LT(error.angle_deg, 0.25);
  EXPECT_GT(refined->overlap, 0.95);
  EXPECT_FALSE(RefineMeshPose(mesh_S, {}, start).ok());
}

TEST(MeshRegistration, NonConvergenceNamesOverlapAndRms) {
  std::vector<Eigen::Vector3d> patch;
  for (int i = 0; i < 40; ++i) {
    for (int j = 0; j < 40; ++j) {
      patch.emplace_back(0.01 * i, 0.01 * j, 0.7 + 0.05 * std::sin(0.5 * i) * std::cos(0.3 * j));
    }
  }
  const Result<MeshRegistration> found = RegisterMesh(LopsidedBody(), patch);
  ASSERT_FALSE(found.ok());
  EXPECT_EQ(found.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(found.status().message().find("did not converge"), std::string::npos);
  EXPECT_NE(found.status().message().find("RMS"), std::string::npos);
  EXPECT_FALSE(RegisterMesh(LopsidedBody(), {}).ok());
}

}  // namespace
}  // namespace softid::ingest
