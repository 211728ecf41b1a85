// Segmentation of raw depth frames: a ball flies past a floor, a wall and a static box, seen
// through a distorted lens with depth noise. The static scene comes from the frames themselves or
// from background frames; the ball's pixels are found against the true masks.
#include "core/ingest/foreground.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <random>

#include "core/capture/depth_renderer.h"
#include "core/geometry/primitives.h"
#include "core/ingest/static_scene.h"

namespace softid::ingest {
namespace {

using capture::DepthImage;

geometry::TriangleMesh Moved(geometry::TriangleMesh mesh, const Eigen::Vector3d& offset) {
  for (Eigen::Vector3d& v : mesh.vertices) v += offset;
  return mesh;
}

geometry::TriangleMesh Merged(const std::vector<geometry::TriangleMesh>& parts) {
  geometry::TriangleMesh out;
  for (const geometry::TriangleMesh& part : parts) {
    const int base = static_cast<int>(out.vertices.size());
    out.vertices.insert(out.vertices.end(), part.vertices.begin(), part.vertices.end());
    for (const Eigen::Vector3i& t : part.triangles)
      out.triangles.push_back(t + Eigen::Vector3i::Constant(base));
  }
  return out;
}

struct RawScene {
  capture::PinholeCamera camera;
  capture::PixelRays rays;
  std::vector<DepthImage> frames, background;
  std::vector<std::vector<uint8_t>> true_masks;
};

// 40 frames of a 6 cm ball arcing over the floor in front of a wall, beside a static 10 cm box;
// depth noise 1.5 mm + 0.2 % of depth, stored in 1 mm units (a 16-bit PNG's quantum).
RawScene MakeRawScene() {
  RawScene s;
  s.camera.name = "cam0";
  s.camera.width = 160;
  s.camera.height = 120;
  s.camera.fx = s.camera.fy = 140.0;
  s.camera.cx = 79.5;
  s.camera.cy = 59.5;
  s.camera.X_WC = capture::LookAt(Eigen::Vector3d(0.0, -1.2, 0.7), Eigen::Vector3d(0.0, 0.0, 0.15));
  s.rays = *capture::ComputePixelRays(s.camera, {-0.12, 0.03, 0.0005, -0.0003, 0.0});
  const geometry::TriangleMesh floor =
      Moved(geometry::MakeBox(Eigen::Vector3d(3.0, 3.0, 0.1), 0.5), Eigen::Vector3d(0, 0, -0.05));
  const geometry::TriangleMesh wall =
      Moved(geometry::MakeBox(Eigen::Vector3d(3.0, 0.1, 2.0), 0.5), Eigen::Vector3d(0, 0.8, 1.0));
  const geometry::TriangleMesh box = Moved(geometry::MakeBox(Eigen::Vector3d(0.1, 0.1, 0.1), 0.05),
                                           Eigen::Vector3d(0.3, 0.1, 0.05));
  const geometry::TriangleMesh statics = Merged({floor, wall, box});
  const geometry::TriangleMesh ball = geometry::MakeSphere(0.06, 3);
  const capture::DepthRenderer renderer;
  std::mt19937 rng(5);
  std::normal_distribution<float> unit(0.0f, 1.0f);
  auto noisy = [&](DepthImage image) {
    for (float& z : image.depth) {
      if (z > 0.0f) z = std::round((z + (0.0015f + 0.002f * z) * unit(rng)) * 1000.0f) / 1000.0f;
    }
    return image;
  };
  for (int k = 0; k < 40; ++k) {
    const double t = k / 30.0;
    const Eigen::Vector3d centre(-0.5 + 0.7 * t, -0.1, 0.5 + 1.0 * t - 4.9 * t * t);
    const geometry::TriangleMesh ball_k =
        Moved(ball, Eigen::Vector3d(centre.x(), centre.y(), std::max(0.06, centre.z())));
    const DepthImage only_ball = renderer.Render(ball_k, s.camera, s.rays);
    const DepthImage only_scene = renderer.Render(statics, s.camera, s.rays);
    std::vector<uint8_t> mask(only_ball.depth.size(), 0);
    for (size_t p = 0; p < mask.size(); ++p) {
      const float b = only_ball.depth[p], z = only_scene.depth[p];
      mask[p] = b > 0.0f && (z == 0.0f || b < z);
    }
    s.true_masks.push_back(std::move(mask));
    s.frames.push_back(noisy(renderer.Render(Merged({statics, ball_k}), s.camera, s.rays)));
    if (k < 8) s.background.push_back(noisy(only_scene));
  }
  return s;
}

double IoU(const std::vector<uint8_t>& a, const std::vector<uint8_t>& b) {
  int both = 0, either = 0;
  for (size_t p = 0; p < a.size(); ++p) {
    both += a[p] && b[p];
    either += a[p] || b[p];
  }
  return either == 0 ? 1.0 : static_cast<double>(both) / either;
}

void ExpectBallFound(const RawScene& s, const StaticScene& scene) {
  double worst = 1.0;
  for (size_t k = 0; k < s.frames.size(); ++k) {
    const Result<Foreground> fg = SegmentForeground(s.frames[k], scene, s.rays);
    ASSERT_TRUE(fg.ok()) << fg.status().ToString();
    int truth = 0;
    for (uint8_t m : s.true_masks[k]) truth += m;
    ASSERT_GT(truth, 30) << "frame " << k;
    // The ball's lowest pixels touch the floor within the noise margin when it lands.
    const double iou = IoU(fg->mask, s.true_masks[k]);
    worst = std::min(worst, iou);
    EXPECT_GE(iou, 0.97) << "frame " << k;
    ASSERT_FALSE(fg->regions.empty());
    EXPECT_GE(fg->regions.front().pixels.size(), 0.9 * truth) << "frame " << k;
  }
  std::printf("worst mask IoU over %zu frames: %.4f\n", s.frames.size(), worst);
}

TEST(Foreground, BallFoundAgainstTheStaticSceneOfTheFramesThemselves) {
  const RawScene s = MakeRawScene();
  const Result<StaticScene> scene = EstimateStaticScene(s.frames);
  ASSERT_TRUE(scene.ok()) << scene.status().ToString();
  ExpectBallFound(s, *scene);
}

TEST(Foreground, BallFoundAgainstBackgroundFrames) {
  const RawScene s = MakeRawScene();
  const Result<StaticScene> scene = EstimateStaticScene(s.background);
  ASSERT_TRUE(scene.ok()) << scene.status().ToString();
  ExpectBallFound(s, *scene);
}

// The static box, the wall and the floor never count as foreground, and the noise estimate
// follows the sensor's: about 1.5 mm + 0.2 % of depth.
TEST(StaticScene, StaticPixelsAreSceneWithTheirNoise) {
  const RawScene s = MakeRawScene();
  const Result<StaticScene> scene = EstimateStaticScene(s.frames);
  ASSERT_TRUE(scene.ok());
  std::vector<float> sigmas;
  int never_ball = 0, known = 0;
  for (size_t p = 0; p < s.true_masks[0].size(); ++p) {
    bool ball = false;
    for (const auto& mask : s.true_masks) ball = ball || mask[p];
    if (ball) continue;
    ++never_ball;
    if (scene->depth_m[p] > 0.0f) {
      ++known;
      sigmas.push_back(scene->sigma_m[p] / (0.0015f + 0.002f * scene->depth_m[p]));
    }
  }
  EXPECT_GT(known, 0.99 * never_ball);
  std::nth_element(sigmas.begin(), sigmas.begin() + sigmas.size() / 2, sigmas.end());
  EXPECT_NEAR(sigmas[sigmas.size() / 2], 1.0, 0.25);
}

TEST(StaticScene, RejectsEmptyOrMismatchedInput) {
  EXPECT_FALSE(EstimateStaticScene({}).ok());
  const Result<StaticScene> mixed =
      EstimateStaticScene({DepthImage::Zeros(4, 3), DepthImage::Zeros(4, 4)});
  ASSERT_FALSE(mixed.ok());
  EXPECT_NE(mixed.status().message().find("image 1 is 4x4"), std::string::npos);
  StaticSceneOptions bad;
  bad.cluster_width_m = -1;
  EXPECT_NE(EstimateStaticScene({DepthImage::Zeros(4, 3)}, bad)
                .status()
                .message()
                .find("cluster_width_m = -1"),
            std::string::npos);
}

}  // namespace
}  // namespace softid::ingest
