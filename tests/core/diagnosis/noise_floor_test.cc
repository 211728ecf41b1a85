#include "core/diagnosis/noise_floor.h"

#include <gtest/gtest.h>

#include <random>

#include "core/diagnosis/localization.h"
#include "core/diagnosis/time_step_error.h"

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

// Halving the step moves the residuals of frames 10-19 by 2 mm: the error of the compared step is
// twice that (first order), there and nowhere else, and on both patches.
TEST(TimeStepError, RichardsonOnTheResidualChange) {
  const ResidualMap compared = Synthetic(std::vector<double>(30, 0.003));
  ResidualMap finer = compared;
  for (int k = 10; k < 20; ++k)
    for (float& phi : finer.frames[k].phi) phi += 0.002f;
  const TimeStepError e = EstimateTimeStepError(compared, finer, nullptr, 4, 8);
  ASSERT_EQ(e.frame_m.size(), 30u);
  EXPECT_NEAR(e.frame_m[5], 0.0, 1e-9);
  EXPECT_NEAR(e.frame_m[15], 0.004, 1e-6);
  ASSERT_EQ(e.patch_m.size(), 2u);
  EXPECT_NEAR(e.patch_m[0], 0.004 * std::sqrt(10.0 / 30.0), 1e-6);
  EXPECT_NEAR(e.patch_m[1], e.patch_m[0], 1e-9);
  EXPECT_NEAR(e.unabsorbed_m, e.change_m, 1e-12);

  // A base parameter that shifts frames 10-29 alike absorbs half of the change (delta = 0.5: 1 mm
  // left on frames 10-19, -1 mm made on frames 20-29); one that moves frames 0-9 only absorbs
  // none of it.
  Sensitivities shift;
  shift.step = 0.5;
  shift.at = compared;
  shift.moved.push_back(compared);
  for (int k = 10; k < 30; ++k)
    for (float& phi : shift.moved[0].frames[k].phi) phi += 0.001f;
  const TimeStepError absorbed = EstimateTimeStepError(compared, finer, &shift, 4, 8);
  EXPECT_NEAR(absorbed.change_m, 0.002 * std::sqrt(10.0 / 30.0), 1e-7);
  EXPECT_NEAR(absorbed.unabsorbed_m, 0.001 * std::sqrt(20.0 / 30.0), 1e-7);
  EXPECT_NEAR(absorbed.frame_m[15], 0.002, 1e-6);
  EXPECT_NEAR(absorbed.frame_m[25], 0.002, 1e-6);
  Sensitivities elsewhere = shift;
  elsewhere.moved[0] = compared;
  for (int k = 0; k < 10; ++k)
    for (float& phi : elsewhere.moved[0].frames[k].phi) phi += 0.001f;
  const TimeStepError kept = EstimateTimeStepError(compared, finer, &elsewhere, 4, 8);
  EXPECT_NEAR(kept.frame_m[15], e.frame_m[15], 1e-6);
}

// A base misfit along the compared step's error is left out of the frame's misfit; a misfit of
// another pattern (here the same size, but uncorrelated with it) stays.
TEST(TimeStepError, TheStepsComponentIsLeftOutOfTheMisfit) {
  std::vector<double> sigmas(30, 0.003);
  ResidualMap map = Synthetic(sigmas);
  TimeStepError step;
  step.point_m.resize(30);
  std::mt19937_64 rng(11);
  std::normal_distribution<double> normal;
  for (int k = 0; k < 30; ++k) {
    FrameResiduals& f = map.frames[k];
    step.point_m[k].resize(f.phi.size());
    for (size_t i = 0; i < f.phi.size(); ++i) {
      step.point_m[k][i] = k >= 10 && k < 20 ? static_cast<float>(0.01 * normal(rng)) : 0.0f;
      if (k >= 10 && k < 20) f.phi[i] += 0.8f * step.point_m[k][i];      // the step's error
      if (k >= 20) f.phi[i] += static_cast<float>(0.008 * normal(rng));  // something else
    }
    double sum = 0.0;
    for (float phi : f.phi) sum += 0.5 * phi * phi;
    f.cost = sum / f.phi.size();
    f.misfit = std::sqrt(2.0 * f.cost);
  }
  std::vector<double> share;
  const ResidualMap left = WithoutTimeStepComponent(map, step, &share);
  EXPECT_GT(map.frames[15].misfit, 0.0075);
  EXPECT_NEAR(left.frames[15].misfit, 0.003, 0.0005);
  EXPECT_GT(share[15], 0.8);
  EXPECT_DOUBLE_EQ(left.frames[5].misfit, map.frames[5].misfit);
  EXPECT_DOUBLE_EQ(left.frames[25].misfit, map.frames[25].misfit);  // no step error there
  std::vector<FrameMotion> motion(30);
  for (int k = 0; k < 30; ++k) {
    motion[k].frame = k;
    motion[k].phase = k < 10 ? Phase::kFlight : (k < 20 ? Phase::kImpact : Phase::kRest);
  }
  const Localization l = Locate(left, motion, 0.003, 1.5);
  EXPECT_EQ(l.FlaggedPhaseNames(), std::vector<std::string>{"rest"});
  EXPECT_EQ(Locate(map, motion, 0.003, 1.5).FlaggedPhaseNames(),
            (std::vector<std::string>{"impact", "rest"}));
}

// Where the estimated step error is round-off (1e-11 m) but happens to lie along a real misfit
// (here exactly parallel: the worst case), it takes at most its bounded amplitude with it, not
// the misfit: air drag's slow lag stays in the frames the finer step barely changes.
TEST(TimeStepError, ARoundOffErrorDoesNotTakeARealMisfit) {
  ResidualMap map = Synthetic({0.003, 0.003});
  TimeStepError step;
  step.point_m.resize(2);
  for (int k = 0; k < 2; ++k) {
    FrameResiduals& f = map.frames[k];
    double sum = 0.0;
    for (size_t i = 0; i < f.phi.size(); ++i) {
      const double pattern = i % 3 == 0 ? 1.0 : -0.5;
      f.phi[i] += static_cast<float>(0.006 * pattern);                 // the real effect's misfit
      step.point_m[k].push_back(static_cast<float>(1e-11 * pattern));  // round-off along it
      sum += 0.5 * f.phi[i] * f.phi[i];
    }
    f.cost = sum / f.phi.size();
    f.misfit = std::sqrt(2.0 * f.cost);
  }
  step.point_m[1].assign(step.point_m[1].size(), 0.0f);
  std::vector<double> share;
  const ResidualMap left = WithoutTimeStepComponent(map, step, &share);
  EXPECT_LT(share[0], 1e-6);
  EXPECT_NEAR(left.frames[0].misfit, map.frames[0].misfit, 1e-6 * map.frames[0].misfit);
  EXPECT_DOUBLE_EQ(left.frames[1].misfit, map.frames[1].misfit);
  for (size_t i = 0; i < map.frames[0].phi.size(); ++i)
    EXPECT_NEAR(left.frames[0].phi[i], map.frames[0].phi[i], 1e-9);
}

}  // namespace
}  // namespace softid::diagnosis
