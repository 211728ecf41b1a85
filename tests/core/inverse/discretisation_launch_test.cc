// The launch "auto" chooses the grid and time step at: measured in flight from a start at rest,
// only when a choice is made and a launch is fitted, and reported with the fit.
#include "core/inverse/discretisation_launch.h"

#include <gtest/gtest.h>

#include <cstdio>

#include "core/inverse/fit.h"
#include "tests/core/inverse/inverse_test_util.h"

namespace softid::inverse {
namespace {

// A job fitting E and the launch of the ball thrown sideways at 0.4 m/s, started at rest.
JobConfig LaunchConfig(const testing::SmallCapture& small) {
  JobConfig config = testing::YoungsModulusConfig(small.truth, /*starts=*/1, /*max_iterations=*/1);
  config.fit = {"youngs_modulus", "initial_velocity"};
  config.fixed.erase("initial_velocity");
  config.initial["initial_velocity"] = InitialValue{.value = nlohmann::json({0.0, 0.0, 0.0})};
  return config;
}

Result<std::optional<FlightStageResult>> Measure(const testing::SmallCapture& small,
                                                 const JobConfig& config,
                                                 const fem::PhysicalParameters& start) {
  return MeasureLaunchForDiscretisation(small.mesh, std::nullopt, start, fem::SimulationOptions{},
                                        config, config.fit, small.frames, small.capture.fps,
                                        nullptr);
}

TEST(DiscretisationLaunch, MeasuredInFlightWhenTheTimeStepIsChosen) {
  testing::SmallCapture small = testing::MakeSmallCapture("ball-bounce", 0.4, 1);
  ASSERT_TRUE(small.ok) << small.error;
  JobConfig config = LaunchConfig(small);
  config.solver.substeps = kAutoSubsteps;
  fem::PhysicalParameters start = small.truth;
  start.initial_velocity.setZero();
  start.youngs_modulus *= 2.0;

  Result<std::optional<FlightStageResult>> flight = Measure(small, config, start);
  ASSERT_TRUE(flight.ok()) << flight.status().ToString();
  ASSERT_TRUE(flight->has_value());
  const fem::PhysicalParameters& measured = (*flight)->parameters;
  std::printf("launch at rest -> %.4f %.4f %.4f m/s (truth 0.4 0 0), flight frames 0-%d\n",
              measured.initial_velocity.x(), measured.initial_velocity.y(),
              measured.initial_velocity.z(), (*flight)->last_frame);
  EXPECT_LT((measured.initial_velocity - small.truth.initial_velocity).norm(), 2e-3);
  EXPECT_EQ(measured.youngs_modulus, start.youngs_modulus);  // only the launch moves
  EXPECT_EQ(ProvisionalDiscretisationFor(config).cells, config.solver.cells);
  EXPECT_EQ(ProvisionalDiscretisationFor(config).substeps, GridSelectionOptions{}.substeps);
}

TEST(DiscretisationLaunch, NotMeasuredWithoutAChoiceOrAFittedLaunch) {
  testing::SmallCapture small = testing::MakeSmallCapture("ball-bounce", 0.4, 1);
  ASSERT_TRUE(small.ok) << small.error;
  const fem::PhysicalParameters start = small.truth;

  JobConfig given = LaunchConfig(small);  // 8 cells, 2 substeps: nothing to choose
  Result<std::optional<FlightStageResult>> flight = Measure(small, given, start);
  ASSERT_TRUE(flight.ok()) << flight.status().ToString();
  EXPECT_FALSE(flight->has_value());

  JobConfig no_launch = testing::YoungsModulusConfig(small.truth, 1, 1);
  no_launch.solver.substeps = kAutoSubsteps;
  flight = Measure(small, no_launch, start);
  ASSERT_TRUE(flight.ok()) << flight.status().ToString();
  EXPECT_FALSE(flight->has_value());

  JobConfig off = LaunchConfig(small);
  off.solver.substeps = kAutoSubsteps;
  off.solver.launch_from_flight = false;
  flight = Measure(small, off, start);
  ASSERT_TRUE(flight.ok()) << flight.status().ToString();
  EXPECT_FALSE(flight->has_value());
}

// A fit choosing its time step reports the launch it chose it at, in the result and its JSON.
TEST(DiscretisationLaunch, AFitReportsTheLaunchItChoseItsStepAt) {
  testing::SmallCapture small = testing::MakeSmallCapture("ball-bounce", 0.4, 1);
  ASSERT_TRUE(small.ok) << small.error;
  JobConfig config = LaunchConfig(small);
  config.solver.substeps = kAutoSubsteps;
  Result<FitResult> fit = Fit(small.capture, config);
  ASSERT_TRUE(fit.ok()) << fit.status().ToString();
  ASSERT_TRUE(fit->discretisation_launch.has_value());
  ASSERT_TRUE(fit->substep_selection.has_value());
  const Eigen::Vector3d& v = fit->discretisation_launch->parameters.initial_velocity;
  EXPECT_LT((v - small.truth.initial_velocity).norm(), 2e-3);
  const nlohmann::json json = ToJson(*fit);
  ASSERT_TRUE(json.contains("discretisation_launch"));
  EXPECT_EQ(json["discretisation_launch"]["held"], nlohmann::json::array({"initial_velocity"}));
  EXPECT_DOUBLE_EQ(json["discretisation_launch"]["initial_velocity"][0].get<double>(), v.x());

  config.solver.substeps = 2;
  Result<FitResult> given = Fit(small.capture, config);
  ASSERT_TRUE(given.ok()) << given.status().ToString();
  EXPECT_FALSE(given->discretisation_launch.has_value());
  EXPECT_FALSE(ToJson(*given).contains("discretisation_launch"));
}

}  // namespace
}  // namespace softid::inverse
