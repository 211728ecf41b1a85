#include "core/inverse/flight_stage.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "core/inverse/least_squares_refinement.h"
#include "core/inverse/parameter_space.h"
#include "core/inverse/trajectory_objective.h"

namespace softid::inverse {
namespace {

bool Contains(const std::vector<std::string>& names, const std::string& name) {
  return std::find(names.begin(), names.end(), name) != names.end();
}

bool Touches(const fem::Simulator& simulator, const fem::GroundPlane& ground, double distance_m) {
  for (const Eigen::Vector3d& x : simulator.SurfacePositions()) {
    if (ground.SignedDistance(x) <= distance_m) return true;
  }
  return false;
}

// Fitted frames after t = 0 among the first `count` frames.
int FittedFlightFrames(const std::vector<ObservedFrame>& frames, int count) {
  int fitted = 0;
  for (int k = 0; k < count; ++k) fitted += !frames[k].heldout && frames[k].time > 0.0;
  return fitted;
}

FlightStageResult Skipped(const fem::PhysicalParameters& start, std::string why) {
  FlightStageResult result;
  result.parameters = start;
  result.skipped = std::move(why);
  return result;
}

// The flight stage's variables: the launch, and what moves the body in flight as well.
std::vector<std::string> FlightFitted(const std::vector<std::string>& fitted) {
  std::vector<std::string> out;
  for (const std::string& name : fitted) {
    if (name == "initial_velocity" || name == "initial_angular_velocity" ||
        name == "initial_pose" || name == "gravity" || name == "drag_linear" ||
        name == "drag_quadratic")
      out.push_back(name);
  }
  return out;
}

}  // namespace

nlohmann::json ToJson(const FlightStageResult& result) {
  nlohmann::json out = {{"held", result.held},
                        {"fitted", result.fitted},
                        {"frames", result.frames},
                        {"last_frame", result.last_frame},
                        {"iterations", result.iterations},
                        {"cost", {{"initial", result.initial_cost}, {"final", result.final_cost}}}};
  // Infinity has no JSON: a body that never lands has no contact time.
  out["contact_time_s"] = std::isfinite(result.contact_time_s)
                              ? nlohmann::json(result.contact_time_s)
                              : nlohmann::json(nullptr);
  if (!result.skipped.empty()) out["skipped"] = result.skipped;
  return out;
}

Result<FlightStageResult> FlightStageResultFromJson(const nlohmann::json& j) {
  try {
    FlightStageResult result;
    result.held = j.at("held").get<std::vector<std::string>>();
    result.fitted = j.at("fitted").get<std::vector<std::string>>();
    result.frames = j.at("frames").get<int>();
    result.last_frame = j.at("last_frame").get<int>();
    result.iterations = j.at("iterations").get<int>();
    result.initial_cost = j.at("cost").at("initial").get<double>();
    result.final_cost = j.at("cost").at("final").get<double>();
    result.contact_time_s = j.at("contact_time_s").is_null()
                                ? std::numeric_limits<double>::infinity()
                                : j.at("contact_time_s").get<double>();
    result.skipped = j.value("skipped", std::string());
    return result;
  } catch (const nlohmann::json::exception& e) {
    return Status::InvalidArgument(std::string("flight: ") + e.what());
  }
}

std::vector<std::string> LaunchParameters(const std::vector<std::string>& fitted) {
  std::vector<std::string> out;
  for (const std::string& name : fitted) {
    if (name == "initial_velocity" || name == "initial_angular_velocity") out.push_back(name);
  }
  return out;
}

Result<FlightFrames> FramesBeforeContact(TrajectoryObjective& objective,
                                         const fem::PhysicalParameters& parameters,
                                         const FlightStageOptions& options) {
  const std::vector<ObservedFrame>& frames = objective.frames();
  FlightFrames out{static_cast<int>(frames.size()), std::numeric_limits<double>::infinity()};
  if (!parameters.ground || frames.empty()) return out;
  fem::Simulator& simulator = objective.simulator();
  try {
    simulator.SetParameters(parameters);
  } catch (const std::invalid_argument& e) {
    return Status::InvalidArgument(e.what());
  }
  const double dt = simulator.options().time_step;
  const double distance = options.contact_distance_fraction * simulator.characteristic_length();
  const fem::GroundPlane& ground = *parameters.ground;
  if (Touches(simulator, ground, distance)) {
    out.contact_time_s = 0.0;
  } else {
    const double end = frames.back().time;
    for (int step = 1; (step - 1) * dt <= end; ++step) {
      if (simulator.Step().diverged) {
        return Status::FailedPrecondition(
            "the run at the start diverged in flight at t = " + std::to_string(step * dt) + " s");
      }
      // The body was clear of the ground at the end of the previous step.
      if (Touches(simulator, ground, distance)) {
        out.contact_time_s = (step - 1) * dt;
        break;
      }
    }
  }
  const double tolerance = 1e-9 * dt;
  out.count = static_cast<int>(std::count_if(frames.begin(), frames.end(), [&](const auto& f) {
    return f.time <= out.contact_time_s + tolerance;
  }));
  return out;
}

Result<FlightStageResult> MeasureLaunchInFlight(TrajectoryObjective& objective,
                                                const std::vector<std::string>& fitted,
                                                const fem::PhysicalParameters& start, double scale,
                                                const std::atomic<bool>* cancel,
                                                const FlightStageOptions& options) {
  const std::vector<std::string> launch = LaunchParameters(fitted);
  if (launch.empty()) return Skipped(start, "no launch parameter is fitted");
  if (launch.size() == fitted.size()) return Skipped(start, "only the launch is fitted");
  if (objective.simulator().num_fixed_nodes() > 0) return Skipped(start, "the body is clamped");
  if (!start.ground) return Skipped(start, "there is no ground");
  const std::vector<std::string> names = FlightFitted(fitted);
  // Two frames after t = 0 for the launch, one more for each acceleration fitted along.
  const int needed = 2 + Contains(names, "gravity") + Contains(names, "drag_linear") +
                     Contains(names, "drag_quadratic");
  const std::vector<ObservedFrame>& frames = objective.frames();
  const int all = static_cast<int>(frames.size());
  SOFTID_ASSIGN_OR_RETURN(
      ParameterSpace space,
      ParameterSpace::Create(names, start, objective.simulator().characteristic_length()));

  FlightStageResult result;
  result.fitted = names;
  result.parameters = start;
  int fitted_count = -1;  // active frames of the last flight fit
  for (int round = 0; round < options.max_rounds; ++round) {
    SOFTID_ASSIGN_OR_RETURN(FlightFrames flight,
                            FramesBeforeContact(objective, result.parameters, options));
    result.contact_time_s = flight.contact_time_s;
    if (flight.count == fitted_count) break;  // the measured launch lands as the fitted frames say
    if (flight.count == all) {
      return Skipped(start, "the body does not touch the ground within the frames");
    }
    const int flight_frames = FittedFlightFrames(frames, flight.count);
    if (flight_frames < needed) {
      return Skipped(start, "the body touches the ground after " + std::to_string(flight_frames) +
                                " fitted frames of flight (" + std::to_string(needed) +
                                " are needed)");
    }
    objective.SetActiveFrames(flight.count);
    std::vector<double> x = space.ToVariables(result.parameters);
    RefinementOptions refine;
    refine.max_iterations = options.max_iterations;
    refine.cancel = cancel;
    // Progress: on a fine grid at a short step one iteration (a Jacobian of central differences)
    // takes minutes.
    const auto round_begin = std::chrono::steady_clock::now();
    const int last_frame = frames[flight.count - 1].frame;
    refine.on_iteration = [&](int iteration, double cost, double) {
      spdlog::info(
          "flight: the launch on frames 0-{} (round {}), iteration {}/{}: cost {:.4e} m^2, "
          "{:.0f} s",
          last_frame, round + 1, iteration, options.max_iterations, cost,
          std::chrono::duration<double>(std::chrono::steady_clock::now() - round_begin).count());
    };
    Result<RefinementSummary> summary =
        RefineByLevenbergMarquardt({&objective}, space, result.parameters, scale, &x, refine);
    objective.SetActiveFrames(all);
    if (cancel != nullptr && cancel->load()) return Status::Cancelled("the fit was cancelled");
    if (!summary.ok()) {
      return Skipped(start, "the flight fit failed: " + summary.status().message());
    }
    if (round == 0) result.initial_cost = summary->initial_cost;
    result.final_cost = summary->final_cost;
    result.iterations += summary->iterations;
    result.parameters = space.ToParameters(x.data(), result.parameters);
    result.frames = flight_frames;
    result.last_frame = frames[flight.count - 1].frame;
    fitted_count = flight.count;
  }
  result.held = launch;
  return result;
}

}  // namespace softid::inverse
