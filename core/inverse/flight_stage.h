// The launch measured in flight: a start's launch velocities fitted on the frames before the body
// first touches the ground, then held while the rest is fitted over every frame.
//
// Why: before the first contact the body flies ballistically, a motion the model reproduces
// exactly whatever its stiffness (a body released at rest shape does not deform in free fall).
// After it, impact and sliding carry whatever the model gets wrong (another code's contact, a
// real floor), and over every frame the fit lets the launch velocity absorb that error: on a
// cube landing on a ramp from 1 cm (CalculiX capture, launch at rest) the fit found a downward
// launch of 0.10 m/s, which moves the body 5 mm in three frames of flight (10 x the depth noise),
// and paid for it with a Young's modulus 58 % low; with the launch held at its true value the
// modulus came out 7 % off. The flight frames alone measure the launch without that bias.
#pragma once

#include <atomic>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/fem/physical_parameters.h"

namespace softid::inverse {

class TrajectoryObjective;

struct FlightStageOptions {
  // Flight ends when a surface point comes this close to the ground, as a fraction of the body's
  // size L [-], > 0: beyond 0.5 % of L the smooth contact force (softplus of width 0.1 % of L by
  // default) is below e^-5 of its value at touch.
  double contact_distance_fraction = 5e-3;
  // Levenberg-Marquardt iterations on the flight frames [-], >= 1: the ballistic cost is nearly
  // quadratic in the launch, a few iterations converge.
  int max_iterations = 10;
  // The flight frames are found again at the measured launch (a faster or slower launch lands
  // earlier or later) at most this many times [-], >= 1.
  int max_rounds = 3;
};

// What a start's flight stage measured. `held` is empty when it did not run (see `skipped`).
struct FlightStageResult {
  std::vector<std::string> held;    // launch parameters held after it, canonical names
  std::vector<std::string> fitted;  // fitted on the flight frames (held ones and the pose)
  std::string skipped;              // why it did not run, empty when it ran
  int frames = 0;                   // fitted flight frames after t = 0
  int last_frame = -1;              // the last flight frame's index in the capture
  double contact_time_s = 0.0;      // first ground contact at the measured launch [s]
  double initial_cost = 0.0, final_cost = 0.0;  // over the flight frames [m^2]
  int iterations = 0;
  fem::PhysicalParameters parameters;  // the start with the measured launch
};

// Its report (every field but `parameters`), as in the result's "flight" and a checkpoint.
nlohmann::json ToJson(const FlightStageResult& result);
Result<FlightStageResult> FlightStageResultFromJson(const nlohmann::json& j);

// The launch parameters a fit of `fitted` measures in flight: initial_velocity and
// initial_angular_velocity, those fitted.
std::vector<std::string> LaunchParameters(const std::vector<std::string>& fitted);

// Active-frame count (a prefix of objective.frames()) of the frames observed before the first
// ground contact of a run at `parameters`, and that contact's time (infinity without one within
// the frames). Forward only, stops at the contact.
struct FlightFrames {
  int count = 0;
  double contact_time_s = 0.0;
};
Result<FlightFrames> FramesBeforeContact(TrajectoryObjective& objective,
                                         const fem::PhysicalParameters& parameters,
                                         const FlightStageOptions& options = {});

// The flight stage of a start at `start`: fits its fitted launch parameters (with what else moves
// the body in flight where fitted: the initial pose, gravity, air drag) on the frames before the
// first contact, by Levenberg-Marquardt
// with the cost in units of `scale` [m^2]. Skipped (result.held empty, result.skipped says why)
// when nothing of the launch is fitted, nothing else is (the launch is then all the fit has), the
// body is clamped or has no ground, it touches the ground within the first frames (too few flight
// frames: 2 after t = 0, one more for each of gravity, linear and quadratic drag fitted) or never.
// Leaves the objective's active frames at every frame. Errors only for a cancel or an internal
// failure; a flight fit that fails keeps the start (skipped).
Result<FlightStageResult> MeasureLaunchInFlight(TrajectoryObjective& objective,
                                                const std::vector<std::string>& fitted,
                                                const fem::PhysicalParameters& start, double scale,
                                                const std::atomic<bool>* cancel,
                                                const FlightStageOptions& options = {});

}  // namespace softid::inverse
