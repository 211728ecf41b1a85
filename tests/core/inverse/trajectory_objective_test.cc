// End to end through a synthetic capture: the objective's adjoint gradient (simulation + sparse
// surface cost) matches central finite differences, and the truth is a minimum of the cost.
#include "core/inverse/trajectory_objective.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <thread>

#include "core/capture/capture.h"
#include "core/inverse/observed_frames.h"
#include "core/scenes/scene.h"
#include "core/scenes/synthesize.h"
#include "tests/core/inverse/inverse_test_util.h"

namespace softid::inverse {
namespace {

// The simulation of the small captures' objectives: an 8-cell grid, other settings default.
fem::SimulationOptions EightCells() {
  fem::SimulationOptions options;
  options.cells_along_longest_side = 8;
  return options;
}

// Checks the adjoint gradient of a small capture's objective over `frames` against central finite
// differences, parameter by parameter.
// With `robust`, the frames add up through a Cauchy frame loss whose scale is the median frame
// cost there, so that the frames' weights differ.
// With `grid_turn`, the rest mesh is given turned by it about its centre and turned back by the
// initial pose, and the grid follows the body (fem::GridOrientation::kBody): the gradient then
// crosses the grid's turn as well.
void ExpectAdjointMatchesFiniteDifferences(
    const testing::SmallCapture& small, std::shared_ptr<const std::vector<ObservedFrame>> frames,
    bool robust = false, const std::optional<Eigen::Matrix3d>& grid_turn = std::nullopt) {
  fem::SimulationOptions options;
  options.cells_along_longest_side = 8;
  options.newton_tolerance = 1e-11;
  options.max_newton_iterations = 40;
  options.linear_tolerance = 1e-12;
  options.adjoint_linear_tolerance = 1e-12;
  fem::PhysicalParameters p = small.truth;
  p.youngs_modulus *= 1.4;
  p.mass_damping *= 0.7;
  p.gravity += Eigen::Vector3d(0.2, -0.1, 0.3);
  p.ground->offset += 0.004;
  // A turned and moved rest pose and a spin: the gradient crosses the rest frame's chain rule
  // (gravity, ground, velocities into the rest frame, displacements back).
  p.initial_pose.rotation = Eigen::Vector3d(0.03, -0.02, 0.05);
  p.initial_pose.translation = Eigen::Vector3d(0.002, -0.003, 0.001);
  p.initial_angular_velocity = Eigen::Vector3d(0.4, -0.6, 0.3);
  geometry::TriangleMesh mesh = small.mesh;
  if (grid_turn) {
    const Eigen::Vector3d centre = mesh.Bounds().center();
    for (Eigen::Vector3d& x : mesh.vertices) x = *grid_turn * (x - centre) + centre;
    const Eigen::AngleAxisd back(grid_turn->transpose());
    p.initial_pose.rotation += back.angle() * back.axis();
    options.grid_orientation = fem::GridOrientation::kBody;
  }
  TrajectoryObjective objective(mesh, std::nullopt, p, options, {}, frames, small.capture.fps, 2);
  if (grid_turn) {
    ASSERT_GT(Eigen::AngleAxisd(objective.simulator().mesh_from_grid()).angle(), 0.1);
  }
  if (robust) {
    Result<ObjectiveEvaluation> plain = objective.Evaluate(p, false);
    ASSERT_TRUE(plain.ok() && !plain->diverged);
    std::vector<double> costs = plain->frame_costs;
    std::nth_element(costs.begin(), costs.begin() + costs.size() / 2, costs.end());
    ASSERT_GT(costs[costs.size() / 2], 0.0);
    objective.SetFrameLoss(FrameLoss{costs[costs.size() / 2]});
  }
  Result<ObjectiveEvaluation> base = objective.Evaluate(p, true);
  ASSERT_TRUE(base.ok()) << base.status().ToString();
  ASSERT_FALSE(base->diverged);
  ASSERT_GT(base->cost, 0.0);
  const fem::ParameterGradient& g = base->gradient;

  auto central = [&](auto set, double step) {
    fem::PhysicalParameters plus = p, minus = p;
    set(plus, step);
    set(minus, -step);
    Result<ObjectiveEvaluation> a = objective.Evaluate(plus, false);
    Result<ObjectiveEvaluation> b = objective.Evaluate(minus, false);
    EXPECT_TRUE(a.ok() && b.ok() && !a->diverged && !b->diverged);
    return (a->cost - b->cost) / (2.0 * step);
  };
  struct Check {
    const char* name;
    std::function<void(fem::PhysicalParameters&, double)> set;
    double step;
    double adjoint;
  };
  const Eigen::Vector3d d(0.3, -0.5, 0.81);
  const Eigen::Vector3d tangent = p.ground->normal.cross(d).normalized();
  const std::vector<Check> checks = {
      {"youngs_modulus (log)", [](auto& q, double t) { q.youngs_modulus *= std::exp(t); }, 1e-5,
       g.youngs_modulus * p.youngs_modulus},
      {"poisson_ratio", [](auto& q, double t) { q.poisson_ratio += t; }, 1e-6, g.poisson_ratio},
      {"mass_damping", [](auto& q, double t) { q.mass_damping += t; }, 1e-6, g.mass_damping},
      {"stiffness_damping", [](auto& q, double t) { q.stiffness_damping += t; }, 1e-7,
       g.stiffness_damping},
      {"gravity", [&](auto& q, double t) { q.gravity += t * d; }, 1e-5, g.gravity.dot(d)},
      {"initial_velocity", [&](auto& q, double t) { q.initial_velocity += t * d; }, 1e-6,
       g.initial_velocity.dot(d)},
      {"ground.offset", [](auto& q, double t) { q.ground->offset += t; }, 1e-7, g.ground_offset},
      {"ground.normal", [&](auto& q, double t) { q.ground->normal += t * tangent; }, 1e-7,
       g.ground_normal.dot(tangent)},
      {"initial_angular_velocity", [&](auto& q, double t) { q.initial_angular_velocity += t * d; },
       1e-6, g.initial_angular_velocity.dot(d)},
      {"initial_pose.rotation", [&](auto& q, double t) { q.initial_pose.rotation += t * d; }, 1e-6,
       g.initial_pose_rotation.dot(d)},
      {"initial_pose.translation", [&](auto& q, double t) { q.initial_pose.translation += t * d; },
       1e-7, g.initial_pose_translation.dot(d)},
  };
  for (const Check& check : checks) {
    const double fd = central(check.set, check.step);
    EXPECT_NEAR(check.adjoint, fd, 1e-4 * std::abs(fd) + 1e-14)
        << check.name << ": adjoint " << check.adjoint << " vs finite differences " << fd;
  }
}

TEST(TrajectoryObjective, AdjointGradientMatchesFiniteDifferences) {
  testing::SmallCapture small = testing::MakeSmallCapture("torus-drop", 0.3);
  ASSERT_TRUE(small.ok) << small.error;
  ExpectAdjointMatchesFiniteDifferences(small, small.frames);
}

// A box (the pillow) given turned: its grid turns with it.
TEST(TrajectoryObjective, AdjointGradientMatchesFiniteDifferencesOnAGridTurnedWithTheBody) {
  testing::SmallCapture small = testing::MakeSmallCapture("pillow-ramp", 0.3);
  ASSERT_TRUE(small.ok) << small.error;
  const Eigen::Matrix3d turn =
      Eigen::AngleAxisd(0.5, Eigen::Vector3d(1.0, -2.0, 0.5).normalized()).toRotationMatrix();
  ExpectAdjointMatchesFiniteDifferences(small, small.frames, /*robust=*/false, turn);
}

// The Cauchy frame loss (frame_loss.h) weights each frame's gradient by its own cost.
TEST(TrajectoryObjective, AdjointGradientMatchesFiniteDifferencesWithACauchyFrameLoss) {
  testing::SmallCapture small = testing::MakeSmallCapture("torus-drop", 0.3);
  ASSERT_TRUE(small.ok) << small.error;
  ExpectAdjointMatchesFiniteDifferences(small, small.frames, /*robust=*/true);
}

// The Cauchy frame loss's cost is the mean of b log(1 + C_k / b) over the fitted frames; its
// residuals are the frames' least-squares residuals weighted by 1 / (1 + C_k / b).
TEST(TrajectoryObjective, ACauchyFrameLossCountsEachFrameByItsRelativeMisfit) {
  testing::SmallCapture small = testing::MakeSmallCapture("torus-drop", 0.3);
  ASSERT_TRUE(small.ok) << small.error;
  fem::PhysicalParameters p = small.truth;
  p.youngs_modulus *= 1.6;
  TrajectoryObjective objective(small.mesh, std::nullopt, p, EightCells(), {}, small.frames,
                                small.capture.fps, 2);
  Result<ObjectiveEvaluation> plain = objective.Evaluate(p, false);
  ASSERT_TRUE(plain.ok() && !plain->diverged);
  std::vector<double> sorted = plain->frame_costs;
  std::sort(sorted.begin(), sorted.end());
  const double b = sorted[sorted.size() / 2];  // [m^2]: frames below and far above it
  objective.SetFrameLoss(FrameLoss{b});
  Eigen::VectorXd residuals;
  Result<ObjectiveEvaluation> robust = objective.EvaluateResiduals(p, &residuals);
  ASSERT_TRUE(robust.ok() && !robust->diverged);
  EXPECT_EQ(robust->frame_costs, plain->frame_costs);
  double expected = 0.0, reweighted = 0.0, largest = 0.0, smallest = 1e300;
  const double frames = static_cast<double>(plain->frame_costs.size());
  for (double c : plain->frame_costs) {
    expected += b * std::log1p(c / b) / frames;
    reweighted += c / (1.0 + c / b) / frames;
    largest = std::max(largest, c);
    smallest = std::min(smallest, c);
  }
  ASSERT_GT(largest, 5.0 * b);  // the premise: some frames far above the scale
  ASSERT_LT(smallest, b);       // and some below it
  EXPECT_NEAR(robust->cost, expected, 1e-12 * expected);
  EXPECT_LT(robust->cost, plain->cost);
  EXPECT_NEAR(0.5 * residuals.squaredNorm(), reweighted, 1e-9 * reweighted);
  EXPECT_NEAR(robust->reweighted_cost, reweighted, 1e-12 * reweighted);
  EXPECT_EQ(plain->reweighted_cost, plain->cost);  // least squares
  // Weighted by L(C_k) / C_k, the residuals' sum of squares is the robust cost itself.
  Eigen::VectorXd value_residuals;
  ASSERT_TRUE(objective
                  .EvaluateResiduals(p, &value_residuals,
                                     TrajectoryObjective::ResidualWeighting::kLossValue)
                  .ok());
  EXPECT_NEAR(0.5 * value_residuals.squaredNorm(), expected, 1e-9 * expected);
}

// Frames between simulation steps (device-clock jitter), a dropped frame and two frames within
// one step: the cost compares interpolated states, and the adjoint splits each frame's gradient
// between the two steps around it.
TEST(TrajectoryObjective, AdjointGradientMatchesFiniteDifferencesBetweenSteps) {
  testing::SmallCapture small = testing::MakeSmallCapture("torus-drop", 0.3);
  ASSERT_TRUE(small.ok) << small.error;
  const double dt = 1.0 / (small.capture.fps * 2);
  const double offsets[] = {0.0, 0.3, -0.45, 0.5, 0.0, 0.9, -0.2};
  std::vector<ObservedFrame> frames;
  for (const ObservedFrame& frame : *small.frames) {
    if (frame.frame == 5) continue;  // dropped
    ObservedFrame jittered = frame;
    if (frame.frame > 0) jittered.time += offsets[frame.frame % 7] * dt;
    frames.push_back(std::move(jittered));
  }
  frames[3].time = frames[4].time - 0.4 * dt;  // within the step before frame 4's
  ASSERT_GT(frames[3].time, frames[2].time);
  ExpectAdjointMatchesFiniteDifferences(
      small, std::make_shared<const std::vector<ObservedFrame>>(std::move(frames)));
}

// Time stamps matter: frames shown at k / 60 s compared at those times through steps of 1/100 s
// (between the steps) stay near the cost floor of the truth, while the same frames taken to be
// at k / 50 s (time stamps ignored) do not.
TEST(TrajectoryObjective, FramesBetweenStepsAreComparedAtTheirTimes) {
  testing::SmallCapture small = testing::MakeSmallCapture("torus-drop", 0.3);
  ASSERT_TRUE(small.ok) << small.error;
  fem::SimulationOptions options;
  options.cells_along_longest_side = 8;
  auto cost_at_truth = [&](double fps, int substeps, double assumed_fps) {
    std::vector<ObservedFrame> frames = *small.frames;
    for (ObservedFrame& frame : frames) frame.time = frame.frame / assumed_fps;
    TrajectoryObjective objective(small.mesh, std::nullopt, small.truth, options, {},
                                  std::make_shared<const std::vector<ObservedFrame>>(frames), fps,
                                  substeps);
    Result<ObjectiveEvaluation> r = objective.Evaluate(small.truth, false);
    EXPECT_TRUE(r.ok() && !r->diverged);
    return r->cost;
  };
  const double on_steps = cost_at_truth(60.0, 2, 60.0);
  const double between_steps = cost_at_truth(50.0, 2, 60.0);
  const double times_ignored = cost_at_truth(50.0, 2, 50.0);
  EXPECT_LT(between_steps, 3.0 * on_steps);
  EXPECT_LT(between_steps, 0.1 * times_ignored);
  std::printf("cost at the truth: on steps %.3g m^2, between steps %.3g m^2, times ignored %.3g\n",
              on_steps, between_steps, times_ignored);
}

TEST(TrajectoryObjective, TruthIsALocalMinimumAndDivergenceIsReported) {
  testing::SmallCapture small = testing::MakeSmallCapture("torus-drop", 0.3);
  ASSERT_TRUE(small.ok) << small.error;
  fem::SimulationOptions options;
  options.cells_along_longest_side = 8;
  TrajectoryObjective objective(small.mesh, std::nullopt, small.truth, options, {}, small.frames,
                                small.capture.fps, 2);
  auto cost_at = [&](double e_scale) {
    fem::PhysicalParameters q = small.truth;
    q.youngs_modulus *= e_scale;
    Result<ObjectiveEvaluation> r = objective.Evaluate(q, false);
    EXPECT_TRUE(r.ok() && !r->diverged);
    return r->cost;
  };
  const double at_truth = cost_at(1.0);
  EXPECT_LT(at_truth, cost_at(0.7));
  EXPECT_LT(at_truth, cost_at(1.4));
  // Truth sits at the noise-free discretisation floor, far below the phi_max^2 / 6 of unmatched.
  EXPECT_LT(at_truth, 0.3 * cost_at(0.1));
}

// The least-squares form carries exactly the cost: 1/2 |r|^2 = cost, one residual per point of
// every fitted frame, held-out frames left out; a point's residual has the sign of its distance.
TEST(TrajectoryObjective, ResidualsAreTheCostAsASumOfSquares) {
  testing::SmallCapture small = testing::MakeSmallCapture("torus-drop", 0.3);
  ASSERT_TRUE(small.ok) << small.error;
  std::vector<ObservedFrame> frames = *small.frames;
  for (size_t k = 3; k < frames.size(); k += 4) frames[k].heldout = true;
  auto shared = std::make_shared<const std::vector<ObservedFrame>>(frames);
  fem::SimulationOptions options;
  options.cells_along_longest_side = 8;
  fem::PhysicalParameters p = small.truth;
  p.youngs_modulus *= 1.6;  // residuals well above the discretisation floor
  TrajectoryObjective objective(small.mesh, std::nullopt, p, options, {}, shared, small.capture.fps,
                                2);
  int fitted_points = 0;
  for (const ObservedFrame& frame : frames) {
    if (!frame.heldout) fitted_points += static_cast<int>(frame.points.size());
  }
  ASSERT_GT(fitted_points, 100);
  EXPECT_EQ(objective.NumResiduals(), fitted_points);
  Eigen::VectorXd residuals;
  Result<ObjectiveEvaluation> evaluation = objective.EvaluateResiduals(p, &residuals);
  ASSERT_TRUE(evaluation.ok()) << evaluation.status().ToString();
  ASSERT_FALSE(evaluation->diverged);
  ASSERT_EQ(residuals.size(), fitted_points);
  Result<ObjectiveEvaluation> plain = objective.Evaluate(p, false);
  ASSERT_TRUE(plain.ok());
  EXPECT_EQ(evaluation->cost, plain->cost);
  EXPECT_NEAR(0.5 * residuals.squaredNorm(), plain->cost, 1e-12 * plain->cost);
  // Both signs occur (points inside and outside the simulated surface).
  EXPECT_GT((residuals.array() > 0.0).count(), 0);
  EXPECT_GT((residuals.array() < 0.0).count(), 0);
  // A shorter horizon has fewer residuals.
  objective.SetActiveFrames(4);
  EXPECT_EQ(objective.NumResiduals(),
            static_cast<int>(frames[0].points.size() + frames[1].points.size() +
                             frames[2].points.size()));
}

// An optimiser's line search and finite differences need the same parameters to give the same
// cost and gradient, bitwise, on the objective it keeps reusing.
TEST(TrajectoryObjective, EvaluationIsBitwiseRepeatable) {
  testing::SmallCapture small = testing::MakeSmallCapture("torus-drop", 0.3);
  ASSERT_TRUE(small.ok) << small.error;
  const fem::SimulationOptions options = EightCells();
  fem::PhysicalParameters p = small.truth;
  p.youngs_modulus *= 0.8;
  p.friction_coefficient = 0.3;
  TrajectoryObjective objective(small.mesh, std::nullopt, p, options, {}, small.frames,
                                small.capture.fps, 2);
  Result<ObjectiveEvaluation> a = objective.Evaluate(p, true);
  Result<ObjectiveEvaluation> b = objective.Evaluate(p, true);
  ASSERT_TRUE(a.ok() && b.ok());
  ASSERT_FALSE(a->diverged || b->diverged);
  EXPECT_EQ(a->cost, b->cost);
  EXPECT_EQ(a->frame_costs, b->frame_costs);
  EXPECT_EQ(fem::ToJson(a->gradient).dump(), fem::ToJson(b->gradient).dump());
  // A value-only evaluation (the line search's) gives the same cost: with a gradient, the frame
  // costs come from the backward pass instead.
  Result<ObjectiveEvaluation> value_only = objective.Evaluate(p, false);
  ASSERT_TRUE(value_only.ok());
  EXPECT_EQ(value_only->cost, a->cost);
  EXPECT_EQ(value_only->frame_costs, a->frame_costs);
  EXPECT_GT(a->cost, 0.0);
}

// A cancel takes effect within a step, forward or backward, even in a long run; the objective is
// usable afterwards with the same results as before.
TEST(TrajectoryObjective, CancelStopsALongRunWithinAStep) {
  testing::SmallCapture small = testing::MakeSmallCapture("torus-drop", 0.3);
  ASSERT_TRUE(small.ok) << small.error;
  fem::SimulationOptions options;
  options.cells_along_longest_side = 8;
  const fem::PhysicalParameters p = small.truth;
  // 100 steps per frame: a run long enough that the flag arrives while it is under way.
  TrajectoryObjective objective(small.mesh, std::nullopt, p, options, {}, small.frames,
                                small.capture.fps, 100);
  Result<ObjectiveEvaluation> before = objective.Evaluate(p, false);
  ASSERT_TRUE(before.ok());

  std::atomic<bool> cancel{true};
  objective.SetCancelFlag(&cancel);
  Result<ObjectiveEvaluation> at_once = objective.Evaluate(p, true);
  EXPECT_EQ(at_once.status().code(), StatusCode::kCancelled);

  cancel.store(false);
  std::thread canceller([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    cancel.store(true);
  });
  Result<ObjectiveEvaluation> midway = objective.Evaluate(p, true);
  canceller.join();
  EXPECT_EQ(midway.status().code(), StatusCode::kCancelled) << midway.status().ToString();

  cancel.store(false);
  Result<ObjectiveEvaluation> after = objective.Evaluate(p, false);
  ASSERT_TRUE(after.ok());
  EXPECT_EQ(after->cost, before->cost);
}

}  // namespace
}  // namespace softid::inverse
