// Fitting physical parameters to a capture: several starts of Ceres' line-search minimiser
// (L-BFGS, Wolfe line search) over the ParameterSpace variables, each minimising a
// TrajectoryObjective, run in parallel; the best start is the result and every start is kept.
// With SolverOptions::refine_iterations > 0 each start then continues with Levenberg-Marquardt on
// the cost's least-squares form (least_squares_refinement.h).
//
// The result's JSON (`ToJson(FitResult)`) is the public result.json schema, also returned by the
// service:
//   {"format": "softid-result/1",
//    "parameters": {"youngs_modulus": {"value": 2.1e4, "unit": "Pa", "initial": 1e4}, ...},
//    "cost": {"initial": .., "final": .., "heldout_initial": .., "heldout_final": ..},
//    "iterations": .., "converged": .., "termination": "..",
//    "starts": [{"index": 0, "parameters": {..}, "cost": {..}, "iterations": .., ...,
//                "stages": [{"last_frame": 14, "iterations": 5, "cost": {..}, ..}, ..],
//                "refinement": null | {"method": "levenberg_marquardt", "iterations": ..,
//                                      "cost": {..}, "converged": .., ..}}, ...],
//    "cost_history": [..],           // best start: cost after each of its iterations [m^2]
//    "cost_history_last_frame": [..],  // the last frame that cost is over (continuation stages
//                                      // fit a prefix of the frames; see StartResult)
//    "fixed": {..},                  // every parameter the fit did not change, public JSON
//    "grid": {"cells": 16, "cell_size_m": .., "element": "..", "orientation": "world" | "body",
//             "turned_deg": .., "selection": {..}},  // selection when "auto"
//    "time_step": {"substeps": 4, "selection": {..}},  // selection: when chosen ("auto")
//    "timing": {"total_seconds": .., "evaluations": .., "ms_per_forward_adjoint_step": .., ..}}
// Vectors are arrays and the ground plane is {"normal": [..], "offset": ..}.
#pragma once

#include <atomic>
#include <functional>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/capture/capture.h"
#include "core/common/status.h"
#include "core/fem/physical_parameters.h"
#include "core/geometry/triangle_mesh.h"
#include "core/inverse/flight_stage.h"
#include "core/inverse/frame_loss.h"
#include "core/inverse/grid_selection.h"
#include "core/inverse/job_config.h"
#include "core/inverse/observed_frames.h"
#include "core/inverse/time_step_selection.h"

namespace softid::inverse {

// One line of live progress (called from the worker threads, serialised by the fit).
struct FitProgress {
  int start = 0;  // index of the start reporting
  int num_starts = 1;
  // Completed iterations of this start (L-BFGS over every stage, then refinement): each start
  // reports 0 (its starting point) and then every iteration 1, 2, ... once.
  int iteration = 0;
  int max_iterations = 0;              // max_iterations + refine_iterations of the config
  double cost = 0.0;                   // [m^2]
  double gradient_norm = 0.0;          // max norm, optimiser variables
  fem::PhysicalParameters parameters;  // current values
  double elapsed_seconds = 0.0;        // since the fit began
  double remaining_seconds = 0.0;      // estimate for the whole fit
  // Continuation over the horizon (SolverOptions::continuation): the stage running (0-based) and
  // the last capture frame it fits; `cost` is over the stage's frames. One stage without it.
  int stage = 0;
  int num_stages = 1;
  int horizon_frame = 0;
  // Time steps this start has simulated so far, and those whose Newton iteration hit its limit
  // (a state that depends on the iteration path; should stay 0).
  long long simulation_steps = 0;
  long long unconverged_steps = 0;
};

struct FitCheckpoint;  // fit_checkpoint.h

struct FitOptions {
  std::function<void(const FitProgress&)> on_progress;  // optional
  // Checked every iteration; a set flag stops every start (the result then says "cancelled").
  const std::atomic<bool>* cancel = nullptr;
  // Called (serialised) with everything finished so far: once the grid and time step are chosen,
  // then after every start that ran to its end. What a caller saves to resume the fit later
  // (fit_checkpoint.h). Optional.
  std::function<void(const FitCheckpoint&)> on_checkpoint;
  // A checkpoint of this fit (same capture and config) to resume from: its grid and time step
  // are used as chosen and its finished starts are kept, not run again. InvalidArgument when its
  // number of starts differs from the config's. Not owned; null: a fresh fit.
  const FitCheckpoint* resume_from = nullptr;
  // Only these starts run (indices < the config's starts; empty: every start), e.g. one task of
  // a fit whose starts run on several workers; the others stay empty (evaluations 0) unless the
  // checkpoint finished them. InvalidArgument naming an index out of range.
  std::vector<int> only_starts;
};

// One stage of a start's continuation over the horizon.
struct HorizonStageResult {
  int last_frame = 0;  // last capture frame fitted in the stage
  int iterations = 0;
  double initial_cost = 0.0, final_cost = 0.0;  // over the stage's fitted frames [m^2]
  std::string termination;                      // Ceres' message
};

// A start's Levenberg-Marquardt refinement (SolverOptions::refine_iterations).
struct RefinementResult {
  int iterations = 0;
  double initial_cost = 0.0, final_cost = 0.0;  // over every fitted frame [m^2]
  bool converged = false;
  std::string termination;                      // Ceres' message, or why it could not run
  int evaluations = 0, failed_evaluations = 0;  // forward runs
};

struct StartResult {
  int index = 0;
  fem::PhysicalParameters initial, final;
  double initial_cost = 0.0, final_cost = 0.0;                  // [m^2]
  double initial_heldout_cost = 0.0, final_heldout_cost = 0.0;  // [m^2]
  int iterations = 0;
  bool converged = false;
  std::string termination;  // Ceres' message, or why the start failed
  bool failed = false;      // the start could not be evaluated at all (e.g. diverged at the start)
  // SolverOptions::max_seconds ended the start's iterations: Ceres' limit, or the next iteration
  // (as long as its longest so far) would have ended past it.
  bool stopped_at_time_limit = false;
  // The cost after each iteration of this start, in order: every continuation stage's, then the
  // refinement's; one entry per ITERATION progress report after the start's iteration 0, so its
  // size is iterations + refinement->iterations [m^2]. An entry is over the capture frames up to
  // cost_history_last_frame (a continuation stage fits a prefix, so entries of different stages
  // are not comparable).
  std::vector<double> cost_history;
  std::vector<int> cost_history_last_frame;
  // The entries of cost_history over every fitted frame (the last stage's and the
  // refinement's), which compare with initial_cost and final_cost.
  std::vector<double> CostHistoryOverEveryFrame() const;
  std::vector<HorizonStageResult> stages;      // the last one fits every frame
  std::optional<RefinementResult> refinement;  // when SolverOptions::refine_iterations > 0
  // The launch measured on the flight frames and then held (SolverOptions::launch_from_flight),
  // or why not; absent when the option is off or no launch parameter is fitted.
  std::optional<FlightStageResult> flight;
  int evaluations = 0, failed_evaluations = 0;
  double seconds = 0.0, forward_seconds = 0.0, backward_seconds = 0.0;
  long long steps = 0;  // simulation steps run, over all evaluations
  // Of those, steps whose Newton iteration stopped short of its tolerance: the cost is not smooth
  // where this is large (the trajectory depends on the iteration path).
  long long unconverged_steps = 0;
};

struct FitResult {
  std::vector<std::string> fitted;  // canonical names
  fem::PhysicalParameters base;     // fixed values and defaults
  std::vector<StartResult> starts;
  int best = -1;  // index into starts
  bool cancelled = false;
  double total_seconds = 0.0;
  int substeps = 0;  // simulation steps per frame used (config's, or chosen when "auto")
  std::optional<SubstepSelection> substep_selection;  // when chosen
  // The last frame fitted when the frames after it were left out as unpredictable
  // (SolverOptions::predictable_frames_only); -1 when every configured frame was fitted.
  int predictable_last_frame = -1;
  // The grid used: cells along the longest side (config's, or chosen when "auto"; 0 when the
  // config gave cell_size) and the cell size h [m].
  int cells = 0;
  double cell_size_m = 0.0;
  std::optional<GridSelection> grid_selection;  // when chosen
  // The launch measured in flight that "auto" chose the grid and time step at
  // (discretisation_launch.h); absent when they were chosen at the starting launch or given.
  std::optional<FlightStageResult> discretisation_launch;
  fem::ElementFormulation element = fem::ElementFormulation::kIncompatibleModes;  // the config's
  // The config's grid orientation, and the grid's axes it gave (fem::ChooseGridAxes).
  fem::GridOrientation grid_orientation = fem::GridOrientation::kWorld;
  int cut_cell_samples = 1;  // the config's: distance samples per cut cell's edge
  Eigen::Matrix3d mesh_from_grid = Eigen::Matrix3d::Identity();
  // How the frames' costs added up (SolverOptions::cost.frame_loss, its scale from the depth
  // noise of frame 0, depth_noise_m [m]; 0 when least squares did not need it).
  FrameLoss frame_loss;
  double depth_noise_m = 0.0;

  const StartResult& Best() const { return starts.at(best); }
};

// The starting parameters of a capture under a config: defaults, density = mass / volume when the
// capture gives the mass, then config.fixed and plain initial values; a fitted ground plane
// without a start lies under the lowest observed point, normal against gravity.
Result<fem::PhysicalParameters> BaseParameters(const capture::Capture& capture,
                                               const geometry::TriangleMesh& mesh,
                                               const std::vector<ObservedFrame>& frames,
                                               const JobConfig& config);

// Runs the fit (config.diagnose is ignored: the diagnosis is core/diagnosis, run by callers).
// InvalidArgument naming the field for a config that does not fit the capture
// (frame range, density fitted although the capture gives the mass, ...). A start whose
// simulation diverges at its initial values is reported as failed; if every start fails the fit
// fails (FailedPrecondition).
Result<FitResult> Fit(const capture::Capture& capture, const JobConfig& config,
                      const FitOptions& options = {});

// The time-step check a fit of `config` runs with "substeps": "auto" (at the config's grid, the
// central start), alone: its trials, and the last frame the fit would compare under
// predictable_frames_only (-1: every frame). The diagnosis compares its models on a fixed coarse
// step, and leaves out what no step predicts with it.
struct TimeStepCheck {
  SubstepSelection selection;
  int predictable_last_frame = -1;
};
Result<TimeStepCheck> CheckTimeStep(const capture::Capture& capture, const JobConfig& config,
                                    const std::atomic<bool>* cancel = nullptr);

// `config` with the grid and the time step `fit` used in place of "auto", and frames.last at the
// last frame it compared where it left the unpredictable ones out (predictable_last_frame):
// analyses after a fit (uncertainty, the diagnosis' refits) must see the fit's own cost
// function, not choose again.
JobConfig WithFitDiscretisation(JobConfig config, const FitResult& fit);

// Public JSON of a parameter value: number, array, {"normal", "offset"} or the stiffness field.
nlohmann::json ParameterValueJson(const fem::PhysicalParameters& p, const std::string& name);
nlohmann::json ToJson(const FitResult& result);

}  // namespace softid::inverse
