#include "core/capture/depth_renderer.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "core/capture/pixel_rays.h"
#include "core/geometry/primitives.h"

namespace softid::capture {
namespace {

// A 121 x 101 camera at the world origin looking along +x (z up); pixel (60, 50) is on the axis.
PinholeCamera MakeCamera(const Eigen::Isometry3d& X_WC) {
  PinholeCamera camera;
  camera.name = "cam";
  camera.width = 121;
  camera.height = 101;
  camera.fx = camera.fy = 200.0;
  camera.cx = 60.0;
  camera.cy = 50.0;
  camera.X_WC = X_WC;
  return camera;
}

geometry::TriangleMesh Translated(geometry::TriangleMesh mesh, const Eigen::Vector3d& offset) {
  for (Eigen::Vector3d& v : mesh.vertices) v += offset;
  return mesh;
}

constexpr double kRadius = 0.1;    // [m]
constexpr double kDistance = 0.6;  // [m] camera to sphere centre
constexpr int kSubdivisions = 5;   // 20480 triangles, chord sagitta < 5e-4 r

// A sphere straight ahead at distance D has centre depth D - r and silhouette radius
// fx r / sqrt(D^2 - r^2) pixels.
TEST(DepthRenderer, SphereCentreDepthAndSilhouette) {
  const DepthRenderer renderer;
  const PinholeCamera camera = MakeCamera(
      LookAt(Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitZ()));
  const geometry::TriangleMesh sphere =
      Translated(geometry::MakeSphere(kRadius, kSubdivisions), Eigen::Vector3d(kDistance, 0, 0));
  const DepthImage image = renderer.Render(sphere, camera);
  ASSERT_EQ(image.width, 121);
  ASSERT_EQ(image.height, 101);
  EXPECT_NEAR(image.at(60, 50), kDistance - kRadius, 1e-4);

  const double expected_radius =
      camera.fx * kRadius / std::sqrt(kDistance * kDistance - kRadius * kRadius);
  const double area_radius = std::sqrt(image.NumValid() / M_PI);
  EXPECT_NEAR(area_radius, expected_radius, 1.0);
  int left = camera.width, right = -1;
  for (int col = 0; col < camera.width; ++col) {
    if (image.at(col, 50) > 0) {
      left = std::min(left, col);
      right = std::max(right, col);
    }
  }
  EXPECT_NEAR(0.5 * (right - left + 1), expected_radius, 1.0);
  EXPECT_NEAR(0.5 * (left + right), camera.cx, 0.5);
  EXPECT_EQ(image.at(0, 0), 0.0f);  // background has no data
}

// Unprojected depth pixels lie on the sphere (within the chord error), also for a camera and
// sphere far from the world origin.
TEST(DepthRenderer, UnprojectedPointsLieOnSphere) {
  const DepthRenderer renderer;
  const Eigen::Vector3d centre_W(100.0, -50.0, 3.0);
  const geometry::TriangleMesh sphere =
      Translated(geometry::MakeSphere(kRadius, kSubdivisions), centre_W);
  for (const Eigen::Vector3d& eye_offset :
       {Eigen::Vector3d(0.5, 0.3, 0.2), Eigen::Vector3d(-0.2, -0.4, 0.4)}) {
    const PinholeCamera camera = MakeCamera(LookAt(centre_W + eye_offset, centre_W));
    const DepthImage image = renderer.Render(sphere, camera);
    const auto points_W = DepthToWorldPoints(image, camera);
    ASSERT_GT(points_W.size(), 1000u);
    double min_distance = 1e9, max_distance = 0.0;
    for (const Eigen::Vector3d& p_W : points_W) {
      const double distance = (p_W - centre_W).norm();
      min_distance = std::min(min_distance, distance);
      max_distance = std::max(max_distance, distance);
    }
    EXPECT_GE(min_distance, kRadius * (1.0 - 1e-3));
    EXPECT_LE(max_distance, kRadius * (1.0 + 1e-5));
  }
}

// Triangles are hit from both sides (open meshes, holes): a triangle facing away renders with the
// same depth as one facing the camera.
TEST(DepthRenderer, NoBackfaceCulling) {
  const DepthRenderer renderer;
  const PinholeCamera camera = MakeCamera(Eigen::Isometry3d::Identity());  // looks along +z
  geometry::TriangleMesh facing;
  facing.vertices = {{-1, -1, 2}, {1, -1, 2}, {0, 1, 2}};
  facing.triangles = {{0, 1, 2}};
  geometry::TriangleMesh away = facing;
  away.triangles = {{0, 2, 1}};
  const DepthImage a = renderer.Render(facing, camera);
  const DepthImage b = renderer.Render(away, camera);
  EXPECT_GT(a.NumValid(), 100);
  EXPECT_EQ(a.depth, b.depth);
  EXPECT_NEAR(a.at(60, 50), 2.0, 1e-6);
}

// An empty mesh renders as an image without data.
TEST(DepthRenderer, EmptyMeshRendersNothing) {
  const DepthRenderer renderer;
  const DepthImage image =
      renderer.Render(geometry::TriangleMesh{}, MakeCamera(Eigen::Isometry3d::Identity()));
  EXPECT_EQ(image.width, 121);
  EXPECT_EQ(image.NumValid(), 0);
}

// The depths of listed pixels through a distorted lens are the whole image's at those pixels,
// misses included; a pixel off the image is refused.
TEST(DepthRenderer, ListedPixelsSeeWhatTheImageShows) {
  const DepthRenderer renderer;
  const PinholeCamera camera = MakeCamera(
      LookAt(Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitZ()));
  const geometry::TriangleMesh sphere =
      Translated(geometry::MakeSphere(kRadius, 3), Eigen::Vector3d(kDistance, 0.02, 0.01));
  const Result<PixelRays> rays = ComputePixelRays(camera, {-0.2, 0.05, 0.001, -0.002, 0.0});
  ASSERT_TRUE(rays.ok()) << rays.status().ToString();
  const DepthImage image = renderer.Render(sphere, camera, *rays);
  std::vector<int> pixels;
  for (int p = 0; p < camera.width * camera.height; p += 7) pixels.push_back(p);
  const std::vector<float> listed = renderer.RenderPixels(sphere, camera, *rays, pixels);
  ASSERT_EQ(listed.size(), pixels.size());
  int hits = 0, misses = 0;
  for (size_t i = 0; i < pixels.size(); ++i) {
    EXPECT_EQ(listed[i], image.depth[pixels[i]]) << "pixel " << pixels[i];
    (listed[i] > 0.0f ? hits : misses) += 1;
  }
  EXPECT_GT(hits, 100);
  EXPECT_GT(misses, 100);
  EXPECT_TRUE(renderer.RenderPixels(sphere, camera, *rays, {}).empty());
  EXPECT_THROW(renderer.RenderPixels(sphere, camera, *rays, {camera.width * camera.height}),
               std::invalid_argument);
}

// A rigid mesh's scene, built once in its own frame, shows from any pose what a scene of the mesh
// moved there shows.
TEST(RigidMeshRenderer, SeesWhatTheMovedMeshShows) {
  const geometry::TriangleMesh box_S = geometry::MakeBox(Eigen::Vector3d(0.3, 0.2, 0.1), 0.05);
  const PinholeCamera camera = MakeCamera(Eigen::Isometry3d::Identity());
  const Result<PixelRays> rays = ComputePixelRays(camera, {-0.2, 0.05, 0.001, -0.002, 0.0});
  ASSERT_TRUE(rays.ok()) << rays.status().ToString();
  std::vector<int> pixels;
  for (int p = 0; p < camera.width * camera.height; p += 3) pixels.push_back(p);
  const RigidMeshRenderer rigid(box_S);
  const DepthRenderer renderer;
  for (const double turn : {0.0, 0.4, 1.3}) {
    Eigen::Isometry3d X_CS = Eigen::Isometry3d::Identity();
    X_CS.linear() = Eigen::AngleAxisd(turn, Eigen::Vector3d(1, 2, 0.5).normalized()).matrix();
    X_CS.translation() = Eigen::Vector3d(0.05, -0.02, 0.9);
    geometry::TriangleMesh box_C = box_S;
    for (Eigen::Vector3d& v : box_C.vertices) v = X_CS * v;
    const std::vector<float> expected = renderer.RenderPixels(box_C, camera, *rays, pixels);
    const std::vector<float> found = rigid.RenderPixels(X_CS, *rays, pixels);
    ASSERT_EQ(found.size(), pixels.size());
    int hits = 0;
    for (size_t i = 0; i < pixels.size(); ++i) {
      // A ray grazing an edge may hit in one frame and pass in the other (float rounding).
      if ((found[i] > 0.0f) != (expected[i] > 0.0f)) continue;
      EXPECT_NEAR(found[i], expected[i], 1e-5) << "turn " << turn << ", pixel " << pixels[i];
      hits += found[i] > 0.0f ? 1 : 0;
    }
    int disagreements = 0;
    for (size_t i = 0; i < pixels.size(); ++i)
      disagreements += (found[i] > 0.0f) != (expected[i] > 0.0f) ? 1 : 0;
    EXPECT_LE(disagreements, 3) << "turn " << turn;
    EXPECT_GT(hits, 200) << "turn " << turn;
  }
  EXPECT_THROW(rigid.RenderPixels(Eigen::Isometry3d::Identity(), *rays, {-1}),
               std::invalid_argument);
}

}  // namespace
}  // namespace softid::capture
