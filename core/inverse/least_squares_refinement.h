// Refinement of a fit by Levenberg-Marquardt on the cost's least-squares form (Ceres' trust-region
// minimiser), after the L-BFGS stages of a start.
//
// Why: with several coupled parameters the cost has long curved valleys (pillow-ramp: Young's
// modulus, mass and stiffness damping trade off so that E twice the truth costs 1.4 % more than
// the truth), where L-BFGS, which only sees gradients, creeps (47 iterations moved E from 6.7 to
// 6.3 kPa of a true 3.45 kPa). The cost is a sum of squared point residuals
// (TrajectoryObjective::EvaluateResiduals; with a robust frame loss, each frame's residuals scaled
// by sqrt(L(C_k) / C_k) so that their sum of squares is still the cost, frame_loss.h), so J^T J
// of their Jacobian J is a curvature that is positive semi-definite everywhere and exact up to
// the residuals' own curvature, which is small near a good fit; Levenberg-Marquardt damps it into a
// trust region, so a wrong quadratic model costs a rejected step, not a divergence.
//
// The Jacobian comes from central differences of forward runs in the optimiser's variables
// (2 n runs for n variables): forward-mode sensitivities through the simulator would be cheaper
// but are not written. Its columns are independent, so they run on as many objectives as given.
#pragma once

#include <atomic>
#include <functional>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/fem/physical_parameters.h"
#include "core/inverse/parameter_space.h"
#include "core/inverse/trajectory_objective.h"

namespace softid::inverse {

struct RefinementOptions {
  int max_iterations = 20;  // Levenberg-Marquardt iterations (each: one Jacobian), >= 1
  // Central-difference step in the optimiser's variables (log variables: a 0.1 % change; gravity:
  // 1 mm/s^2): large against the simulation's solver noise, small against the curvature.
  double jacobian_step = 1e-3;
  // Stop when a step lowers the cost by less than this fraction (Ceres' function_tolerance), or
  // when an accepted step's Gauss-Newton model predicted less than that (near the minimum the
  // actual change is the forward runs' noise, a few 1e-6 relative).
  double function_tolerance = 1e-6;
  double gradient_tolerance = 1e-10;  // as Ceres' Solver::Options
  double parameter_tolerance = 1e-8;  // as Ceres' Solver::Options
  const std::atomic<bool>* cancel = nullptr;
  // After each iteration: iteration (1-based), cost [m^2], gradient max norm (variables, scaled).
  std::function<void(int, double, double)> on_iteration;
};

struct RefinementSummary {
  int iterations = 0;
  double initial_cost = 0.0, final_cost = 0.0;  // [m^2]
  bool converged = false;   // Ceres: CONVERGENCE, or the model's predicted change (USER_SUCCESS)
  std::string termination;  // Ceres' message
  int evaluations = 0, failed_evaluations = 0;  // forward runs (Jacobian columns included)
  long long steps = 0, unconverged_steps = 0;   // simulation steps of those runs
  double forward_seconds = 0.0;
};

// Minimises objective(space.ToParameters(x, base)) from x (updated in place) with the cost in units
// of `scale` [m^2] (as the L-BFGS stages: phi_max^2). `objectives` are equivalent objectives (same
// capture, options and active frames), one per thread; objectives[0] evaluates the residuals, all
// of them the Jacobian's columns. A forward run that diverges makes the step fail (the trust region
// shrinks). InvalidArgument for an empty `objectives` or x of the wrong size.
Result<RefinementSummary> RefineByLevenbergMarquardt(
    const std::vector<TrajectoryObjective*>& objectives, const ParameterSpace& space,
    const fem::PhysicalParameters& base, double scale, std::vector<double>* x,
    const RefinementOptions& options = {});

}  // namespace softid::inverse
