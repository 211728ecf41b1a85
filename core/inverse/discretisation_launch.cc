#include "core/inverse/discretisation_launch.h"

#include <spdlog/spdlog.h>

#include <stdexcept>

#include "core/inverse/grid_selection.h"
#include "core/inverse/objective_settings.h"
#include "core/inverse/trajectory_objective.h"

namespace softid::inverse {

ProvisionalDiscretisation ProvisionalDiscretisationFor(const JobConfig& config) {
  const GridSelectionOptions grid_defaults;
  ProvisionalDiscretisation out;
  out.cells =
      config.solver.cells == kAutoCells ? grid_defaults.candidates.front() : config.solver.cells;
  out.substeps =
      config.solver.substeps == kAutoSubsteps ? grid_defaults.substeps : config.solver.substeps;
  return out;
}

Result<std::optional<FlightStageResult>> MeasureLaunchForDiscretisation(
    const geometry::TriangleMesh& mesh, const std::optional<Eigen::AlignedBox3d>& fixed_region,
    const fem::PhysicalParameters& start, const fem::SimulationOptions& simulation,
    const JobConfig& config, const std::vector<std::string>& fitted,
    std::shared_ptr<const std::vector<ObservedFrame>> frames, double fps,
    const std::atomic<bool>* cancel) {
  const bool chooses = config.solver.cells == kAutoCells || config.solver.substeps == kAutoSubsteps;
  if (!chooses || !config.solver.launch_from_flight || LaunchParameters(fitted).empty())
    return std::optional<FlightStageResult>();
  const ProvisionalDiscretisation provisional = ProvisionalDiscretisationFor(config);
  fem::SimulationOptions options = simulation;
  if (config.solver.cell_size_m <= 0.0) options.cells_along_longest_side = provisional.cells;
  std::unique_ptr<TrajectoryObjective> objective;
  try {
    objective = std::make_unique<TrajectoryObjective>(mesh, fixed_region, start, options,
                                                      CostOptionsFor(config.solver),
                                                      std::move(frames), fps, provisional.substeps);
  } catch (const std::invalid_argument& e) {
    return Status::InvalidArgument(e.what());
  }
  objective->SetCancelFlag(cancel);
  const double scale = CostScaleM2(config.solver, objective->simulator().hex_mesh().CellSize());
  SOFTID_ASSIGN_OR_RETURN(FlightStageResult flight,
                          MeasureLaunchInFlight(*objective, fitted, start, scale, cancel));
  if (flight.held.empty()) {
    spdlog::info("grid and time step: chosen at the starting launch ({})", flight.skipped);
    return std::optional<FlightStageResult>();
  }
  const Eigen::Vector3d& v = flight.parameters.initial_velocity;
  const Eigen::Vector3d& w = flight.parameters.initial_angular_velocity;
  spdlog::info(
      "grid and time step: chosen at the launch measured in flight on frames 0-{} ({} cells, {} "
      "substeps): velocity [{:.4g}, {:.4g}, {:.4g}] m/s, spin [{:.4g}, {:.4g}, {:.4g}] rad/s",
      flight.last_frame, provisional.cells, provisional.substeps, v.x(), v.y(), v.z(), w.x(), w.y(),
      w.z());
  return std::optional<FlightStageResult>(std::move(flight));
}

}  // namespace softid::inverse
