// The launch measured in flight: the flight frames end at the landing, the launch comes out of
// them whatever the stiffness, the stage is skipped where it cannot measure the launch, and a fit
// holds what it measured.
#include "core/inverse/flight_stage.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "core/inverse/fit.h"
#include "core/inverse/trajectory_objective.h"
#include "tests/core/inverse/inverse_test_util.h"

namespace softid::inverse {
namespace {

constexpr int kSubsteps = 2;

TrajectoryObjective MakeObjective(
    const testing::SmallCapture& small,
    const std::optional<Eigen::AlignedBox3d>& fixed_region = std::nullopt) {
  fem::SimulationOptions options;
  options.cells_along_longest_side = 8;
  return TrajectoryObjective(small.mesh, fixed_region, small.truth, options, {}, small.frames,
                             small.capture.fps, kSubsteps);
}

// phi_max^2 of the default cost on the objective's grid, as the fit scales its cost.
double CostScale(TrajectoryObjective& objective) {
  const double phi_max = 2.0 * objective.simulator().hex_mesh().CellSize();
  return phi_max * phi_max;
}

// The ball thrown sideways from 22 cm above the floor (lowest point) lands when it has fallen that
// far, less the contact distance: free fall is exact in the simulation (lumped mass, Newmark), so
// the landing is found within one step, and the flight frames are those up to it.
TEST(FlightStage, FlightFramesEndAtTheLanding) {
  testing::SmallCapture small = testing::MakeSmallCapture("ball-bounce", 0.4, 1);
  ASSERT_TRUE(small.ok) << small.error;
  TrajectoryObjective objective = MakeObjective(small);
  const FlightStageOptions options;
  Result<FlightFrames> flight = FramesBeforeContact(objective, small.truth, options);
  ASSERT_TRUE(flight.ok()) << flight.status().ToString();

  double lowest = INFINITY;
  for (const Eigen::Vector3d& v : objective.simulator().rest_surface().vertices)
    lowest = std::min(lowest, v.z());
  const double drop_m =
      lowest - options.contact_distance_fraction * objective.characteristic_length();
  const double landing_s = std::sqrt(2.0 * drop_m / 9.81);
  const double dt = 1.0 / (small.capture.fps * kSubsteps);
  std::printf("landing at %.4f s, analytic %.4f s; %d flight frames\n", flight->contact_time_s,
              landing_s, flight->count);
  EXPECT_LE(flight->contact_time_s, landing_s);
  EXPECT_GT(flight->contact_time_s, landing_s - 1.01 * dt);
  const std::vector<ObservedFrame>& frames = objective.frames();
  ASSERT_GT(flight->count, 2);
  ASSERT_LT(flight->count, static_cast<int>(frames.size()));
  EXPECT_LE(frames[flight->count - 1].time, flight->contact_time_s);
  EXPECT_GT(frames[flight->count].time, flight->contact_time_s);

  // Without a ground every frame is flight.
  fem::PhysicalParameters floorless = small.truth;
  floorless.ground.reset();
  Result<FlightFrames> free = FramesBeforeContact(objective, floorless, options);
  ASSERT_TRUE(free.ok());
  EXPECT_EQ(free->count, static_cast<int>(frames.size()));
  EXPECT_TRUE(std::isinf(free->contact_time_s));
}

// Started at rest with three times the stiffness, the flight stage finds the ball's sideways
// launch from its flight frames alone and leaves the stiffness where it was.
TEST(FlightStage, MeasuresTheLaunchWhateverTheStiffness) {
  testing::SmallCapture small = testing::MakeSmallCapture("ball-bounce", 0.4, 1);
  ASSERT_TRUE(small.ok) << small.error;
  TrajectoryObjective objective = MakeObjective(small);
  fem::PhysicalParameters start = small.truth;
  start.youngs_modulus *= 3.0;
  start.initial_velocity.setZero();
  Result<FlightStageResult> flight = MeasureLaunchInFlight(
      objective, {"youngs_modulus", "initial_velocity"}, start, CostScale(objective), nullptr);
  ASSERT_TRUE(flight.ok()) << flight.status().ToString();
  ASSERT_TRUE(flight->skipped.empty()) << flight->skipped;
  EXPECT_EQ(flight->held, std::vector<std::string>{"initial_velocity"});
  EXPECT_EQ(flight->fitted, std::vector<std::string>{"initial_velocity"});
  const Eigen::Vector3d error = flight->parameters.initial_velocity - small.truth.initial_velocity;
  std::printf(
      "launch %s m/s (truth 0.4, 0, 0) from %d flight frames up to frame %d, %d iterations\n",
      nlohmann::json(std::vector<double>(flight->parameters.initial_velocity.data(),
                                         flight->parameters.initial_velocity.data() + 3))
          .dump()
          .c_str(),
      flight->frames, flight->last_frame, flight->iterations);
  EXPECT_LT(error.norm(), 2e-3);
  EXPECT_EQ(flight->parameters.youngs_modulus, start.youngs_modulus);
  EXPECT_GE(flight->frames, 2);
  EXPECT_LT(flight->final_cost, 0.01 * flight->initial_cost);
  EXPECT_EQ(objective.active_frames(), static_cast<int>(objective.frames().size()));

  // The report survives its JSON (results and checkpoints).
  Result<FlightStageResult> read = FlightStageResultFromJson(ToJson(*flight));
  ASSERT_TRUE(read.ok()) << read.status().ToString();
  EXPECT_EQ(read->held, flight->held);
  EXPECT_EQ(read->last_frame, flight->last_frame);
  EXPECT_DOUBLE_EQ(read->contact_time_s, flight->contact_time_s);
}

TEST(FlightStage, SkippedWhereFlightCannotMeasureTheLaunch) {
  testing::SmallCapture small = testing::MakeSmallCapture("ball-bounce", 0.4, 1);
  ASSERT_TRUE(small.ok) << small.error;
  TrajectoryObjective objective = MakeObjective(small);
  const double scale = CostScale(objective);
  auto skipped = [&](const std::vector<std::string>& fitted, const fem::PhysicalParameters& start) {
    Result<FlightStageResult> flight =
        MeasureLaunchInFlight(objective, fitted, start, scale, nullptr);
    EXPECT_TRUE(flight.ok()) << flight.status().ToString();
    EXPECT_TRUE(flight->held.empty());
    EXPECT_EQ(flight->parameters.initial_velocity, start.initial_velocity);
    return flight->skipped;
  };
  EXPECT_EQ(skipped({"youngs_modulus"}, small.truth), "no launch parameter is fitted");
  EXPECT_EQ(skipped({"initial_velocity"}, small.truth), "only the launch is fitted");
  fem::PhysicalParameters floorless = small.truth;
  floorless.ground.reset();
  EXPECT_EQ(skipped({"youngs_modulus", "initial_velocity"}, floorless), "there is no ground");
  // Released 5 mm above the floor and thrown down at 1 m/s, the ball lands within the first frame.
  fem::PhysicalParameters thrown_down = small.truth;
  thrown_down.ground->offset = 0.215;
  thrown_down.initial_velocity = Eigen::Vector3d(0.0, 0.0, -1.0);
  EXPECT_NE(skipped({"youngs_modulus", "initial_velocity"}, thrown_down)
                .find("touches the ground after 0 fitted frames of flight"),
            std::string::npos);
  // With gravity and both drags fitted along, 5 flight frames are needed.
  fem::PhysicalParameters low = small.truth;
  low.ground->offset = 0.2;  // 2 cm below the ball: lands after frame 3 (65 ms)
  EXPECT_NE(
      skipped({"youngs_modulus", "initial_velocity", "gravity", "drag_linear", "drag_quadratic"},
              low)
          .find("(5 are needed)"),
      std::string::npos);

  testing::SmallCapture bar = testing::MakeSmallCapture("bar-hanging", 0.1, 1);
  ASSERT_TRUE(bar.ok) << bar.error;
  fem::SimulationOptions options;
  options.cells_along_longest_side = 8;
  TrajectoryObjective clamped(bar.mesh, bar.capture.fixed_region, bar.truth, options, {},
                              bar.frames, bar.capture.fps, kSubsteps);
  fem::PhysicalParameters bar_start = bar.truth;
  bar_start.ground = fem::GroundPlane{};
  Result<FlightStageResult> flight = MeasureLaunchInFlight(
      clamped, {"youngs_modulus", "initial_velocity"}, bar_start, scale, nullptr);
  ASSERT_TRUE(flight.ok());
  EXPECT_EQ(flight->skipped, "the body is clamped");
}

// The ball's bounces fitted with its stiffness damping left out (0 where the truth is 0.02 s): the
// fit holds the launch its flight frames measured, whatever the bounces' misfit would pull it to,
// and says so in the result.
TEST(FlightStage, AFitHoldsTheLaunchItMeasuredInFlight) {
  testing::SmallCapture small = testing::MakeSmallCapture("ball-bounce", 0.45, 1);
  ASSERT_TRUE(small.ok) << small.error;
  JobConfig config = testing::YoungsModulusConfig(small.truth, /*starts=*/1, /*max_iterations=*/10);
  config.fit = {"youngs_modulus", "initial_velocity"};
  config.initial["youngs_modulus"] =
      InitialValue{.value = 1.5 * small.truth.youngs_modulus, .range = std::nullopt};
  config.fixed.erase("initial_velocity");
  config.fixed["stiffness_damping"] = 0.0;
  Result<FitResult> held = Fit(small.capture, config);
  ASSERT_TRUE(held.ok()) << held.status().ToString();
  const StartResult& best = held->Best();
  ASSERT_TRUE(best.flight.has_value());
  ASSERT_TRUE(best.flight->skipped.empty()) << best.flight->skipped;
  EXPECT_EQ(best.final.initial_velocity, best.flight->parameters.initial_velocity);
  EXPECT_LT((best.final.initial_velocity - small.truth.initial_velocity).norm(), 2e-3);
  EXPECT_NE(best.final.youngs_modulus, best.initial.youngs_modulus);
  const nlohmann::json json = ToJson(*held);
  EXPECT_EQ(json["starts"][0]["flight"]["held"], nlohmann::json::array({"initial_velocity"}));
  EXPECT_EQ(json["parameters"]["initial_velocity"]["value"][0].get<double>(),
            best.flight->parameters.initial_velocity.x());

  config.solver.launch_from_flight = false;
  Result<FitResult> free = Fit(small.capture, config);
  ASSERT_TRUE(free.ok()) << free.status().ToString();
  EXPECT_FALSE(free->Best().flight.has_value());
  EXPECT_TRUE(ToJson(*free)["starts"][0]["flight"].is_null());
  std::printf(
      "launch held from flight %.4f %.4f %.4f (E %.5g); fitted over every frame %.4f %.4f "
      "%.4f (E %.5g); truth 0.4 0 0 (E %.5g)\n",
      best.final.initial_velocity.x(), best.final.initial_velocity.y(),
      best.final.initial_velocity.z(), best.final.youngs_modulus,
      free->Best().final.initial_velocity.x(), free->Best().final.initial_velocity.y(),
      free->Best().final.initial_velocity.z(), free->Best().final.youngs_modulus,
      small.truth.youngs_modulus);
}

}  // namespace
}  // namespace softid::inverse
