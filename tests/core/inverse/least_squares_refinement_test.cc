// Levenberg-Marquardt on the cost's least-squares form: from a start far along the coupled
// directions of two parameters it reaches the minimum at the truth in a few iterations, with the
// same result whether the Jacobian's columns run on one objective or two, and with the Cauchy
// frame loss by the loss's own value.
#include "core/inverse/least_squares_refinement.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <memory>

#include "core/inverse/frame_loss.h"
#include "core/inverse/parameter_space.h"
#include "tests/core/inverse/inverse_test_util.h"

namespace softid::inverse {
namespace {

class Refinement : public ::testing::Test {
 protected:
  void SetUp() override {
    small_ = std::make_unique<testing::SmallCapture>(testing::MakeSmallCapture("torus-drop", 0.35));
    ASSERT_TRUE(small_->ok) << small_->error;
    options_.cells_along_longest_side = 8;
  }
  std::unique_ptr<TrajectoryObjective> MakeObjective() const {
    return std::make_unique<TrajectoryObjective>(small_->mesh, std::nullopt, small_->truth,
                                                 options_, cost::SurfaceCostOptions{},
                                                 small_->frames, small_->capture.fps, 2);
  }
  // Young's modulus and the floor, from far along their coupled directions: E x 1.6 and the floor
  // 4 mm higher (the torus lands early and stiff).
  Result<ParameterSpace> CoupledSpace() const {
    return ParameterSpace::Create({"youngs_modulus", "ground_plane"}, small_->truth, 0.2);
  }
  fem::PhysicalParameters CoupledStart() const {
    fem::PhysicalParameters start = small_->truth;
    start.youngs_modulus *= 1.6;
    start.ground->offset += 0.004;
    return start;
  }
  std::unique_ptr<testing::SmallCapture> small_;
  fem::SimulationOptions options_;
};

TEST_F(Refinement, ReachesTheMinimumOfTwoCoupledParametersInFewIterations) {
  const fem::PhysicalParameters& truth = small_->truth;
  Result<ParameterSpace> space = CoupledSpace();
  ASSERT_TRUE(space.ok()) << space.status().ToString();
  const fem::PhysicalParameters start = CoupledStart();
  std::vector<double> x = space->ToVariables(start);
  std::unique_ptr<TrajectoryObjective> objective = MakeObjective();
  const double phi_max = 2.0 * objective->simulator().hex_mesh().CellSize();
  const double scale = phi_max * phi_max;
  Result<ObjectiveEvaluation> at_truth = objective->Evaluate(truth, false);
  ASSERT_TRUE(at_truth.ok() && !at_truth->diverged);

  int reported = 0;
  RefinementOptions options;
  options.max_iterations = 25;
  options.on_iteration = [&](int iteration, double cost, double) {
    EXPECT_EQ(iteration, ++reported);
    EXPECT_GT(cost, 0.0);
  };
  Result<RefinementSummary> summary =
      RefineByLevenbergMarquardt({objective.get()}, *space, truth, scale, &x, options);
  ASSERT_TRUE(summary.ok()) << summary.status().ToString();
  EXPECT_TRUE(summary->converged) << summary->termination;
  EXPECT_LT(summary->iterations, 25);
  EXPECT_EQ(reported, summary->iterations);
  EXPECT_GT(summary->evaluations, 5 * summary->iterations);  // 2 n + 1 runs per Jacobian
  EXPECT_LT(summary->final_cost, 0.3 * summary->initial_cost);
  // The noise-free capture was made on this grid: the minimum lies at the truth up to the cost's
  // discretisation floor, so it costs no more than the truth does.
  EXPECT_LE(summary->final_cost, at_truth->cost * (1.0 + 1e-6));
  const fem::PhysicalParameters found = space->ToParameters(x.data(), truth);
  EXPECT_NEAR(found.youngs_modulus, truth.youngs_modulus, 0.1 * truth.youngs_modulus);
  EXPECT_NEAR(found.ground->offset, truth.ground->offset, 1e-3);

  // The Jacobian's columns on two objectives (two threads): bitwise the same path.
  std::vector<double> x2 = space->ToVariables(start);
  std::unique_ptr<TrajectoryObjective> second = MakeObjective();
  options.on_iteration = nullptr;
  Result<RefinementSummary> parallel = RefineByLevenbergMarquardt(
      {objective.get(), second.get()}, *space, truth, scale, &x2, options);
  ASSERT_TRUE(parallel.ok()) << parallel.status().ToString();
  EXPECT_EQ(x2, x);
  EXPECT_EQ(parallel->iterations, summary->iterations);
}

// With the Cauchy frame loss the residuals' sum of squares is the robust cost itself, so the
// refinement compares its steps, and reports its cost, by what the L-BFGS stages minimised.
TEST_F(Refinement, MinimisesTheCauchyFrameLossByItsValue) {
  const fem::PhysicalParameters& truth = small_->truth;
  Result<ParameterSpace> space = CoupledSpace();
  ASSERT_TRUE(space.ok()) << space.status().ToString();
  fem::PhysicalParameters start = CoupledStart();
  std::vector<double> x = space->ToVariables(start);
  start = space->ToParameters(x.data(), truth);  // the refinement's start, as its variables give it
  std::unique_ptr<TrajectoryObjective> objective = MakeObjective();
  Result<ObjectiveEvaluation> at_start = objective->Evaluate(start, false);
  ASSERT_TRUE(at_start.ok() && !at_start->diverged);
  std::vector<double> costs = at_start->frame_costs;
  std::sort(costs.begin(), costs.end());
  // A scale under most of the start's frame costs: there the loss is far from least squares.
  const FrameLoss loss{0.1 * costs[costs.size() / 2]};
  objective->SetFrameLoss(loss);
  Result<ObjectiveEvaluation> robust_start = objective->Evaluate(start, false);
  Result<ObjectiveEvaluation> at_truth = objective->Evaluate(truth, false);
  ASSERT_TRUE(robust_start.ok() && at_truth.ok() && !at_truth->diverged);
  ASSERT_LT(robust_start->cost, 0.5 * at_start->cost);  // the premise: frames far above the scale

  const double phi_max = 2.0 * objective->simulator().hex_mesh().CellSize();
  const double scale = phi_max * phi_max;
  RefinementOptions options;
  options.max_iterations = 25;
  Result<RefinementSummary> summary =
      RefineByLevenbergMarquardt({objective.get()}, *space, truth, scale, &x, options);
  ASSERT_TRUE(summary.ok()) << summary.status().ToString();
  EXPECT_TRUE(summary->converged) << summary->termination;
  EXPECT_NEAR(summary->initial_cost, robust_start->cost, 1e-9 * robust_start->cost);
  const fem::PhysicalParameters found = space->ToParameters(x.data(), truth);
  Result<ObjectiveEvaluation> at_found = objective->Evaluate(found, false);
  ASSERT_TRUE(at_found.ok() && !at_found->diverged);
  EXPECT_NEAR(summary->final_cost, at_found->cost, 1e-9 * at_found->cost);
  EXPECT_LE(summary->final_cost, at_truth->cost * (1.0 + 1e-6));
  EXPECT_NEAR(found.youngs_modulus, truth.youngs_modulus, 0.1 * truth.youngs_modulus);
  EXPECT_NEAR(found.ground->offset, truth.ground->offset, 1e-3);
}

TEST_F(Refinement, RejectsMissingObjectivesAndMismatchedVariables) {
  Result<ParameterSpace> space = ParameterSpace::Create({"youngs_modulus"}, small_->truth, 0.2);
  ASSERT_TRUE(space.ok());
  std::vector<double> x = space->ToVariables(small_->truth);
  Result<RefinementSummary> none = RefineByLevenbergMarquardt({}, *space, small_->truth, 1.0, &x);
  EXPECT_EQ(none.status().code(), StatusCode::kInvalidArgument);
  std::unique_ptr<TrajectoryObjective> objective = MakeObjective();
  std::vector<double> wrong(3, 0.0);
  Result<RefinementSummary> mismatched =
      RefineByLevenbergMarquardt({objective.get()}, *space, small_->truth, 1.0, &wrong);
  EXPECT_EQ(mismatched.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(mismatched.status().message().find("3 variables"), std::string::npos);
}

}  // namespace
}  // namespace softid::inverse
