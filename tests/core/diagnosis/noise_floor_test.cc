#include "core/diagnosis/noise_floor.h"

#include <gtest/gtest.h>

#include <random>

#include "core/diagnosis/localization.h"

namespace softid::diagnosis {
namespace {

// A residual map of `frames` frames whose points are Gaussian with the given sigma per frame.
ResidualMap Synthetic(const std::vector<double>& sigmas, int points = 400) {
  ResidualMap map;
  map.truncation = 0.05;
  map.patches.centres = {Eigen::Vector3d(-1, 0, 0), Eigen::Vector3d(1, 0, 0)};
  map.patches.labels = {"-x side", "+x side"};
  std::mt19937_64 rng(3);
  std::normal_distribution<double> normal;
  for (size_t k = 0; k < sigmas.size(); ++k) {
    FrameResiduals f;
    f.frame = static_cast<int>(k);
    double sum = 0.0;
    for (int i = 0; i < points; ++i) {
      const double phi = sigmas[k] * normal(rng);
      f.phi.push_back(static_cast<float>(phi));
      f.patch.push_back(i % 2);
      f.matched.push_back(1);
      sum += 0.5 * phi * phi;
    }
    f.cost = sum / points;
    f.misfit = std::sqrt(2.0 * f.cost);
    map.frames.push_back(f);
  }
  return map;
}

// With a third of the frames clean, the floor is the noise, whichever estimate gives it.
TEST(NoiseFloor, NoiseLevelWhenAThirdIsClean) {
  std::vector<double> sigmas(30, 0.003);
  for (int k = 10; k < 30; ++k) sigmas[k] = 0.009;  // a mismatch from frame 10 on
  Result<NoiseFloor> floor = EstimateNoiseFloor(Synthetic(sigmas));
  ASSERT_TRUE(floor.ok()) << floor.status().ToString();
  EXPECT_NEAR(floor->sigma, 0.003, 0.0003);
  EXPECT_FALSE(floor->frame0_excess);
}

// When the mismatch spoils nearly every moving frame, the quantile is inflated and frame 0 (no
// physics in it) still gives the noise.
TEST(NoiseFloor, FrameZeroWhenMostFramesMisfit) {
  std::vector<double> sigmas(30, 0.009);
  sigmas[0] = 0.003;
  sigmas[1] = 0.003;
  Result<NoiseFloor> floor = EstimateNoiseFloor(Synthetic(sigmas));
  ASSERT_TRUE(floor.ok()) << floor.status().ToString();
  EXPECT_EQ(floor->method, "frame0");
  EXPECT_NEAR(floor->sigma, 0.003, 0.0003);
  EXPECT_GT(floor->quantile_misfit, 0.008);
}

// A frame 0 worse than the moving frames (a mis-posed camera, a time offset) is not the floor and
// is flagged.
TEST(NoiseFloor, InflatedFrameZeroFallsBackToQuantile) {
  std::vector<double> sigmas(30, 0.003);
  sigmas[0] = 0.01;
  Result<NoiseFloor> floor = EstimateNoiseFloor(Synthetic(sigmas));
  ASSERT_TRUE(floor.ok());
  EXPECT_EQ(floor->method, "quantile");
  EXPECT_NEAR(floor->sigma, 0.003, 0.0003);
  EXPECT_TRUE(floor->frame0_excess);
}

TEST(NoiseFloor, Errors) {
  EXPECT_EQ(EstimateNoiseFloor(ResidualMap()).status().code(), StatusCode::kFailedPrecondition);
  NoiseFloorOptions options;
  options.quantile = 1.5;
  EXPECT_NE(EstimateNoiseFloor(Synthetic({0.003}), options)
                .status()
                .message()
                .find("noise_floor.quantile = 1.5"),
            std::string::npos);
}

// The misfit is flagged where it is (frames 10.., the sliding phase) and nowhere else; the onset
// is frame 10.
TEST(Localization, FlagsThePhaseAndOnsetOfAMismatch) {
  std::vector<double> sigmas(30, 0.003);
  for (int k = 10; k < 30; ++k) sigmas[k] = 0.009;
  const ResidualMap map = Synthetic(sigmas);
  std::vector<FrameMotion> motion(30);
  for (int k = 0; k < 30; ++k) {
    motion[k].frame = k;
    motion[k].phase = k < 10 ? Phase::kFlight : Phase::kSliding;
  }
  const Localization l = Locate(map, motion, 0.003, 1.5);
  EXPECT_TRUE(l.flagged);
  EXPECT_EQ(l.onset_frame, 10);
  ASSERT_EQ(l.FlaggedPhaseNames(), std::vector<std::string>{"sliding"});
  EXPECT_GE(l.worst_frame, 10);
  // Same noise everywhere: nothing flagged.
  const Localization clean = Locate(Synthetic(std::vector<double>(30, 0.003)), motion, 0.003, 1.5);
  EXPECT_FALSE(clean.flagged);
  EXPECT_EQ(clean.onset_frame, -1);
}

}  // namespace
}  // namespace softid::diagnosis
