// How a job's fit is computed: the discretisation, the optimiser and the cost, with documented
// defaults (the "how"; job_config.h holds the "what": which parameters, their starts and fixed
// values, the frames, and the reports asked for).
//
// In a job config's JSON these settings sit at the top level beside the job's specification (a
// public contract, job_config.h and docs/job-config.md); SolverOptionsFromJson reads only them.
#pragma once

#include <array>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string_view>

#include "core/common/status.h"
#include "core/cost/sparse_surface_cost.h"
#include "core/fem/hex_element.h"
#include "core/fem/simulation_options.h"
#include "core/inverse/frame_loss.h"

namespace softid::inverse {

// SolverOptions::substeps value meaning "choose by step doubling" ("auto" in JSON).
inline constexpr int kAutoSubsteps = 0;
// SolverOptions::cells value meaning "choose by refinement" ("auto" in JSON).
inline constexpr int kAutoCells = 0;

// How the optimiser obtains the gradient of the cost.
enum class GradientMethod {
  kAdjoint,           // exact, one backward pass through the simulation per evaluation
  kFiniteDifference,  // forward differences, one extra simulation per parameter; a cross-check
};
// "adjoint" | "finite_difference" (the JSON names).
const char* ToString(GradientMethod method);

// Settings of the depth cost (core/cost). Lengths are in grid cells h so that they follow the
// resolution of the simulation.
struct CostSettings {
  // Half-width of the narrow band around the simulated surface in which the cost's distance
  // field is computed [cells]; wider bands cost time, narrower ones lose points that are far off.
  int band_cells = 3;  // >= 1
  // Distances of observed points to the simulated surface are truncated at this many cells, so
  // outliers (background, sensor noise, missing geometry) cost a bounded amount instead of
  // dragging the fit [cells].
  double truncation_cells = 2.0;  // > 0, finite
  // How the cost evaluates the rest signed distance (sparse_surface_cost.h): "surface_fitted"
  // (default) interpolates nodal values refitted so that observations of the true motion cost
  // ~0 (the sampled distances leave a floor that biases fits: surface_fitted_sdf.h); "exact"
  // queries the distance to the rest surface itself (no floor, one closest-point query per
  // point); "sampled" interpolates the nodal distances (the paper's).
  cost::RestSdf rest_sdf = cost::RestSdf::kSurfaceFitted;
  // How the frames' costs add up (frame_loss.h): "squared" (least squares) or "cauchy" (each
  // frame counted by b log(1 + C_k / b), so that frames the model cannot reproduce count by their
  // relative change), with b = (frame_loss_noise_multiple x the capture's depth noise)^2 / 2.
  // Used by the fit and the analyses of its result (uncertainty, discretisation error); the
  // diagnosis compares models by least squares whatever this says.
  FrameLossKind frame_loss = FrameLossKind::kSquared;
  double frame_loss_noise_multiple = 2.0;  // > 0, finite [-]
  friend bool operator==(const CostSettings&, const CostSettings&) = default;
};

struct SolverOptions {
  // Grid resolution: cells along the longest side of the rest mesh's bounds, unless
  // cell_size_m > 0, or kAutoCells ("auto" in JSON, the default): chosen per capture by refinement
  // at the starting parameters until a finer grid moves the simulated surface by less than half
  // the depth noise (grid_selection.h), because the grid's discretisation error becomes a
  // parameter error.
  int cells = kAutoCells;  // [-], >= 2 or kAutoCells
  // Edge of a grid cell h [m]; > 0 overrides `cells`, 0 = absent (JSON "cell_size", not written
  // when 0).
  double cell_size_m = 0.0;
  // Simulation steps per camera frame: dt = 1 / (fps * substeps), or kAutoSubsteps ("auto" in
  // JSON, the default): chosen per capture by step doubling at the starting parameters (see
  // time_step_selection.h), because a too coarse step biases the fit (torus-drop against a
  // capture made at 16 substeps: 2 substeps at 60 fps put Young's modulus 33 % off, 4 substeps
  // 2.4-3.8 %).
  int substeps = kAutoSubsteps;  // [-], >= 1 or kAutoSubsteps
  // Time integration: generalized-alpha with this high-frequency spectral radius
  // (fem::SimulationOptions::UseGeneralizedAlpha), or kNewmark (absent from JSON): the default
  // Newmark parameters. Must match how the motion is best resolved, not how a capture was made.
  static constexpr double kNewmark = -1.0;
  double rho_infinity = kNewmark;  // [-], in [0, 1] or kNewmark
  // The grid's element (fem/hex_element.h): "trilinear" (the default) or "incompatible_modes",
  // which bends as the continuum does with few cells across a limb, where the trilinear element
  // is too stiff and biases Young's modulus low. Not yet the default: see docs/benchmarks.md,
  // "Element".
  fem::ElementFormulation element = fem::ElementFormulation::kTrilinear;
  // How the grid lies over the rest mesh (fem::SimulationOptions::grid_orientation): "body"
  // (turned to the body's flat faces when that aligns clearly more of its surface; a curved or
  // clamped body keeps the mesh's axes) or "world" (the mesh's own axes). "body" by default: on
  // the CalculiX blocks and cubes resting at 10-25 degrees to the world's axes it moved Young's
  // modulus from -2.0, -2.0, +9.0 % to -0.9, -0.9, +2.6 % of the reference (docs/benchmarks.md).
  fem::GridOrientation grid_orientation = fem::GridOrientation::kBody;
  // Distance samples per cell edge shaping the cut cells (fem::SimulationOptions::
  // cut_cell_samples): 1, 2, 4 or 8.
  int cut_cell_samples = fem::SimulationOptions().cut_cell_samples;

  // Independent optimisations from random starts (drawn from the initial ranges); the best result
  // wins. Contact-rich fits have local minima, so one start is rarely enough.
  int starts = 4;  // [-], >= 1
  // Cores the fit may use; 0 = std::thread::hardware_concurrency(). Starts run in parallel on
  // min(threads, starts) of them, and the cores they leave idle go to each start's simulation
  // (fem::SimulationOptions::threads): one start on 2 cores steps ~1.6x faster.
  int threads = 0;  // [-], >= 0
  // Seed of the random starts: the same seed and config give the same starts.
  std::uint64_t seed = 1;

  // Stopping criteria of the optimiser, with the meanings of Ceres' Solver::Options.
  int max_iterations = 50;            // [-], >= 1
  double function_tolerance = 1e-6;   // |cost change| / cost [-], > 0, finite
  double gradient_tolerance = 1e-10;  // max-norm of the projected gradient [-], > 0, finite
  double parameter_tolerance = 1e-8;  // |step| / (|x| + tolerance) [-], > 0, finite
  // Wall time of the fit [s], >= 0, finite; 0 = no limit. Counted from the call of Fit (the grid
  // and time-step choice included; on each worker from its own call when starts run on several),
  // each start stops before an iteration that would end later, judged by its longest iteration
  // so far plus, with held-out frames, two forward runs for their evaluation (else at its first
  // iteration that ends later: Ceres' max_solver_time_in_seconds), and keeps its best point; a
  // start begun past it stops after its first evaluation, and the refinement is skipped. A limit
  // makes the result depend on the machine's speed: for a time budget, not for reproducible fits.
  double max_seconds = 0.0;
  GradientMethod gradient = GradientMethod::kAdjoint;
  // Step of finite differences, relative, in the optimiser's (log) parameters: 1e-4 changes a
  // positive parameter by 0.01 %, above simulation noise yet small against its curvature.
  double finite_difference_step = 1e-4;  // [-], > 0, finite
  // Continuation over the horizon: each start first fits the frames up to shortly after the
  // simulation departs from the recording, then a prefix twice as long, and so on up to every
  // frame (fit.h). A bounce or a vibration seen over the whole sequence gives the cost a local
  // minimum wherever a wrong stiffness brings a later rebound back in phase (torus-drop: E at
  // 1.4x, 2.5x and 3.2x of the truth from starts in [0.1x, 10x]); the first impact alone
  // does not. false = every frame from the first iteration on.
  bool continuation = true;
  // Each start first fits its launch (initial_velocity, initial_angular_velocity, those fitted,
  // with initial_pose, gravity and air drag where fitted) on the frames before the body first
  // touches the ground, where the model's motion is exact ballistics, and then holds the launch
  // while it fits the rest over every frame (flight_stage.h). Over every frame the launch absorbs
  // what the model gets wrong in contact: a cube landing on a ramp from 1 cm (CalculiX capture)
  // fitted a downward launch of 0.10 m/s where it was released at rest, and a Young's modulus 58 %
  // low. Skipped, and said so in the result's "flight", where the body is clamped, has no ground,
  // never lands, or lands before 2 fitted frames after t = 0 (one more per acceleration fitted
  // along: gravity, each drag). false = the launch is fitted over every frame like any other
  // parameter.
  bool launch_from_flight = true;
  // With "substeps": "auto", where the time-step choice finds the motion chaotic after some
  // frames, fit only the leading frames in which it still converges with the step
  // (PredictableLastFrame, time_step_selection.h): an undamped block rocking on a floor, whose
  // late frames no step predicts. Over all 49 frames of CalculiX's fine block-drop capture (64
  // substeps) Young's modulus went 17 % low, over the 19 frames in which the step converges it
  // came out 2.0 % low; the friction cube's whole slide converges at 64 substeps and is kept.
  // The frames left out are in the result (time_step.predictable_last_frame). false = every
  // frame is fitted.
  bool predictable_frames_only = true;
  // After its L-BFGS stages, each start is refined by at most this many Levenberg-Marquardt
  // iterations on the least-squares form of the cost over every frame
  // (least_squares_refinement.h), which follows the curved valleys of coupled parameters that
  // L-BFGS creeps along. Each iteration costs 2 n + 1 forward runs for n optimiser variables.
  // 0 = no refinement.
  int refine_iterations = 0;  // [-], >= 0

  CostSettings cost;

  // InvalidArgument "<JSON field> = <value>: <requirement>" for the first field out of its range,
  // with the words the JSON parser uses, checked on the typed fields (no JSON round trip).
  Status Validate() const;

  friend bool operator==(const SolverOptions&, const SolverOptions&) = default;
};

// The top-level keys of a job config that belong to the solver options.
inline constexpr auto kSolverOptionKeys = std::to_array<std::string_view>({
    "cells",
    "cell_size",
    "substeps",
    "rho_infinity",
    "element",
    "grid_orientation",
    "cut_cell_samples",
    "starts",
    "threads",
    "seed",
    "max_iterations",
    "function_tolerance",
    "gradient_tolerance",
    "parameter_tolerance",
    "max_seconds",
    "gradient",
    "finite_difference_step",
    "continuation",
    "launch_from_flight",
    "predictable_frames_only",
    "refine_iterations",
    "cost",
});

// Reads the solver keys of a job config object (others are left to the caller, which rejects
// unknown ones); absent keys keep their defaults. Errors name the field and value as Validate's.
Result<SolverOptions> SolverOptionsFromJson(const nlohmann::json& job_config);
// Writes every solver key into `job_config` (an object), "cell_size" and "rho_infinity" only when
// set, so that SolverOptionsFromJson gives `options` back.
void WriteJson(const SolverOptions& options, nlohmann::json* job_config);

}  // namespace softid::inverse
