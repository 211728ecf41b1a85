#include "core/inverse/objective_settings.h"

#include <algorithm>
#include <cmath>

namespace softid::inverse {

fem::SimulationOptions SimulationOptionsFor(const SolverOptions& solver) {
  fem::SimulationOptions simulation;
  simulation.cells_along_longest_side = solver.cells;
  simulation.cell_size = solver.cell_size_m;
  if (solver.rho_infinity != SolverOptions::kNewmark)
    simulation.UseGeneralizedAlpha(solver.rho_infinity);
  simulation.element = solver.element;
  simulation.grid_orientation = solver.grid_orientation;
  simulation.cut_cell_samples = solver.cut_cell_samples;
  // The band must fit in the padding, and the cost must be truncated where the grid cuts it off.
  simulation.padding_cells = std::max(
      {simulation.padding_cells, static_cast<int>(std::ceil(solver.cost.truncation_cells)) + 1,
       solver.cost.band_cells});
  return simulation;
}

double CostScaleM2(const SolverOptions& solver, double cell_size_m) {
  const double phi_max = solver.cost.truncation_cells * cell_size_m;
  return phi_max * phi_max;
}

cost::SurfaceCostOptions CostOptionsFor(const SolverOptions& solver) {
  cost::SurfaceCostOptions options;
  options.band_cells = solver.cost.band_cells;
  options.truncation_cells = solver.cost.truncation_cells;
  options.rest_sdf = solver.cost.rest_sdf;
  return options;
}

Result<std::shared_ptr<const std::vector<ObservedFrame>>> LoadFittedFrames(
    const capture::Capture& capture, const JobConfig& config) {
  SOFTID_ASSIGN_OR_RETURN(std::vector<ObservedFrame> frames,
                          LoadObservedFrames(capture, config.frames.first, config.frames.last));
  for (ObservedFrame& frame : frames) frame.heldout = config.IsHeldOut(frame.frame);
  return std::make_shared<const std::vector<ObservedFrame>>(std::move(frames));
}

}  // namespace softid::inverse
