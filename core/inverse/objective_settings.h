// The simulation and cost settings a job's solver options imply. Everything that builds a
// TrajectoryObjective for a job (the fit, the identifiability analysis, the diagnosis) takes them
// from here, so that all of them see the same cost function.
#pragma once

#include <memory>
#include <vector>

#include "core/capture/capture.h"
#include "core/common/status.h"
#include "core/cost/sparse_surface_cost.h"
#include "core/fem/simulation_options.h"
#include "core/inverse/job_config.h"
#include "core/inverse/observed_frames.h"

namespace softid::inverse {

// Grid resolution from solver.cells / solver.cell_size_m, the integrator from
// solver.rho_infinity, with a grid padding wide enough for the cost's band and truncation
// (SurfaceCostOptions::band_cells); everything else at its default. time_step is set by
// TrajectoryObjective from the capture's fps and solver.substeps.
fem::SimulationOptions SimulationOptionsFor(const SolverOptions& solver);

// solver.cost as the cost's options.
cost::SurfaceCostOptions CostOptionsFor(const SolverOptions& solver);

// The scale a fit's optimiser sees its cost in: phi_max^2, the cost's truncation distance
// (solver.cost.truncation_cells cells of size cell_size_m) squared [m^2].
double CostScaleM2(const SolverOptions& solver, double cell_size_m);

// The capture frames config.frames selects, with config.heldout_every's frames marked held out,
// shared read-only by objectives (the fit's starts, the analyses after it). Errors as
// LoadObservedFrames.
Result<std::shared_ptr<const std::vector<ObservedFrame>>> LoadFittedFrames(
    const capture::Capture& capture, const JobConfig& config);

}  // namespace softid::inverse
