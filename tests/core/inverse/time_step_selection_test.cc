#include "core/inverse/time_step_selection.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>

#include "core/geometry/primitives.h"
#include "core/scenes/scene.h"
#include "tests/core/inverse/tilted_block_drop.h"

namespace softid::inverse {
namespace {

fem::SimulationOptions CoarseGrid() {
  fem::SimulationOptions options;
  options.cells_along_longest_side = 8;
  return options;
}

// A soft ball thrown onto the floor: the impact is what a coarse step gets wrong.
TEST(SelectSubsteps, StepDoublingDifferencesShrinkAndTheChoiceMeetsTheTolerance) {
  const Result<scenes::Scene> scene = scenes::MakeBuiltinScene("ball-bounce");
  ASSERT_TRUE(scene.ok());
  SubstepSelectionOptions options;
  options.min_substeps = 1;
  options.max_substeps = 8;
  options.tolerance_fraction = 1e-9;  // unreachable: every candidate is tried
  const Result<SubstepSelection> all = SelectSubsteps(
      scene->mesh, scene->fixed_region, scene->parameters, CoarseGrid(), 60.0, 30, options);
  ASSERT_TRUE(all.ok()) << all.status().ToString();
  ASSERT_EQ(all->trials.size(), 3u);  // 1 vs 2, 2 vs 4, 4 vs 8
  EXPECT_FALSE(all->within_tolerance);
  EXPECT_EQ(all->substeps, 8);
  for (size_t i = 0; i < all->trials.size(); ++i) {
    EXPECT_FALSE(all->trials[i].diverged);
    EXPECT_GT(all->trials[i].difference_m, 0.0);
    EXPECT_GT(all->trials[i].worst_frame, 0);
  }
  // The time discretisation error converges: each halving of the step at least halves it.
  EXPECT_LT(all->trials[1].difference_m, 0.5 * all->trials[0].difference_m);
  EXPECT_LT(all->trials[2].difference_m, 0.5 * all->trials[1].difference_m);
  EXPECT_TRUE(all->converging);
  // In free fall before the bounce every step agrees; the bounce is where they part.
  for (const SubstepTrial& trial : all->trials) {
    EXPECT_GT(trial.frames_within_tolerance, 0);
    EXPECT_LE(trial.frames_within_tolerance, trial.worst_frame);
  }

  // A tolerance between the second and third differences selects 4 substeps, after two trials.
  const double length = scene->mesh.Bounds().sizes().maxCoeff();
  options.tolerance_fraction =
      0.5 * (all->trials[1].difference_m + all->trials[2].difference_m) / length;
  const Result<SubstepSelection> chosen = SelectSubsteps(
      scene->mesh, scene->fixed_region, scene->parameters, CoarseGrid(), 60.0, 30, options);
  ASSERT_TRUE(chosen.ok());
  EXPECT_TRUE(chosen->within_tolerance);
  EXPECT_EQ(chosen->substeps, 4);
  ASSERT_EQ(chosen->trials.size(), 3u);
  EXPECT_LE(chosen->trials.back().difference_m, chosen->tolerance_m);
  EXPECT_GT(chosen->trials[1].difference_m, chosen->tolerance_m);
  EXPECT_EQ(chosen->trials.back().frames_within_tolerance, 31);  // frames 0-30
  EXPECT_LT(chosen->trials[1].frames_within_tolerance, 31);
  const nlohmann::json json = ToJson(*chosen);
  EXPECT_TRUE(json.at("converging").get<bool>());
  EXPECT_EQ(json.at("trials").back().at("frames_within_tolerance").get<int>(), 31);
}

// A block dropped tilted onto a frictionless floor with no damping rocks from corner to corner:
// a chaotic motion, in which the runs at s and 2 s substeps part after the first impacts whatever
// s is. The selection says so instead of blaming the step.
TEST(SelectSubsteps, ChaoticRockingIsToldFromAStepError) {
  const geometry::TriangleMesh block = testing::TiltedBlock();
  const fem::PhysicalParameters parameters = testing::UndampedBlockOnAFloor();
  SubstepSelectionOptions options;
  options.min_substeps = 8;
  options.max_substeps = 32;
  const Result<SubstepSelection> selection =
      SelectSubsteps(block, std::nullopt, parameters, CoarseGrid(), 60.0, 47, options);
  ASSERT_TRUE(selection.ok()) << selection.status().ToString();
  ASSERT_EQ(selection->trials.size(), 2u);
  EXPECT_FALSE(selection->within_tolerance);
  EXPECT_FALSE(selection->converging)
      << selection->trials[0].difference_m << " then " << selection->trials[1].difference_m;
  // Before the first impact (it falls 4 cm: about 5 frames) the runs agree.
  EXPECT_GT(selection->trials.back().frames_within_tolerance, 3);
  EXPECT_LT(selection->trials.back().frames_within_tolerance, 48);
  // The impact itself still converges with the step (first order), the rocking after it not.
  EXPECT_EQ(selection->trials[0].frames_converging, selection->trials[0].frames_within_tolerance);
  EXPECT_GT(selection->trials.back().frames_converging,
            selection->trials.back().frames_within_tolerance);
  EXPECT_LT(selection->trials.back().frames_converging, 48);
}

// The fit keeps every step's state for its adjoint: on a large grid the candidates stop short of
// max_substeps so that nodes x substeps stays within the budget.
TEST(SelectSubsteps, LargeGridsTakeFewerCandidates) {
  SubstepSelectionOptions options;
  options.max_substeps = 64;
  options.max_node_steps_per_frame = 192000.0;
  EXPECT_EQ(LargestSubstepCandidate(1000, options), 64);
  EXPECT_EQ(LargestSubstepCandidate(6000, options), 32);
  EXPECT_EQ(LargestSubstepCandidate(1e7, options), options.min_substeps);
  // Only doublings of min_substeps: a budget of 34 or a cap of 48 still ends at 32.
  EXPECT_EQ(LargestSubstepCandidate(192000.0 / 34.5, options), 32);
  SubstepSelectionOptions capped = options;
  capped.max_substeps = 48;
  EXPECT_EQ(LargestSubstepCandidate(1000, capped), 32);
  capped.min_substeps = 3;
  EXPECT_EQ(LargestSubstepCandidate(1000, capped), 48);

  const Result<scenes::Scene> scene = scenes::MakeBuiltinScene("ball-bounce");
  ASSERT_TRUE(scene.ok());
  options.min_substeps = 1;
  options.tolerance_fraction = 1e-9;  // unreachable: every candidate up to the largest is tried
  options.max_node_steps_per_frame = 0.0;
  EXPECT_FALSE(SelectSubsteps(scene->mesh, scene->fixed_region, scene->parameters, CoarseGrid(),
                              60.0, 10, options)
                   .ok());
  options.max_node_steps_per_frame = 1.0;  // any grid: the smallest candidate only
  const Result<SubstepSelection> selection = SelectSubsteps(
      scene->mesh, scene->fixed_region, scene->parameters, CoarseGrid(), 60.0, 10, options);
  ASSERT_TRUE(selection.ok()) << selection.status().ToString();
  EXPECT_EQ(selection->max_substeps, 1);
  EXPECT_EQ(selection->substeps, 1);
  EXPECT_TRUE(selection->trials.empty());
  EXPECT_EQ(ToJson(*selection).at("max_substeps").get<int>(), 1);
}

// Newmark integrates a constant acceleration exactly: in free fall the first candidate passes.
TEST(SelectSubsteps, FreeFallNeedsNoRefinement) {
  Result<scenes::Scene> scene = scenes::MakeBuiltinScene("ball-bounce");
  ASSERT_TRUE(scene.ok());
  scene->parameters.ground.reset();
  const Result<SubstepSelection> selection =
      SelectSubsteps(scene->mesh, scene->fixed_region, scene->parameters, CoarseGrid(), 60.0, 12);
  ASSERT_TRUE(selection.ok()) << selection.status().ToString();
  EXPECT_TRUE(selection->within_tolerance);
  EXPECT_EQ(selection->substeps, SubstepSelectionOptions{}.min_substeps);
  ASSERT_EQ(selection->trials.size(), 1u);
  EXPECT_LT(selection->trials[0].difference_m, 1e-6);
}

TEST(SelectSubsteps, RejectsInvalidOptionsNamingThem) {
  const Result<scenes::Scene> scene = scenes::MakeBuiltinScene("ball-bounce");
  ASSERT_TRUE(scene.ok());
  SubstepSelectionOptions options;
  options.max_substeps = 1;
  Result<SubstepSelection> selection = SelectSubsteps(
      scene->mesh, scene->fixed_region, scene->parameters, CoarseGrid(), 60.0, 10, options);
  ASSERT_FALSE(selection.ok());
  EXPECT_NE(selection.status().message().find("max_substeps = 1"), std::string::npos);
  selection =
      SelectSubsteps(scene->mesh, scene->fixed_region, scene->parameters, CoarseGrid(), 0.0, 10);
  ASSERT_FALSE(selection.ok());
  EXPECT_NE(selection.status().message().find("fps = 0"), std::string::npos);
  selection =
      SelectSubsteps(scene->mesh, scene->fixed_region, scene->parameters, CoarseGrid(), 60.0, 0);
  ASSERT_FALSE(selection.ok());
  EXPECT_NE(selection.status().message().find("last_frame = 0"), std::string::npos);
}

// A time limit the first run already uses up: the step is not halved, the first candidate is
// taken and the selection says why, and its trials are no evidence of chaos.
TEST(SelectSubsteps, TakesTheFinestStepRunWithinTheTimeLimit) {
  const Result<scenes::Scene> scene = scenes::MakeBuiltinScene("ball-bounce");
  ASSERT_TRUE(scene.ok());
  SubstepSelectionOptions options;
  options.min_substeps = 1;
  options.max_substeps = 8;
  options.tolerance_fraction = 1e-9;  // unreachable: only the limit ends the halving
  options.max_seconds = 1e-6;
  const Result<SubstepSelection> limited = SelectSubsteps(
      scene->mesh, scene->fixed_region, scene->parameters, CoarseGrid(), 60.0, 30, options);
  ASSERT_TRUE(limited.ok()) << limited.status().ToString();
  EXPECT_EQ(limited->substeps, 1);
  EXPECT_TRUE(limited->trials.empty());
  EXPECT_TRUE(limited->stopped_at_time_limit);
  EXPECT_TRUE(ToJson(*limited).at("stopped_at_time_limit").get<bool>());
  SubstepSelection chaotic_looking;
  chaotic_looking.trials.resize(2);
  chaotic_looking.trials[1].substeps = 2;
  chaotic_looking.trials[1].frames_within_tolerance = 3;
  chaotic_looking.trials[1].frames_converging = 12;
  EXPECT_EQ(PredictableLastFrame(chaotic_looking, 30), 11);
  chaotic_looking.stopped_at_time_limit = true;
  EXPECT_EQ(PredictableLastFrame(chaotic_looking, 30), -1);
  options.max_seconds = -1.0;
  const Result<SubstepSelection> refused = SelectSubsteps(
      scene->mesh, scene->fixed_region, scene->parameters, CoarseGrid(), 60.0, 30, options);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("max_seconds = -1"), std::string::npos);
}

}  // namespace
}  // namespace softid::inverse
