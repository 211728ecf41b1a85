// How much of a fitted value is owed to the discretisation, reported beside its statistical
// uncertainty (fit_uncertainty.h).
//
// A fit on a finite grid and time step returns the parameters that make the *discrete* model
// match the recording; the continuum's would differ. The change of the optimum from the chosen
// level to a finer one (cells 1.5 x smaller, half the time step) is estimated at the optimum x*
// without refitting, by one Newton step from x* on the finer model:
//   dx = -H^-1 (g_finer(x*) - g(x*)),
// with H the cost's Hessian from the identifiability analysis and g the adjoint gradient: two
// forward and adjoint runs in all, one of them on a grid with ~3.4 x the nodes. A finer level,
// not a coarser one, because the step must stay in the range where the cost is quadratic: on the
// torus at 4 substeps the optimum at 2 substeps lies 33-46 % away in E, past anything a Newton
// step predicts. For a method of order p, refining by the ratio r reduces the error by r^p, so
// the chosen level's own error is about |dx| r^p / (r^p - 1) (Richardson). p = 1 is taken for
// both: Newmark with gamma 0.6 is first order in time, and the cut cells represent the boundary
// to first order in h (the elements' interior converges faster, so this is an upper estimate).
// Each fitted value gets the two estimates and their sum.
//
// The Newton step rests on the finer level's gradient, which a motion sensitive to small changes
// makes unreliable (a cube wobbling as it slides: at 16 substeps the step predicted E to move 21 %
// at 32, a refit there moved it 2.9 %). So the step is checked on the finer level's cost itself,
// one more forward run: along dx the cost is c(t) = c(0) + a t + b t^2 with b = dx^T H dx / 2 from
// the fit's own curvature, a then follows from c(1), and the optimum along dx lies at t* = -a /
// (2 b); dx is scaled by t* (in [0, 1]: a step the cost does not follow is shortened, never
// lengthened), and each level reports t* as `step_scale`. Where the cost rises from the start
// (t* = 0) the gradient says nothing of where the finer optimum lies: that level has no estimate.
// Variables the fit held after measuring them on their own frames (the launch, in flight) do not
// move: a refit would measure them again on rigid motion, which the discretisation barely
// changes (counted free, the friction cube's correlated launch pulled E along with it).
#pragma once

#include <Eigen/Core>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "core/capture/capture.h"
#include "core/common/status.h"
#include "core/inverse/fit.h"
#include "core/inverse/identifiability.h"
#include "core/inverse/job_config.h"

namespace softid::inverse {

// The change of the optimum between the fit's level and a finer one.
struct DiscretisationShift {
  double ratio = 0.0;         // chosen h / finer h, or finer substeps / chosen substeps [-]
  int chosen = 0;             // cells along the longest side (0: config's cell_size), or substeps
  int compared = 0;           // the same for the finer level
  Eigen::VectorXd variables;  // dx, the optimiser's variables [-]; +inf where unbounded
  double error_factor = 0.0;  // r^p / (r^p - 1), p = 1: shift -> the chosen level's error
  // The share of the Newton step the finer level's cost follows (StepScaleAlong), in [0, 1];
  // `variables` is already scaled by it. NaN when not checked (no finite step).
  double step_scale = std::numeric_limits<double>::quiet_NaN();
  double cost_at_optimum = 0.0;  // the finer level's cost at x* [m^2]
  double cost_at_step = 0.0;     // ... and at x* + dx (the whole Newton step) [m^2]
  std::string error;             // why no shift could be estimated (the finer run diverged, ...)
};

// The minimum along a step, t* in [0, 1], of c(t) = c0 + a t + b t^2 through c(0) = c0 and
// c(1) = c1 with the curvature b [the cost's unit], > 0: -a / (2 b), clamped; 1 when b <= 0 (no
// curvature to judge by).
double StepScaleAlong(double c0, double c1, double b);

struct ParameterDiscretisationError {
  std::string name;  // the fitted name
  // One per number of the value's public form (as ParameterUncertainty), the estimated error of
  // the chosen level [the parameter's unit], >= 0; +inf where undetermined, NaN when that level's
  // estimate is missing.
  std::vector<double> grid, time_step, total;
  // The value moved by both signed estimates: a Richardson extrapolation towards the continuum
  // (first order) [the parameter's unit]; NaN where an estimate is missing or undetermined.
  // docs/benchmarks.md shows how close it comes on independent captures.
  std::vector<double> corrected;
};

struct DiscretisationError {
  DiscretisationShift grid, time_step;
  std::vector<ParameterDiscretisationError> parameters;  // in the order of FitResult::fitted
  double seconds = 0.0;
};

// The estimate for `fit` (its best start) with `report` from AnalyzeIdentifiability of the same
// fit. A level that cannot be simulated (a divergent run) leaves its shift's `error` set and its
// numbers NaN; the other is still estimated.
Result<DiscretisationError> EstimateDiscretisationError(const capture::Capture& capture,
                                                        const JobConfig& config,
                                                        const FitResult& fit,
                                                        const IdentifiabilityReport& report);

// result.json's "discretisation" object: {"method", "grid": {"cells", "compared_cells", "ratio",
// "error_factor", "error"?}, "time_step": {"substeps", "compared_substeps", ...}, "seconds"}.
nlohmann::json ToJson(const DiscretisationError& error);

}  // namespace softid::inverse
