// A fit of a chaotic motion compares only the frames the model predicts: an undamped block rocking
// on a floor, whose late frames no time step makes converge, is fitted up to where halving the
// step still converges, and says so; asked to, it fits every frame.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>

#include "core/capture/capture.h"
#include "core/inverse/fit.h"
#include "core/inverse/fit_uncertainty.h"
#include "core/inverse/time_step_selection.h"
#include "core/scenes/scene.h"
#include "core/scenes/synthesize.h"
#include "tests/core/inverse/tilted_block_drop.h"

namespace softid::inverse {
namespace {

constexpr int kLastFrame = 47;  // 0.8 s at 60 fps

// The tilted block's drop seen by two 40 x 40 cameras, noise-free, simulated on 8 cells at 16
// substeps; removed with the fixture.
class PredictableFramesTest : public ::testing::Test {
 protected:
  void SetUp() override {
    Result<scenes::Scene> scene = scenes::MakeBuiltinScene("ball-bounce");
    ASSERT_TRUE(scene.ok());
    scene->mesh = testing::TiltedBlock();
    scene->parameters = testing::UndampedBlockOnAFloor();
    scene->view_target = Eigen::Vector3d(0.0, 0.0, 0.05);
    scene->view_radius = 0.25;
    directory_ = std::filesystem::temp_directory_path() /
                 ("softid_predictable_frames_" + std::to_string(::getpid()));
    std::filesystem::remove_all(directory_);
    scenes::SynthesisOptions options;
    options.run.duration = (kLastFrame + 0.5) / 60.0;
    options.run.substeps_per_frame = 16;
    options.run.simulation.cells_along_longest_side = 8;
    options.cameras.count = 2;
    options.cameras.width = 40;
    options.cameras.height = 40;
    ASSERT_TRUE(scenes::Synthesize(*scene, options, directory_).ok());
    Result<capture::Capture> capture = capture::ReadCapture(directory_);
    ASSERT_TRUE(capture.ok()) << capture.status().ToString();
    capture_ = *capture;
    truth_ = scene->parameters;
  }
  void TearDown() override {
    std::error_code ignored;
    std::filesystem::remove_all(directory_, ignored);
  }

  // Young's modulus from 1.3 x the truth, the rest fixed; "substeps": "auto".
  JobConfig Config() const {
    JobConfig config;
    config.fit = {"youngs_modulus"};
    config.initial["youngs_modulus"].value = 1.3 * truth_.youngs_modulus;
    config.fixed = fem::ToJson(truth_);
    config.fixed.erase("youngs_modulus");
    config.fixed.erase("density");  // from the capture's mass
    config.solver.cells = 8;
    config.solver.substeps = kAutoSubsteps;
    config.solver.starts = 1;
    config.solver.max_iterations = 2;
    return config;
  }

  std::filesystem::path directory_;
  capture::Capture capture_;
  fem::PhysicalParameters truth_;
};

// Observed points in frames 0..last.
double PointsUpTo(const capture::Capture& capture, int last) {
  const Result<std::vector<ObservedFrame>> frames = LoadObservedFrames(capture, 0, last);
  double points = 0.0;
  if (frames.ok()) {
    for (const ObservedFrame& frame : *frames) points += static_cast<double>(frame.points.size());
  }
  return points;
}

TEST_F(PredictableFramesTest, TheFitLeavesOutTheFramesNoStepPredicts) {
  const JobConfig config = Config();
  const Result<FitResult> fit = Fit(capture_, config);
  ASSERT_TRUE(fit.ok()) << fit.status().ToString();
  ASSERT_TRUE(fit->substep_selection.has_value());
  const SubstepSelection& selection = *fit->substep_selection;
  EXPECT_FALSE(selection.converging);
  const SubstepTrial& last = selection.trials.back();
  std::printf("%d substeps; within tolerance on %d frames, converging on %d; fitted to frame %d\n",
              fit->substeps, last.frames_within_tolerance, last.frames_converging,
              fit->predictable_last_frame);
  // The landing converges with the step, the rocking does not: the fit stops in between.
  EXPECT_EQ(fit->predictable_last_frame, last.frames_converging - 1);
  EXPECT_GE(fit->predictable_last_frame, last.frames_within_tolerance + 2);
  EXPECT_LT(fit->predictable_last_frame, kLastFrame);
  for (const HorizonStageResult& stage : fit->Best().stages) {
    EXPECT_LE(stage.last_frame, fit->predictable_last_frame);
  }
  EXPECT_EQ(ToJson(*fit).at("time_step").at("predictable_last_frame").get<int>(),
            fit->predictable_last_frame);
  // The analyses after the fit compare the same frames, at the same step.
  EXPECT_EQ(WithFitDiscretisation(config, *fit).frames.last, fit->predictable_last_frame);
  EXPECT_EQ(WithFitDiscretisation(config, *fit).solver.substeps, fit->substeps);
  const Result<FitUncertainty> uncertainty = EstimateFitUncertainty(capture_, config, *fit);
  ASSERT_TRUE(uncertainty.ok()) << uncertainty.status().ToString();
  EXPECT_EQ(uncertainty->report.num_effective_samples,
            PointsUpTo(capture_, fit->predictable_last_frame));
  EXPECT_LT(uncertainty->report.num_effective_samples, PointsUpTo(capture_, kLastFrame));
  // The check alone (what the diagnosis runs before comparing at a fixed step) finds the same.
  JobConfig fixed_step = config;
  fixed_step.solver.substeps = 4;
  const Result<TimeStepCheck> check = CheckTimeStep(capture_, fixed_step);
  ASSERT_TRUE(check.ok()) << check.status().ToString();
  EXPECT_EQ(check->predictable_last_frame, fit->predictable_last_frame);
  EXPECT_EQ(check->selection.substeps, fit->substeps);

  JobConfig every_frame = config;
  every_frame.solver.predictable_frames_only = false;
  const Result<FitResult> all = Fit(capture_, every_frame);
  ASSERT_TRUE(all.ok()) << all.status().ToString();
  EXPECT_EQ(all->predictable_last_frame, -1);
  EXPECT_FALSE(ToJson(*all).at("time_step").contains("predictable_last_frame"));
  EXPECT_EQ(all->Best().stages.back().last_frame, kLastFrame);
  EXPECT_EQ(WithFitDiscretisation(every_frame, *all).frames.last, every_frame.frames.last);
}

// Where every frame converges or meets the tolerance, or not even the first impact converges,
// every frame is kept.
TEST(PredictableLastFrame, OnlyWhereTheImpactConvergesAndTheRestDoesNot) {
  SubstepSelection selection;
  selection.converging = false;
  selection.trials.resize(2);
  selection.trials.back().frames_within_tolerance = 7;
  selection.trials.back().frames_converging = 18;
  EXPECT_EQ(PredictableLastFrame(selection, 48), 17);
  selection.trials.back().frames_converging = 9;  // 2 frames past the tolerance: too few
  EXPECT_EQ(PredictableLastFrame(selection, 48), -1);
  selection.trials.back().frames_converging = 49;  // every frame converges
  EXPECT_EQ(PredictableLastFrame(selection, 48), -1);
  selection.trials.back().frames_converging = 18;
  // The largest difference shrank, but by chance in the frames that do not converge.
  selection.converging = true;
  EXPECT_EQ(PredictableLastFrame(selection, 48), 17);
  selection.within_tolerance = true;
  EXPECT_EQ(PredictableLastFrame(selection, 48), -1);
  selection.within_tolerance = false;
  selection.trials.resize(1);
  EXPECT_EQ(PredictableLastFrame(selection, 48), -1);
}

}  // namespace
}  // namespace softid::inverse
