// Segmentation of raw depth frames: a ball flies past a floor, a wall and a static box, seen
// through a distorted lens with depth noise. The static scene comes from the frames themselves or
// from background frames; the ball's pixels are found against the true masks.
#include "core/ingest/foreground.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <random>

#include "core/ingest/static_scene.h"
#include "tests/core/ingest/raw_scene_util.h"

namespace softid::ingest {
namespace {

using capture::DepthImage;
using testing::MakeRawScene;
using testing::RawScene;

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
  StaticSceneOptions no_threads;
  no_threads.threads = -1;
  EXPECT_NE(EstimateStaticScene({DepthImage::Zeros(4, 3)}, no_threads)
                .status()
                .message()
                .find("threads = -1"),
            std::string::npos);
}

// The pixels are shared out among threads in bands of rows; the scene is the same whatever the
// count (and a band count that does not divide the height leaves no row out).
TEST(StaticScene, SameSceneOnOneThreadOrMany) {
  const RawScene s = MakeRawScene();
  StaticSceneOptions one, three;
  one.threads = 1;
  three.threads = 3;
  const Result<StaticScene> serial = EstimateStaticScene(s.frames, one);
  const Result<StaticScene> parallel = EstimateStaticScene(s.frames, three);
  ASSERT_TRUE(serial.ok() && parallel.ok());
  EXPECT_EQ(serial->depth_m, parallel->depth_m);
  EXPECT_EQ(serial->sigma_m, parallel->sigma_m);
  const int last_row = s.frames[0].height - 1;
  int known_in_last_row = 0;
  for (int col = 0; col < s.frames[0].width; ++col)
    known_in_last_row += parallel->depth(col, last_row) > 0.0f ? 1 : 0;
  EXPECT_GT(known_in_last_row, 0);
}

// A noise-free frame over a flat scene 2 m away with sigma 1 cm: margins 4 cm, 2 cm to join.
struct FlatScene {
  static constexpr int kWidth = 40, kHeight = 30;
  StaticScene scene;
  DepthImage frame = DepthImage::Zeros(kWidth, kHeight);
  capture::PixelRays rays;

  FlatScene() {
    scene.width = kWidth;
    scene.height = kHeight;
    scene.depth_m.assign(kWidth * kHeight, 2.0f);
    scene.sigma_m.assign(kWidth * kHeight, 0.01f);
    scene.maybe_object.assign(kWidth * kHeight, 0);
    frame.depth.assign(kWidth * kHeight, 2.0f);
    capture::PinholeCamera camera;
    camera.width = kWidth;
    camera.height = kHeight;
    camera.fx = camera.fy = 40.0;
    camera.cx = 19.5;
    camera.cy = 14.5;
    rays = capture::ComputePixelRays(camera, {}).value();
  }
  static int Pixel(int col, int row) { return row * kWidth + col; }
  void Fill(int col0, int col1, int row0, int row1, float depth) {
    for (int row = row0; row < row1; ++row) {
      for (int col = col0; col < col1; ++col) frame.depth[Pixel(col, row)] = depth;
    }
  }
  // The static scene there is at `depth` and may be the object (it rests there in every frame).
  void MarkSceneAsObject(int col0, int col1, int row0, int row1, float depth) {
    for (int row = row0; row < row1; ++row) {
      for (int col = col0; col < col1; ++col) {
        scene.depth_m[Pixel(col, row)] = depth;
        scene.maybe_object[Pixel(col, row)] = 1;
      }
    }
  }
};

// Pixels the scene marks maybe_object (the object may rest on them in every frame) join the
// object's region where its depth continues into them, and make no region alone (clutter behind
// the released object stays out).
TEST(Foreground, MaybeObjectPixelsJoinAContinuingRegionOnly) {
  FlatScene s;
  // The object: columns 5..14 nearer than the scene; columns 15..19 the object too, but the scene
  // there is the object itself (depth 1.5, as seen), marked maybe_object.
  s.Fill(5, 20, 10, 20, 1.5f);
  s.MarkSceneAsObject(15, 20, 10, 20, 1.5f);
  // Clutter at 1.0 m, its scene the clutter itself and marked maybe_object, apart from the object.
  s.Fill(28, 36, 10, 20, 1.0f);
  s.MarkSceneAsObject(28, 36, 10, 20, 1.0f);
  const Result<Foreground> fg = SegmentForeground(s.frame, s.scene, s.rays);
  ASSERT_TRUE(fg.ok()) << fg.status().ToString();
  ASSERT_EQ(fg->regions.size(), 1u);
  EXPECT_EQ(fg->regions[0].pixels.size(), 10u * 15u);
  EXPECT_EQ(fg->mask[FlatScene::Pixel(17, 15)], 1);
  EXPECT_EQ(fg->mask[FlatScene::Pixel(30, 15)], 0);
}

// Hysteresis: where an object meets the floor its pixels stand only a little in front of it; they
// join the region of surely nearer pixels they continue, but a patch of them alone is no region,
// and they never bridge groups of nearer pixels too small to count into one.
TEST(Foreground, PixelsALittleNearerJoinASureRegionOnly) {
  FlatScene s;
  s.Fill(5, 15, 5, 15, 1.9f);    // the object, 10 cm in front: sure
  s.Fill(5, 15, 15, 18, 1.97f);  // its base, 3 cm in front: joins
  s.Fill(25, 32, 5, 12, 1.97f);  // a patch 3 cm in front alone
  s.Fill(25, 28, 20, 22, 1.9f);  // two groups of 6 sure pixels (fewer than 12) ...
  s.Fill(30, 33, 20, 22, 1.9f);
  s.Fill(28, 30, 20, 22, 1.97f);  // ... linked by pixels that only join
  const Result<Foreground> fg = SegmentForeground(s.frame, s.scene, s.rays);
  ASSERT_TRUE(fg.ok()) << fg.status().ToString();
  ASSERT_EQ(fg->regions.size(), 1u);
  EXPECT_EQ(fg->regions[0].pixels.size(), 10u * 13u);
  EXPECT_EQ(fg->mask[FlatScene::Pixel(10, 16)], 1);
  EXPECT_EQ(fg->mask[FlatScene::Pixel(28, 8)], 0);
  EXPECT_EQ(fg->mask[FlatScene::Pixel(26, 20)], 0);
}

// A pixel inside a region whose reading noise took behind the margin, but whose depth continues
// its neighbours', is the object; one on the region's edge, or in a hole wider than a pixel, is
// not.
TEST(Foreground, EnclosedPixelsJoinTheirRegion) {
  FlatScene s;
  s.Fill(5, 20, 5, 20, 1.97f);                      // an object 3 cm in front: joins ...
  s.Fill(8, 12, 8, 12, 1.9f);                       // ... around a sure core
  s.frame.depth[FlatScene::Pixel(15, 15)] = 1.99f;  // enclosed, 1 cm in front
  s.frame.depth[FlatScene::Pixel(19, 12)] = 1.99f;  // on the edge
  s.Fill(14, 17, 7, 10, 2.0f);                      // a hole of 3 x 3 pixels through the object
  const Result<Foreground> fg = SegmentForeground(s.frame, s.scene, s.rays);
  ASSERT_TRUE(fg.ok()) << fg.status().ToString();
  ASSERT_EQ(fg->regions.size(), 1u);
  EXPECT_EQ(fg->mask[FlatScene::Pixel(15, 15)], 1);
  EXPECT_EQ(fg->mask[FlatScene::Pixel(19, 12)], 0);
  for (int row = 7; row < 10; ++row) {
    for (int col = 14; col < 17; ++col) EXPECT_EQ(fg->mask[FlatScene::Pixel(col, row)], 0);
  }
  EXPECT_EQ(fg->regions[0].pixels.size(), 15u * 15u - 1u - 9u);
}

TEST(Foreground, RejectsBadOptions) {
  FlatScene s;
  ForegroundOptions options;
  options.join_noise_sigmas = 5.0;  // above noise_sigmas
  Result<Foreground> fg = SegmentForeground(s.frame, s.scene, s.rays, options);
  ASSERT_FALSE(fg.ok());
  EXPECT_NE(fg.status().message().find("join_noise_sigmas = 5"), std::string::npos);
  options = {};
  options.min_enclosing_neighbours = 9;
  fg = SegmentForeground(s.frame, s.scene, s.rays, options);
  ASSERT_FALSE(fg.ok());
  EXPECT_NE(fg.status().message().find("min_enclosing_neighbours = 9"), std::string::npos);
}

}  // namespace
}  // namespace softid::ingest
