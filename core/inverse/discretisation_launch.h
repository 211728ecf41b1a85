// The launch a fit's "auto" grid and time step are chosen at.
//
// Why: both choices simulate the body at one set of parameters and compare runs (grid_selection.h,
// time_step_selection.h); the frames left out as unpredictable follow from the time step's. At
// the config's starting launch (at rest unless given) a thrown body is simulated falling from
// where it was released: a block thrown up at 0.6 m/s and spinning at 9 rad/s (CalculiX capture
// `tumble-throw`) then lands at frame 8 instead of about 20, the choices judge the wrong landing
// and its tumble, and the fit kept frames 0-19 (of which the last few carry contact) where at
// the measured launch step doubling converges up to frame 38. Measured in flight first
// (flight_stage.h) on a coarse provisional grid (free flight is rigid motion, which any grid
// reproduces), the choices see the motion the capture shows.
#pragma once

#include <Eigen/Geometry>
#include <atomic>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/fem/physical_parameters.h"
#include "core/fem/simulation_options.h"
#include "core/geometry/triangle_mesh.h"
#include "core/inverse/flight_stage.h"
#include "core/inverse/job_config.h"
#include "core/inverse/observed_frames.h"

namespace softid::inverse {

// The grid (cells along the longest side) and steps per frame of the provisional flight fit: the
// coarsest grid "auto" tries and the step its comparison runs at, or the config's own.
struct ProvisionalDiscretisation {
  int cells = 0;
  int substeps = 0;
};
ProvisionalDiscretisation ProvisionalDiscretisationFor(const JobConfig& config);

// The launch measured in flight from `start` on the provisional discretisation, when the config
// chooses its grid or time step ("auto"), measures launches in flight
// (SolverOptions::launch_from_flight) and fits a launch parameter; nullopt otherwise, or when the
// flight stage did not run (its result's `skipped` says why in the log). `fitted`: canonical
// names. Cancelled when `cancel` is set during it.
Result<std::optional<FlightStageResult>> MeasureLaunchForDiscretisation(
    const geometry::TriangleMesh& mesh, const std::optional<Eigen::AlignedBox3d>& fixed_region,
    const fem::PhysicalParameters& start, const fem::SimulationOptions& simulation,
    const JobConfig& config, const std::vector<std::string>& fitted,
    std::shared_ptr<const std::vector<ObservedFrame>> frames, double fps,
    const std::atomic<bool>* cancel);

}  // namespace softid::inverse
