// Choosing the simulation grid of a fit from the capture itself (refinement), the spatial
// analogue of time_step_selection.h.
//
// A coarse grid makes the simulated object stiffer or softer than the continuum, and a fit then
// moves Young's modulus to make up for it: the grid's discretisation error becomes a parameter
// error. The selection simulates the object at its starting parameters on grids of increasing
// resolution and takes the coarsest whose surface trajectory agrees with the next finer one to
// within a fraction of the capture's depth noise (rest_frame_noise.h): finer grids would change
// the simulated surface by less than the camera can see. Grids above a node budget are not tried,
// so that the choice never makes a job unaffordable; the result then says the tolerance was not
// met.
#pragma once

#include <Eigen/Geometry>
#include <atomic>
#include <nlohmann/json.hpp>
#include <optional>
#include <vector>

#include "core/common/status.h"
#include "core/fem/physical_parameters.h"
#include "core/fem/simulation_options.h"
#include "core/geometry/triangle_mesh.h"

namespace softid::inverse {

struct GridSelectionOptions {
  // Candidate resolutions, cells along the longest side of the mesh, ascending, each >= 2. Steps of
  // about 1.5 x: each costs ~3.4 x the nodes of the one before.
  std::vector<int> candidates = {8, 12, 16, 24, 32, 48};
  // Accepted difference between a grid and the next finer: max over frames of the RMS distance
  // over surface vertices, as a fraction of the depth noise sigma [-], > 0. 0.5: a systematic
  // change of half the noise is visible in a fit over thousands of points, but smaller than the
  // spread of any one pixel.
  double noise_fraction = 0.5;
  // Floor of the accepted difference, as a fraction of the mesh's longest side [-], >= 0, for
  // noise-free captures whose sigma is the depth quantum.
  double min_tolerance_fraction = 1e-3;
  // Candidates whose grid keeps more nodes (CountGridNodes: the cells the body cuts, not its
  // bounding box) are not simulated [-], >= 1: a fit's time grows a little faster than its node
  // count (docs/benchmarks.md). A slim body keeps a small share of its box (the scanned bunny:
  // 4539 of 12500 at 24 cells), and its thin parts are what need the finer grid. 6000 admits 16
  // cells for a cube (4913), 24 for the torus (3592) and the bunny, 32 for the dragon (4117).
  int max_grid_nodes = 6000;
  // Steps per camera frame of the comparison runs [-], >= 1: fine enough that the time step does
  // not hide the grid's error.
  int substeps = 8;
  // Wall time of the choice [s], >= 0; 0 = no limit. A finer grid whose run would end past it
  // (the last run's time scaled by the nodes) is not simulated: the finest grid run so far is
  // taken, and the selection says so (a fit under SolverOptions::max_seconds keeps time to fit).
  double max_seconds = 0.0;
  // Checked every simulation step; when set, selection stops with StatusCode::kCancelled.
  const std::atomic<bool>* cancel = nullptr;

  // InvalidArgument naming the field and value.
  Status Validate() const;
};

struct GridTrial {
  int cells = 0;              // this grid
  int finer_cells = 0;        // compared with
  int grid_nodes = 0;         // of this grid
  double difference_m = 0.0;  // max over frames of the RMS surface distance [m]
  int worst_frame = 0;
  // Leading frames whose difference is within the tolerance (every frame: the trial passed).
  int frames_within_tolerance = 0;
  // Per frame 0..last: the RMS distance over the rest mesh's vertices [m] (empty: diverged). Where
  // the grids part says which frames the grid's error reaches, beyond the one worst frame.
  std::vector<double> per_frame_m;
  bool diverged = false;  // either run failed
  double seconds = 0.0;   // both runs
};

struct GridSelection {
  int cells = 0;  // the choice, cells along the longest side
  double depth_noise_m = 0.0;
  double tolerance_m = 0.0;
  bool within_tolerance = false;  // false: the finest affordable candidate, tolerance not met
  // GridSelectionOptions::max_seconds ended the refinement before a finer grid was tried.
  bool stopped_at_time_limit = false;
  // (No analogue of SubstepSelection::converging: a grid's difference does not shrink steadily
  // enough to tell chaos by. A ball bouncing: 0.66 then 0.83 mm at 6/9 and 9/13 cells, the cut
  // cells' fit to the surface changes with the grid; a block rocking chaotically: 22.5 then
  // 9.8 mm.)
  std::vector<GridTrial> trials;
  // The next finer candidate when the refinement stopped short of it because its grid keeps more
  // than GridSelectionOptions::max_grid_nodes (0: there was none, or it was not the reason).
  int untried_cells = 0;
  int untried_grid_nodes = 0;
  // The chosen grid's run's wall time per time step (at GridSelectionOptions::substeps) [s],
  // measured (0: unknown, e.g. read back from a checkpoint): a fit under a time limit scales its
  // evaluations' cost from it.
  double seconds_per_step = 0.0;
};

// @param depth_noise_m the capture's depth noise sigma [m], > 0 (EstimateRestFrameNoise).
// @param last_frame the last frame the fit compares (frames 0..last_frame are simulated), >= 1.
// `simulation`'s grid fields are replaced by each candidate's.
Result<GridSelection> SelectGrid(const geometry::TriangleMesh& rest_mesh,
                                 const std::optional<Eigen::AlignedBox3d>& fixed_region,
                                 const fem::PhysicalParameters& parameters,
                                 const fem::SimulationOptions& simulation, double fps,
                                 int last_frame, double depth_noise_m,
                                 const GridSelectionOptions& options = {});

nlohmann::json ToJson(const GridSelection& selection);

// The nodes fem::Simulator keeps (the cells the body cuts) on the grid of `cells` along the
// longest side of `rest_mesh`, with `simulation`'s grid options and axes (fem::ChooseGridAxes;
// a clamped body's grid is not shifted onto the clamp's faces here): one signed-distance field, no
// simulation. InvalidArgument as geometry::ComputeSignedDistanceField.
Result<int> CountGridNodes(const geometry::TriangleMesh& rest_mesh,
                           const fem::SimulationOptions& simulation, bool clamped, int cells);

// The nodes of a grid with `cells` along the longest side over a body's bounding box of `size`
// [m], computed without building the grid: an upper bound of the nodes the simulation keeps (a
// box's count; a slim body keeps far fewer, see CountGridNodes).
double GridNodeEstimate(const Eigen::Vector3d& size, int cells);

// CountGridNodes at options.candidates, ascending, up to and including the first above
// options.max_grid_nodes: the grids "auto" cells may simulate, and what they cost.
Result<std::vector<int>> CandidateGridNodes(const geometry::TriangleMesh& rest_mesh,
                                            const fem::SimulationOptions& simulation, bool clamped,
                                            const GridSelectionOptions& options = {});

}  // namespace softid::inverse
