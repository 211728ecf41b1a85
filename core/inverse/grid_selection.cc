#include "core/inverse/grid_selection.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <chrono>
#include <cmath>
#include <stdexcept>
#include <string>

#include "core/fem/hex_mesh.h"
#include "core/fem/simulator.h"
#include "core/geometry/signed_distance_field.h"
#include "core/inverse/surface_trajectory.h"

namespace softid::inverse {
namespace {

using Clock = std::chrono::steady_clock;

bool Cancelled(const std::atomic<bool>* cancel) {
  return cancel != nullptr && cancel->load(std::memory_order_relaxed);
}

double SecondsSince(Clock::time_point begin) {
  return std::chrono::duration<double>(Clock::now() - begin).count();
}

fem::SimulationOptions WithCells(fem::SimulationOptions simulation, int cells) {
  simulation.cells_along_longest_side = cells;
  simulation.cell_size = 0.0;
  return simulation;
}

Status CheckGridSelectionInputs(const GridSelectionOptions& options, double fps, int last_frame,
                                double depth_noise_m) {
  SOFTID_RETURN_IF_ERROR(options.Validate());
  if (!(depth_noise_m > 0.0) || !std::isfinite(depth_noise_m))
    return Status::InvalidArgument(fmt::format("depth_noise_m = {}: must be > 0", depth_noise_m));
  if (!(fps > 0.0)) return Status::InvalidArgument(fmt::format("fps = {}: must be > 0", fps));
  if (last_frame < 1) {
    return Status::InvalidArgument(
        fmt::format("last_frame = {}: need at least one frame after the first", last_frame));
  }
  return Status::Ok();
}

// The comparison of the runs on the grids of `cells` (coarse) and `finer_cells` (fine).
GridTrial CompareGrids(int cells, int finer_cells, const SurfaceRun& coarse, const SurfaceRun& fine,
                       const geometry::TriangleMesh& rest_mesh, double tolerance_m) {
  GridTrial trial;
  trial.cells = cells;
  trial.finer_cells = finer_cells;
  trial.grid_nodes = coarse.grid_nodes;
  trial.diverged = coarse.frames.empty() || fine.frames.empty();
  if (!trial.diverged) {
    const TrajectoryDifference difference = CompareTrajectories(
        coarse.frames, fine.frames, static_cast<int>(rest_mesh.vertices.size()));
    trial.difference_m = difference.difference_m;
    trial.worst_frame = difference.worst_frame;
    trial.frames_within_tolerance = difference.LeadingFramesWithin(tolerance_m);
    trial.per_frame_m = difference.per_frame_m;
  }
  return trial;
}

// Refines the grid through options.candidates (while affordable) until a grid and the next finer
// one agree within selection->tolerance_m; records every trial. Throws std::invalid_argument as
// SimulateSurfaceTrajectory.
Status RefineGridUntilConverged(const geometry::TriangleMesh& rest_mesh,
                                const std::optional<Eigen::AlignedBox3d>& fixed_region,
                                const fem::PhysicalParameters& parameters,
                                const fem::SimulationOptions& simulation, double fps,
                                int last_frame, const GridSelectionOptions& options,
                                GridSelection* selection) {
  auto run = [&](int cells) {
    return SimulateSurfaceTrajectory(rest_mesh, fixed_region, parameters,
                                     WithCells(simulation, cells), fps, last_frame,
                                     options.substeps, options.cancel);
  };
  SOFTID_ASSIGN_OR_RETURN(
      const std::vector<int> nodes,
      CandidateGridNodes(rest_mesh, simulation, fixed_region.has_value(), options));
  const auto begin = Clock::now();
  auto started = begin;
  selection->cells = options.candidates.front();
  SurfaceRun coarse = run(selection->cells);
  double last_run_s = coarse.seconds;
  for (size_t i = 1; i < nodes.size(); ++i) {
    const int finer_cells = options.candidates[i];
    if (nodes[i] > options.max_grid_nodes) {
      selection->untried_cells = finer_cells;
      selection->untried_grid_nodes = nodes[i];
      break;
    }
    // A run's time grows with the grid's nodes: the next one's is the last one's, scaled.
    const double next_run_s = last_run_s * nodes[i] / std::max(1, nodes[i - 1]);
    if (options.max_seconds > 0.0 && SecondsSince(begin) + next_run_s > options.max_seconds) {
      selection->stopped_at_time_limit = true;
      break;
    }
    SurfaceRun fine = run(finer_cells);
    last_run_s = fine.seconds;
    if (Cancelled(options.cancel)) return Status::Cancelled("the grid choice was cancelled");
    GridTrial trial = CompareGrids(selection->cells, finer_cells, coarse, fine, rest_mesh,
                                   selection->tolerance_m);
    trial.seconds = SecondsSince(started);
    started = Clock::now();
    selection->trials.push_back(trial);
    spdlog::info(
        "grid: {} vs {} cells along the longest side: surface differs by {:.3g} mm at frame {}, "
        "within tolerance on the first {} frames{}",
        trial.cells, trial.finer_cells, 1e3 * trial.difference_m, trial.worst_frame,
        trial.frames_within_tolerance, trial.diverged ? " (a run diverged)" : "");
    if (!trial.diverged && trial.difference_m <= selection->tolerance_m) {
      selection->within_tolerance = true;
      break;
    }
    selection->cells = finer_cells;
    coarse = std::move(fine);
  }
  if (Cancelled(options.cancel)) return Status::Cancelled("the grid choice was cancelled");
  selection->seconds_per_step = coarse.SecondsPerStep();  // coarse is the chosen grid's run
  return Status::Ok();
}

}  // namespace

Status GridSelectionOptions::Validate() const {
  if (candidates.empty()) return Status::InvalidArgument("candidates: must not be empty");
  for (size_t i = 0; i < candidates.size(); ++i) {
    if (candidates[i] < 2 || (i > 0 && candidates[i] <= candidates[i - 1])) {
      return Status::InvalidArgument(fmt::format(
          "candidates[{}] = {}: must be >= 2 and above the one before", i, candidates[i]));
    }
  }
  if (!(noise_fraction > 0.0) || !std::isfinite(noise_fraction))
    return Status::InvalidArgument(fmt::format("noise_fraction = {}: must be > 0", noise_fraction));
  if (!(min_tolerance_fraction >= 0.0) || !std::isfinite(min_tolerance_fraction)) {
    return Status::InvalidArgument(
        fmt::format("min_tolerance_fraction = {}: must be >= 0", min_tolerance_fraction));
  }
  if (max_grid_nodes < 1)
    return Status::InvalidArgument(
        fmt::format("max_grid_nodes = {}: must be >= 1", max_grid_nodes));
  if (substeps < 1)
    return Status::InvalidArgument(fmt::format("substeps = {}: must be >= 1", substeps));
  if (!(max_seconds >= 0.0) || !std::isfinite(max_seconds))
    return Status::InvalidArgument(fmt::format("max_seconds = {}: must be >= 0", max_seconds));
  return Status::Ok();
}

Result<GridSelection> SelectGrid(const geometry::TriangleMesh& rest_mesh,
                                 const std::optional<Eigen::AlignedBox3d>& fixed_region,
                                 const fem::PhysicalParameters& parameters,
                                 const fem::SimulationOptions& simulation, double fps,
                                 int last_frame, double depth_noise_m,
                                 const GridSelectionOptions& options) {
  SOFTID_RETURN_IF_ERROR(CheckGridSelectionInputs(options, fps, last_frame, depth_noise_m));
  GridSelection selection;
  selection.depth_noise_m = depth_noise_m;
  selection.tolerance_m =
      std::max(options.noise_fraction * depth_noise_m,
               options.min_tolerance_fraction * rest_mesh.Bounds().sizes().maxCoeff());
  try {
    SOFTID_RETURN_IF_ERROR(RefineGridUntilConverged(rest_mesh, fixed_region, parameters, simulation,
                                                    fps, last_frame, options, &selection));
  } catch (const std::invalid_argument& error) {
    return Status::InvalidArgument(error.what());
  }
  if (selection.stopped_at_time_limit) {
    spdlog::warn(
        "grid: {} cells along the longest side, the finest the time limit ({:.3g} s) let the "
        "choice compare; it was not shown to be within tolerance of a finer grid",
        selection.cells, options.max_seconds);
  } else if (!selection.within_tolerance) {
    const std::string why_not_finer =
        selection.untried_cells > 0
            ? fmt::format(
                  "the next candidate, {} cells, keeps {} grid nodes, above the budget of {}",
                  selection.untried_cells, selection.untried_grid_nodes, options.max_grid_nodes)
            : fmt::format("it is the finest candidate ({} cells)", options.candidates.back());
    spdlog::warn(
        "grid: {} cells along the longest side leave the surface {:.3g} mm from the next finer "
        "grid from frame {} on (tolerance {:.3g} mm: {} x the depth noise {:.3g} mm), and {}; the "
        "fit may be biased by the grid: see the result's discretisation_error",
        selection.cells,
        selection.trials.empty() ? 0.0 : 1e3 * selection.trials.back().difference_m,
        selection.trials.empty() ? 0 : selection.trials.back().frames_within_tolerance,
        1e3 * selection.tolerance_m, options.noise_fraction, 1e3 * depth_noise_m, why_not_finer);
  }
  return selection;
}

Result<int> CountGridNodes(const geometry::TriangleMesh& rest_mesh,
                           const fem::SimulationOptions& simulation, bool clamped, int cells) {
  const Eigen::Matrix3d mesh_from_grid = fem::ChooseGridAxes(rest_mesh, simulation, clamped);
  geometry::TriangleMesh turned = rest_mesh;
  for (Eigen::Vector3d& x : turned.vertices) x = mesh_from_grid.transpose() * x;
  geometry::SignedDistanceOptions options;
  options.cells_along_longest_side = cells;
  options.padding_cells = simulation.padding_cells;
  options.cut_cell_samples = simulation.cut_cell_samples;
  SOFTID_ASSIGN_OR_RETURN(const geometry::SignedDistanceField sdf,
                          geometry::ComputeSignedDistanceField(turned, options));
  return fem::BuildHexMesh(sdf, simulation.min_cell_volume_fraction).NumNodes();
}

Result<std::vector<int>> CandidateGridNodes(const geometry::TriangleMesh& rest_mesh,
                                            const fem::SimulationOptions& simulation, bool clamped,
                                            const GridSelectionOptions& options) {
  SOFTID_RETURN_IF_ERROR(options.Validate());
  std::vector<int> nodes;
  for (const int cells : options.candidates) {
    SOFTID_ASSIGN_OR_RETURN(const int count, CountGridNodes(rest_mesh, simulation, clamped, cells));
    nodes.push_back(count);
    if (count > options.max_grid_nodes) break;
  }
  return nodes;
}

double GridNodeEstimate(const Eigen::Vector3d& size, int cells) {
  const double h = size.maxCoeff() / std::max(1, cells);
  double nodes = 1.0;  // in doubles: no overflow for absurd inputs
  for (int a = 0; a < 3; ++a) nodes *= std::ceil(size[a] / h) + 1.0;
  return nodes;
}

nlohmann::json ToJson(const GridSelection& selection) {
  nlohmann::json trials = nlohmann::json::array();
  for (const GridTrial& t : selection.trials) {
    trials.push_back({{"cells", t.cells},
                      {"finer_cells", t.finer_cells},
                      {"grid_nodes", t.grid_nodes},
                      {"difference_m", t.difference_m},
                      {"worst_frame", t.worst_frame},
                      {"frames_within_tolerance", t.frames_within_tolerance},
                      {"per_frame_m", t.per_frame_m},
                      {"diverged", t.diverged},
                      {"seconds", t.seconds}});
  }
  return {{"cells", selection.cells},
          {"depth_noise_m", selection.depth_noise_m},
          {"tolerance_m", selection.tolerance_m},
          {"within_tolerance", selection.within_tolerance},
          {"stopped_at_time_limit", selection.stopped_at_time_limit},
          {"untried_cells", selection.untried_cells},
          {"untried_grid_nodes", selection.untried_grid_nodes},
          {"trials", trials}};
}

}  // namespace softid::inverse
