// The discretisation error of a fitted value, estimated at the optimum by one Newton step onto a
// finer grid and time step, against the change of a real refit on those levels.
#include "core/inverse/discretisation_error.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/inverse/fit_uncertainty.h"
#include "tests/core/inverse/inverse_test_util.h"

namespace softid::inverse {
namespace {

// Young's modulus of a ball bouncing once, the rest of the truth fixed, one start at the truth.
JobConfig BounceConfig(const fem::PhysicalParameters& truth, int cells, int substeps) {
  return testing::ModulusAtDiscretisation(truth, cells, substeps);
}

double FittedLogModulus(const testing::SmallCapture& capture, const JobConfig& config) {
  const Result<FitResult> fit = Fit(capture.capture, config);
  EXPECT_TRUE(fit.ok()) << fit.status().ToString();
  return fit.ok() ? std::log(fit->Best().final.youngs_modulus) : 0.0;
}

TEST(DiscretisationError, PredictsTheRefitOnTheFinerGridAndTimeStep) {
  const testing::SmallCapture capture = testing::MakeSmallCapture("ball-bounce", 0.4, 2, 14);
  ASSERT_TRUE(capture.ok) << capture.error;
  const JobConfig config = BounceConfig(capture.truth, 6, 2);
  const Result<FitResult> fit = Fit(capture.capture, config);
  ASSERT_TRUE(fit.ok()) << fit.status().ToString();
  const Result<FitUncertainty> analysis = EstimateFitUncertainty(capture.capture, config, *fit);
  ASSERT_TRUE(analysis.ok()) << analysis.status().ToString();
  ASSERT_TRUE(analysis->discretisation.has_value()) << analysis->discretisation_failure;
  const DiscretisationError& error = *analysis->discretisation;
  ASSERT_TRUE(error.grid.error.empty()) << error.grid.error;
  ASSERT_TRUE(error.time_step.error.empty()) << error.time_step.error;
  EXPECT_EQ(error.grid.compared, 9);
  EXPECT_EQ(error.time_step.compared, 4);
  // The bounce's cost is quadratic about the optimum on both finer levels: their costs follow the
  // Newton step (almost) all the way, and fall along it.
  for (const DiscretisationShift* shift : {&error.grid, &error.time_step}) {
    std::printf("step scale %.3f, finer cost %.4g at x*, %.4g at x* + dx\n", shift->step_scale,
                shift->cost_at_optimum, shift->cost_at_step);
    EXPECT_GT(shift->step_scale, 0.7);
    EXPECT_LE(shift->step_scale, 1.0);
    EXPECT_LT(shift->cost_at_step, shift->cost_at_optimum);
  }

  // The refits the estimate stands in for.
  const double x = std::log(fit->Best().final.youngs_modulus);
  const double grid_change = FittedLogModulus(capture, BounceConfig(capture.truth, 9, 2)) - x;
  const double time_change = FittedLogModulus(capture, BounceConfig(capture.truth, 6, 4)) - x;
  for (const auto& [name, predicted, actual] :
       {std::tuple{"grid", error.grid.variables[0], grid_change},
        std::tuple{"time step", error.time_step.variables[0], time_change}}) {
    SCOPED_TRACE(name);
    // Large enough to mean something (a change of 0.2 % or more), and predicted with its sign
    // and within a factor of two.
    std::printf("%s: predicted change of log E %.5f, refit %.5f\n", name, predicted, actual);
    ASSERT_GT(std::abs(actual), 2e-3);
    EXPECT_GT(predicted / actual, 0.5) << "predicted " << predicted << ", refit " << actual;
    EXPECT_LT(predicted / actual, 2.0) << "predicted " << predicted << ", refit " << actual;
  }

  // Each value's error in its own unit: |shift| x E x r / (r - 1), summed over the two levels.
  ASSERT_EQ(error.parameters.size(), 1u);
  const ParameterDiscretisationError& e = error.parameters[0];
  const double modulus = fit->Best().final.youngs_modulus;
  EXPECT_NEAR(e.grid[0], std::abs(error.grid.variables[0]) * modulus * error.grid.error_factor,
              1e-3 * e.grid[0]);
  EXPECT_NEAR(e.total[0], e.grid[0] + e.time_step[0], 1e-9 * e.total[0]);
  // The corrected value moves with the signs of the shifts: towards the finer levels' optima.
  const double grid_signed = (error.grid.variables[0] > 0 ? 1 : -1) * e.grid[0];
  const double time_signed = (error.time_step.variables[0] > 0 ? 1 : -1) * e.time_step[0];
  EXPECT_NEAR(e.corrected[0], modulus + grid_signed + time_signed, 1e-3 * e.total[0]);
  const nlohmann::json json = ToJson(*fit, &*analysis);
  const nlohmann::json& entry = json["parameters"]["youngs_modulus"];
  EXPECT_DOUBLE_EQ(entry["discretisation_error"]["total"].get<double>(), e.total[0]);
  EXPECT_NEAR(entry["relative_discretisation_error"].get<double>(), e.total[0] / modulus, 1e-12);
  EXPECT_EQ(json["discretisation"]["grid"]["compared_cells"], 9);
  EXPECT_DOUBLE_EQ(entry["discretisation_error"]["corrected"].get<double>(), e.corrected[0]);
}

// Along a step the cost is c(t) = c0 + a t + b t^2: its minimum t* = -a / (2 b) from c(0), c(1) and
// b, kept within [0, 1].
TEST(DiscretisationError, StepScaleIsTheMinimumAlongTheStep) {
  const auto scale = [](double c0, double a, double b) {
    return StepScaleAlong(c0, c0 + a + b, b);
  };
  EXPECT_NEAR(scale(5.0, -2.0, 1.0), 1.0, 1e-12);   // the Newton step itself: a = -2 b
  EXPECT_NEAR(scale(5.0, -0.5, 1.0), 0.25, 1e-12);  // the cost turns up a quarter of the way
  EXPECT_NEAR(scale(5.0, -0.02, 0.1), 0.1, 1e-12);
  EXPECT_EQ(scale(5.0, 0.3, 1.0), 0.0);           // rises from the start: no move
  EXPECT_EQ(scale(5.0, -4.0, 1.0), 1.0);          // never lengthened
  EXPECT_EQ(StepScaleAlong(5.0, 4.0, 0.0), 1.0);  // no curvature to judge by
  EXPECT_EQ(StepScaleAlong(5.0, std::nan(""), 1.0), 1.0);
}

}  // namespace
}  // namespace softid::inverse
