#include "core/inverse/fit.h"

#include <ceres/ceres.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <mutex>
#include <random>
#include <thread>

#include "core/capture/capture.h"
#include "core/common/json_fields.h"
#include "core/geometry/grid_alignment.h"
#include "core/inverse/discretisation_launch.h"
#include "core/inverse/fit_checkpoint.h"
#include "core/inverse/flight_stage.h"
#include "core/inverse/horizon_continuation.h"
#include "core/inverse/least_squares_refinement.h"
#include "core/inverse/objective_settings.h"
#include "core/inverse/parameter_space.h"
#include "core/inverse/rest_frame_noise.h"
#include "core/inverse/trajectory_objective.h"

namespace softid::inverse {
namespace {

using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// The minimised function in the optimiser's variables: cost / phi_max^2 (dimensionless, so the
// tolerances mean the same for every object size and grid).
class CeresObjective : public ceres::FirstOrderFunction {
 public:
  CeresObjective(TrajectoryObjective* objective, const ParameterSpace* space,
                 const fem::PhysicalParameters* base, const JobConfig* config, double scale,
                 StartResult* stats)
      : objective_(objective),
        space_(space),
        base_(base),
        config_(config),
        scale_(scale),
        stats_(stats) {}

  int NumParameters() const override { return space_->NumVariables(); }

  bool Evaluate(const double* x, double* cost, double* gradient) const override {
    const bool adjoint = config_->solver.gradient == GradientMethod::kAdjoint;
    std::optional<double> value = EvaluateAt(x, gradient != nullptr && adjoint, gradient);
    if (!value) return false;
    *cost = *value;
    if (gradient != nullptr && !adjoint) {
      // Forward differences in the optimiser's variables (the Table 1 comparison row).
      const double step = config_->solver.finite_difference_step;
      std::vector<double> shifted(x, x + NumParameters());
      for (int i = 0; i < NumParameters(); ++i) {
        shifted[i] = x[i] + step;
        std::optional<double> moved = EvaluateAt(shifted.data(), false, nullptr);
        shifted[i] = x[i];
        if (!moved) return false;
        gradient[i] = (*moved - *value) / step;
      }
    }
    return true;
  }

 private:
  std::optional<double> EvaluateAt(const double* x, bool with_gradient, double* gradient) const {
    const fem::PhysicalParameters p = space_->ToParameters(x, *base_);
    ++stats_->evaluations;
    if (!p.Validate().ok()) {
      ++stats_->failed_evaluations;
      return std::nullopt;
    }
    Result<ObjectiveEvaluation> evaluation = objective_->Evaluate(p, with_gradient);
    if (!evaluation.ok() || evaluation->diverged) {
      ++stats_->failed_evaluations;
      return std::nullopt;
    }
    stats_->forward_seconds += evaluation->forward_seconds;
    stats_->backward_seconds += evaluation->backward_seconds;
    stats_->steps += evaluation->steps;
    stats_->unconverged_steps += evaluation->unconverged_steps;
    if (with_gradient) {
      space_->ChainGradient(evaluation->gradient, x, gradient);
      for (int i = 0; i < NumParameters(); ++i) gradient[i] /= scale_;
    }
    return evaluation->cost / scale_;
  }

  TrajectoryObjective* objective_;
  const ParameterSpace* space_;
  const fem::PhysicalParameters* base_;
  const JobConfig* config_;
  double scale_;
  StartResult* stats_;
};

// Shared progress of all starts: serialises the user's callback and estimates the time left.
class ProgressBoard {
 public:
  ProgressBoard(const FitOptions& options, const JobConfig& config, int num_starts, int threads)
      : options_(options),
        max_iterations_(config.solver.max_iterations + config.solver.refine_iterations),
        num_starts_(num_starts),
        threads_(threads),
        begin_(Clock::now()) {}

  void StartBegins() {
    std::lock_guard lock(mutex_);
    ++begun_;
  }

  void Report(int start, int iteration, double cost, double gradient_norm,
              const fem::PhysicalParameters& parameters, int stage, int num_stages,
              int horizon_frame, long long simulation_steps, long long unconverged_steps) {
    std::lock_guard lock(mutex_);
    ++iterations_done_;
    const double elapsed = SecondsSince(begin_);
    if (!options_.on_progress) return;
    FitProgress progress;
    progress.start = start;
    progress.num_starts = num_starts_;
    progress.iteration = iteration;
    progress.max_iterations = max_iterations_;
    progress.cost = cost;
    progress.gradient_norm = gradient_norm;
    progress.parameters = parameters;
    progress.stage = stage;
    progress.num_stages = num_stages;
    progress.horizon_frame = horizon_frame;
    progress.simulation_steps = simulation_steps;
    progress.unconverged_steps = unconverged_steps;
    progress.elapsed_seconds = elapsed;
    // Pessimistic: every running start uses all its iterations, pending ones too.
    const double per_iteration = elapsed / std::max(1, iterations_done_) * threads_;
    const int pending = num_starts_ - begun_;
    const double left_iterations =
        std::max(0, max_iterations_ - iteration) + double(pending) * max_iterations_ / threads_;
    progress.remaining_seconds = per_iteration * left_iterations;
    options_.on_progress(progress);
  }

 private:
  const FitOptions& options_;
  int max_iterations_, num_starts_, threads_;
  Clock::time_point begin_;
  std::mutex mutex_;
  int begun_ = 0;
  int iterations_done_ = 0;
};

// Where a start's iterations are: its stage of the continuation over the horizon.
struct StageInfo {
  int stage = 0, num_stages = 1;
  int last_frame = 0;         // last capture frame fitted in the stage
  int iterations_before = 0;  // completed in earlier stages
  bool first = true;          // the first stage solved: it reports the start's iteration 0
};

class IterationReporter : public ceres::IterationCallback {
 public:
  IterationReporter(int start, const double* x, const ParameterSpace* space,
                    const fem::PhysicalParameters* base, double scale, ProgressBoard* board,
                    const std::atomic<bool>* cancel, StageInfo stage, StartResult* stats,
                    std::function<bool(double)> out_of_budget)
      : start_(start),
        x_(x),
        space_(space),
        base_(base),
        scale_(scale),
        board_(board),
        cancel_(cancel),
        stage_(stage),
        stats_(stats),
        out_of_budget_(std::move(out_of_budget)) {}

  ceres::CallbackReturnType operator()(const ceres::IterationSummary& summary) override {
    const double cost = summary.cost * scale_;
    // Iteration 0 is the stage's starting point: reported once, for the first stage solved.
    if (summary.iteration > 0 || stage_.first) {
      if (summary.iteration > 0) {
        stats_->cost_history.push_back(cost);
        stats_->cost_history_last_frame.push_back(stage_.last_frame);
      }
      board_->Report(start_, stage_.iterations_before + summary.iteration, cost,
                     summary.gradient_max_norm, space_->ToParameters(x_, *base_), stage_.stage,
                     stage_.num_stages, stage_.last_frame, stats_->steps,
                     stats_->unconverged_steps);
    }
    if (cancel_ != nullptr && cancel_->load()) return ceres::SOLVER_ABORT;
    if (out_of_budget_(summary.iteration_time_in_seconds))
      return ceres::SOLVER_TERMINATE_SUCCESSFULLY;
    return ceres::SOLVER_CONTINUE;
  }

 private:
  int start_;
  const double* x_;
  const ParameterSpace* space_;
  const fem::PhysicalParameters* base_;
  double scale_;
  ProgressBoard* board_;
  const std::atomic<bool>* cancel_;
  StageInfo stage_;
  StartResult* stats_;
  std::function<bool(double)> out_of_budget_;  // after an iteration of the given seconds
};

// Whether the optimiser works with log(value): ranges of such parameters are sampled on a log
// scale.
bool IsLogScaled(const std::string& name) {
  const fem::ParameterInfo* parameter = fem::FindParameter(name);
  return parameter != nullptr && parameter->transform == fem::ParameterTransform::kLog;
}

// Starting parameters: start s draws every ranged parameter (log-uniform for positive
// quantities, uniform otherwise) from a generator seeded by (seed, s). Without ranges all starts
// would coincide, so there is one.
std::vector<fem::PhysicalParameters> DrawStarts(const JobConfig& config,
                                                const fem::PhysicalParameters& base) {
  bool any_range = false;
  for (const auto& [name, initial] : config.initial) any_range |= initial.range.has_value();
  const int count = any_range ? config.solver.starts : 1;
  std::vector<fem::PhysicalParameters> starts;
  for (int s = 0; s < count; ++s) {
    std::seed_seq seq{static_cast<unsigned>(config.solver.seed),
                      static_cast<unsigned>(config.solver.seed >> 32), static_cast<unsigned>(s)};
    std::mt19937_64 rng(seq);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    fem::PhysicalParameters p = base;
    for (const auto& [name, initial] : config.initial) {
      if (!initial.range) continue;
      double* value = fem::ScalarParameter(p, name);
      if (value == nullptr) continue;
      const double t = unit(rng);
      const double lo = initial.range->min, hi = initial.range->max;
      *value = IsLogScaled(name) && lo > 0.0 ? lo * std::pow(hi / lo, t) : lo + t * (hi - lo);
    }
    starts.push_back(p);
  }
  return starts;
}

// The starts' centre: ranged scalars at the middle of their range (geometric for log-scaled
// parameters). The time step is chosen here, at neither extreme of the random starts.
fem::PhysicalParameters CentralStart(const JobConfig& config, const fem::PhysicalParameters& base) {
  fem::PhysicalParameters p = base;
  for (const auto& [name, initial] : config.initial) {
    if (!initial.range) continue;
    double* value = fem::ScalarParameter(p, name);
    if (value == nullptr) continue;
    const double lo = initial.range->min, hi = initial.range->max;
    *value = IsLogScaled(name) && lo > 0.0 ? std::sqrt(lo * hi) : 0.5 * (lo + hi);
  }
  return p;
}

// Continuation over the horizon: intermediate stages only need to reach the basin of the next
// one, so they stop at a looser tolerance and share at most half of the iteration budget.
constexpr double kStageFunctionTolerance = 1e-4;
constexpr double kStageBudgetFraction = 0.5;
// L-BFGS's initial inverse Hessian scaled by the last curvature pair, gamma = s^T y / y^T y
// (Nocedal and Wright's usual choice), is left off, as in Ceres: one scalar cannot serve
// variables of very different sensitivity. Measured (2026-11-25): the teddy-sized job (gravity,
// E, alpha, beta) did better with it (E 0.3 % instead of 3.0 % off after 50 iterations, 67
// instead of 75 evaluations), but the diagnosis' drag-given-spin refit stopped at drag 0.42 and
// spin 3.1 rad/s instead of 0.6 and 4.0. One variable: the same either way.
constexpr bool kScaleLbfgsByCurvature = false;

// One start's run: what its stages share. `x` holds the optimiser's variables, updated in place.
struct StartRun {
  int index;
  TrajectoryObjective& objective;
  const ParameterSpace& space;
  const fem::PhysicalParameters& base;
  const JobConfig& config;
  const FitOptions& options;
  ProgressBoard& board;
  StartResult* result;
  double scale;  // phi_max^2 [m^2]: cost / scale is what the optimiser minimises
  std::vector<double> x;
  const std::vector<ObservedFrame>& frames;
  Clock::time_point fit_begin;  // of the whole fit, for SolverOptions::max_seconds

  double longest_iteration_s = 0.0;  // of this start so far
  bool stopped_for_time = false;     // an iteration would have ended past max_seconds

  bool Cancelled() const { return options.cancel != nullptr && options.cancel->load(); }
  // Seconds the start may still optimise (Ceres' default without a limit), at least a
  // millisecond: Ceres then stops after its first evaluation, at the stage's starting point.
  double SecondsLeft() const {
    if (config.solver.max_seconds <= 0.0)
      return ceres::GradientProblemSolver::Options().max_solver_time_in_seconds;
    if (stopped_for_time) return 1e-3;
    return std::max(1e-3, config.solver.max_seconds - SecondsSince(fit_begin));
  }
  bool OutOfTime() const {
    return stopped_for_time || (config.solver.max_seconds > 0.0 &&
                                SecondsSince(fit_begin) >= config.solver.max_seconds);
  }
  // After an iteration of `seconds`: whether one as long as the longest so far, and the held-out
  // evaluation after the start (two forward runs), would end past max_seconds. Ceres' own limit
  // lets the iteration under way finish, and one line search at 16 cells with friction took 3
  // minutes of a 10-minute diagnosis budget.
  bool NextIterationWouldOverrun(double seconds) {
    longest_iteration_s = std::max(longest_iteration_s, seconds);
    if (config.solver.max_seconds <= 0.0) return false;
    const bool any_heldout =
        std::any_of(frames.begin(), frames.end(), [](const ObservedFrame& f) { return f.heldout; });
    const double forward_run_s =
        result->evaluations > 0 ? result->forward_seconds / result->evaluations : 0.0;
    const double reserve = longest_iteration_s + (any_heldout ? 2.0 * forward_run_s : 0.0);
    stopped_for_time = SecondsSince(fit_begin) + reserve > config.solver.max_seconds;
    return stopped_for_time;
  }
};

// The stages, from the frame costs at the start (a start that cannot be simulated gets one
// stage, whose solver reports the failure). Sets *full_initial_cost when it evaluated the start.
std::vector<int> PlanHorizonStages(StartRun& run, std::optional<double>* full_initial_cost) {
  const int all_frames = static_cast<int>(run.frames.size());
  std::vector<int> stages = {all_frames};
  if (run.config.solver.continuation) {
    run.objective.SetActiveFrames(all_frames);
    Result<ObjectiveEvaluation> at_start =
        run.objective.Evaluate(run.space.ToParameters(run.x.data(), run.base), false);
    if (at_start.ok() && !at_start->diverged) {
      *full_initial_cost = at_start->cost;
      // Frames matching to 1 % of the truncation distance are matching, however noise-free.
      stages = HorizonStages(run.frames, at_start->frame_costs, 1e-4 * run.scale);
    }
  }
  return stages;
}

// L-BFGS settings of one stage: the last gets the iterations left and the job's tolerance.
ceres::GradientProblemSolver::Options StageSolverOptions(const JobConfig& config, bool last,
                                                         int used_iterations, int stage_budget) {
  ceres::GradientProblemSolver::Options solver;
  solver.line_search_direction_type = ceres::LBFGS;
  solver.line_search_type = ceres::WOLFE;
  solver.use_approximate_eigenvalue_bfgs_scaling = kScaleLbfgsByCurvature;
  solver.max_num_iterations = last ? std::max(1, config.solver.max_iterations - used_iterations)
                                   : stage_budget - used_iterations;
  solver.function_tolerance =
      last ? config.solver.function_tolerance
           : std::max(config.solver.function_tolerance, kStageFunctionTolerance);
  solver.gradient_tolerance = config.solver.gradient_tolerance;
  solver.parameter_tolerance = config.solver.parameter_tolerance;
  solver.logging_type = ceres::SILENT;
  solver.update_state_every_iteration = true;
  return solver;
}

// Solves stage `stage` by L-BFGS from run.x, records it in run.result->stages and returns its
// iterations.
int SolveStage(StartRun& run, const std::vector<int>& stages, size_t stage, int used_iterations,
               int stage_budget, ceres::GradientProblemSolver::Summary* summary) {
  const bool last = stage + 1 == stages.size();
  StartResult* result = run.result;
  run.objective.SetActiveFrames(stages[stage]);
  auto* function =
      new CeresObjective(&run.objective, &run.space, &run.base, &run.config, run.scale, result);
  ceres::GradientProblem problem(function);  // takes ownership
  StageInfo info{static_cast<int>(stage), static_cast<int>(stages.size()),
                 run.frames[stages[stage] - 1].frame, used_iterations, result->stages.empty()};
  IterationReporter reporter(
      run.index, run.x.data(), &run.space, &run.base, run.scale, &run.board, run.options.cancel,
      info, result, [&run](double seconds) { return run.NextIterationWouldOverrun(seconds); });
  ceres::GradientProblemSolver::Options solver =
      StageSolverOptions(run.config, last, used_iterations, stage_budget);
  solver.max_solver_time_in_seconds = run.SecondsLeft();
  solver.callbacks.push_back(&reporter);
  ceres::Solve(solver, problem, run.x.data(), summary);
  const int iterations = std::max(0, static_cast<int>(summary->iterations.size()) - 1);
  result->stages.push_back({info.last_frame, iterations, summary->initial_cost * run.scale,
                            summary->final_cost * run.scale, summary->message});
  return iterations;
}

// The continuation over the horizon: solves the stages in turn, intermediate ones only while
// their budget lasts. *summary is the last solved stage's; returns the iterations used.
int SolveStages(StartRun& run, const std::vector<int>& stages,
                ceres::GradientProblemSolver::Summary* summary) {
  int used_iterations = 0;
  const int stage_budget =
      static_cast<int>(kStageBudgetFraction * run.config.solver.max_iterations);
  for (size_t stage = 0; stage < stages.size(); ++stage) {
    const bool last = stage + 1 == stages.size();
    if (!last && used_iterations >= stage_budget) continue;
    used_iterations += SolveStage(run, stages, stage, used_iterations, stage_budget, summary);
    if (run.Cancelled()) break;
  }
  run.objective.SetActiveFrames(static_cast<int>(run.frames.size()));
  return used_iterations;
}

void RecordLbfgsOutcome(const ceres::GradientProblemSolver::Summary& summary, int used_iterations,
                        StartResult* result) {
  result->iterations = used_iterations;
  result->converged = summary.termination_type == ceres::CONVERGENCE;
  result->termination = summary.message;
  result->failed = summary.iterations.empty() || !std::isfinite(summary.initial_cost) ||
                   summary.termination_type == ceres::FAILURE;
}

RefinementOptions RefinementOptionsFor(const JobConfig& config, const FitOptions& options) {
  RefinementOptions refine;
  refine.max_iterations = config.solver.refine_iterations;
  refine.function_tolerance = config.solver.function_tolerance;
  refine.gradient_tolerance = config.solver.gradient_tolerance;
  refine.parameter_tolerance = config.solver.parameter_tolerance;
  refine.cancel = options.cancel;
  return refine;
}

// The refinement's record, its counts added to the start's.
RefinementResult RecordRefinement(const RefinementSummary& refined, StartResult* result) {
  RefinementResult record;
  record.iterations = refined.iterations;
  record.initial_cost = refined.initial_cost;
  record.final_cost = refined.final_cost;
  record.converged = refined.converged;
  record.termination = refined.termination;
  record.evaluations = refined.evaluations;
  record.failed_evaluations = refined.failed_evaluations;
  result->evaluations += refined.evaluations;
  result->failed_evaluations += refined.failed_evaluations;
  result->steps += refined.steps;
  result->unconverged_steps += refined.unconverged_steps;
  result->forward_seconds += refined.forward_seconds;
  return record;
}

// Levenberg-Marquardt after L-BFGS over every frame: keeps its point (and final cost in *summary)
// only where it did better.
void RefineStart(StartRun& run, int stage_count, int used_iterations,
                 ceres::GradientProblemSolver::Summary* summary) {
  StartResult* result = run.result;
  RefinementOptions refine = RefinementOptionsFor(run.config, run.options);
  refine.on_iteration = [&](int iteration, double cost, double gradient_norm) {
    result->cost_history.push_back(cost);
    result->cost_history_last_frame.push_back(run.frames.back().frame);
    run.board.Report(run.index, used_iterations + iteration, cost, gradient_norm,
                     run.space.ToParameters(run.x.data(), run.base), stage_count, stage_count + 1,
                     run.frames.back().frame, result->steps, result->unconverged_steps);
  };
  const std::vector<double> before = run.x;
  Result<RefinementSummary> refined =
      RefineByLevenbergMarquardt({&run.objective}, run.space, run.base, run.scale, &run.x, refine);
  RefinementResult record;
  if (refined.ok()) {
    record = RecordRefinement(*refined, result);
    // Ceres keeps the best point it accepted; a refinement that found nothing keeps L-BFGS's.
    if (refined->final_cost <= summary->final_cost * run.scale) {
      summary->final_cost = refined->final_cost / run.scale;
      result->converged = refined->converged || result->converged;
    } else {
      run.x = before;
    }
  } else {
    record.termination = refined.status().message();
    run.x = before;
  }
  result->refinement = std::move(record);
}

// The start's final parameters and costs over every frame.
void RecordFinalState(const StartRun& run, const ceres::GradientProblemSolver::Summary& summary,
                      size_t num_stages, const std::optional<double>& full_initial_cost) {
  StartResult* result = run.result;
  result->final = run.space.ToParameters(run.x.data(), run.base);
  // Converged without a single step: the gradient vanished at the start, i.e. nothing in the
  // fitted frames responds to the fitted parameters there (typically the simulated object misses
  // the observations, e.g. falls through where the recording shows a floor). Not a result.
  if (summary.termination_type == ceres::CONVERGENCE && result->iterations == 0) {
    result->failed = true;
    result->termination =
        "the cost does not change with the fitted parameters at the start values (" +
        summary.message +
        "): the fitted frames show nothing these parameters move; if the object touches a floor, "
        "give ground_plane in \"fixed\" or fit it";
  }
  result->initial_cost = full_initial_cost.value_or(summary.initial_cost * run.scale);
  if (num_stages == 1) result->initial_cost = summary.initial_cost * run.scale;
  result->final_cost = summary.final_cost * run.scale;
}

// Held-out frames: the costs they did not help to fit.
void RecordHeldoutCosts(StartRun& run) {
  StartResult* result = run.result;
  const bool any_heldout = std::any_of(run.frames.begin(), run.frames.end(),
                                       [](const ObservedFrame& f) { return f.heldout; });
  if (any_heldout && !result->failed) {
    Result<ObjectiveEvaluation> before = run.objective.Evaluate(result->initial, false);
    Result<ObjectiveEvaluation> after = run.objective.Evaluate(result->final, false);
    if (before.ok() && !before->diverged) result->initial_heldout_cost = before->heldout_cost;
    if (after.ok() && !after->diverged) result->final_heldout_cost = after->heldout_cost;
  }
}

// What a start optimises after its flight stage: every fitted parameter, or all but the launch
// measured in flight, about the start with that launch.
struct StartSpace {
  std::optional<ParameterSpace> held;  // set when the launch is held
  fem::PhysicalParameters base;
};

// The flight stage of a start (flight_stage.h) when the config asks for it; *result->flight
// records it. A failure skips it (after a cancel the stages stop at their first evaluation).
StartSpace MeasureLaunch(TrajectoryObjective& objective, const ParameterSpace& space,
                         const fem::PhysicalParameters& base, const JobConfig& config,
                         const FitOptions& options, double scale, StartResult* result) {
  StartSpace out{std::nullopt, base};
  if (!config.solver.launch_from_flight || LaunchParameters(space.names()).empty()) return out;
  // By least squares whatever the job's frame loss: the flight is rigid motion the model
  // reproduces to the noise, and a launch measured from rest needs least squares' wide basin (the
  // Cauchy loss is flat where every frame misfits: a launched block's launch came out at half its
  // speed, and its modulus at 10x).
  const FrameLoss loss = objective.frame_loss();
  objective.SetFrameLoss(FrameLoss{});
  Result<FlightStageResult> flight =
      MeasureLaunchInFlight(objective, space.names(), result->initial, scale, options.cancel);
  objective.SetFrameLoss(loss);
  if (!flight.ok()) {
    FlightStageResult skipped;
    skipped.skipped = flight.status().message();
    flight = std::move(skipped);
  }
  result->flight = *flight;
  if (flight->held.empty()) return out;
  std::vector<std::string> rest;
  for (const std::string& name : space.names()) {
    if (std::find(flight->held.begin(), flight->held.end(), name) == flight->held.end())
      rest.push_back(name);
  }
  Result<ParameterSpace> held =
      ParameterSpace::Create(rest, flight->parameters, objective.characteristic_length());
  if (!held.ok()) {
    result->flight->skipped = held.status().message();
    result->flight->held.clear();
    return out;
  }
  out.held = std::move(*held);
  out.base = flight->parameters;
  return out;
}

void RunStart(int index, const fem::PhysicalParameters& start, TrajectoryObjective& objective,
              const ParameterSpace& space, const fem::PhysicalParameters& base,
              const JobConfig& config, const FitOptions& options, ProgressBoard& board,
              Clock::time_point fit_begin, StartResult* result) {
  const auto begin = Clock::now();
  result->index = index;
  result->initial = space.ToParameters(space.ToVariables(start).data(), base);
  const double scale = CostScaleM2(config.solver, objective.simulator().hex_mesh().CellSize());
  const StartSpace start_space =
      MeasureLaunch(objective, space, base, config, options, scale, result);
  const ParameterSpace& run_space = start_space.held ? *start_space.held : space;
  StartRun run{.index = index,
               .objective = objective,
               .space = run_space,
               .base = start_space.base,
               .config = config,
               .options = options,
               .board = board,
               .result = result,
               .scale = scale,
               .x = run_space.ToVariables(start_space.held ? start_space.base : start),
               .frames = objective.frames(),
               .fit_begin = fit_begin};

  std::optional<double> full_initial_cost;
  const std::vector<int> stages = PlanHorizonStages(run, &full_initial_cost);
  ceres::GradientProblemSolver::Summary summary;
  const int used_iterations = SolveStages(run, stages, &summary);
  RecordLbfgsOutcome(summary, used_iterations, result);
  result->stopped_at_time_limit = run.OutOfTime();
  if (run.stopped_for_time) {
    result->termination =
        "stopped at the time limit: an iteration as long as the longest so far (" +
        std::to_string(run.longest_iteration_s) +
        " s) would end past max_seconds = " + std::to_string(config.solver.max_seconds) + " s";
  }
  const bool cancelled = run.Cancelled();
  if (config.solver.refine_iterations > 0 && !result->failed && !cancelled && !run.OutOfTime()) {
    RefineStart(run, static_cast<int>(stages.size()), used_iterations, &summary);
  }
  RecordFinalState(run, summary, stages.size(), full_initial_cost);
  RecordHeldoutCosts(run);
  result->seconds = SecondsSince(begin);
}

}  // namespace

std::vector<double> StartResult::CostHistoryOverEveryFrame() const {
  std::vector<double> out;
  if (cost_history_last_frame.empty()) return out;
  const int last =
      *std::max_element(cost_history_last_frame.begin(), cost_history_last_frame.end());
  for (size_t i = 0; i < cost_history.size(); ++i) {
    if (cost_history_last_frame[i] == last) out.push_back(cost_history[i]);
  }
  return out;
}

namespace {

nlohmann::json CostJson(double initial, double final) {
  return {{"initial", initial}, {"final", final}};
}

}  // namespace

namespace {

// What a fit of a capture under a config has before it chooses its discretisation and runs its
// starts.
struct FitSetup {
  geometry::TriangleMesh mesh;
  std::shared_ptr<const std::vector<ObservedFrame>> frames;
  fem::PhysicalParameters base;
  std::optional<ParameterSpace> space;
  std::vector<fem::PhysicalParameters> starts;
  int cores = 1;    // the fit's share of the machine
  int threads = 1;  // starts run at once
  fem::SimulationOptions simulation;
};

// The nominal frame (a multiple of 1 / fps) at or after the last observed frame's time: how far
// the grid and time-step choices simulate (the frame index itself when frames are evenly spaced).
int LastNominalFrame(const std::vector<ObservedFrame>& frames, double fps) {
  return static_cast<int>(std::ceil(frames.back().time * fps - 1e-9));
}

// The grid's orientation the fit's simulations take (fem::ChooseGridAxes), for the record.
void RecordGridAxes(const capture::Capture& capture, const geometry::TriangleMesh& mesh,
                    const JobConfig& config, const fem::SimulationOptions& simulation,
                    FitResult* result) {
  result->grid_orientation = config.solver.grid_orientation;
  result->mesh_from_grid = fem::ChooseGridAxes(mesh, simulation, capture.fixed_region.has_value());
}

// The wall time the grid and time-step choices of a fit may take together [s], 0 = no limit: half
// the fit's SolverOptions::max_seconds, so that a fit under a limit keeps time to iterate.
double DiscretisationSeconds(const SolverOptions& solver) {
  return solver.max_seconds > 0.0 ? 0.5 * solver.max_seconds : 0.0;
}

// The grid of the fit: config.solver.cells, or chosen by refinement (grid_selection.h) against the
// depth noise of frame 0 (rest_frame_noise.h) when "auto". Sets simulation's grid and result's
// record.
Status ChooseGrid(const capture::Capture& capture, const geometry::TriangleMesh& mesh,
                  const JobConfig& config, const fem::PhysicalParameters& start, int last_frame,
                  const std::atomic<bool>* cancel, fem::SimulationOptions* simulation,
                  FitResult* result) {
  result->element = config.solver.element;
  result->cut_cell_samples = config.solver.cut_cell_samples;
  RecordGridAxes(capture, mesh, config, *simulation, result);
  const double length = geometry::BoundsInGrid(mesh, result->mesh_from_grid).sizes().maxCoeff();
  if (config.solver.cell_size_m > 0.0) {
    result->cell_size_m = config.solver.cell_size_m;
    return Status::Ok();
  }
  result->cells = config.solver.cells;
  if (config.solver.cells == kAutoCells) {
    // Without points in frame 0 the noise is unknown; the depth quantum is the floor.
    Result<RestFrameNoise> noise = EstimateRestFrameNoise(capture, mesh);
    const double sigma = noise.ok() ? noise->sigma_m : DepthQuantisationSigma(capture);
    GridSelectionOptions grid_options;
    grid_options.cancel = cancel;
    grid_options.max_seconds = DiscretisationSeconds(config.solver);
    if (config.solver.substeps != kAutoSubsteps) grid_options.substeps = config.solver.substeps;
    SOFTID_ASSIGN_OR_RETURN(GridSelection selection,
                            SelectGrid(mesh, capture.fixed_region, start, *simulation, capture.fps,
                                       last_frame, std::max(sigma, 1e-9), grid_options));
    result->cells = selection.cells;
    result->grid_selection = std::move(selection);
  }
  simulation->cells_along_longest_side = result->cells;
  result->cell_size_m = length / result->cells;
  return Status::Ok();
}

// A time-step choice the time limit cut short takes at least the step the grid check compares
// at (GridSelectionOptions::substeps, within the grid's memory bound): its first run, 2 substeps,
// can be tens of percent off in Young's modulus, and the grid check's runs have shown the finer
// step affordable.
void TakeAtLeastTheGridChecksStep(SubstepSelection* selection) {
  if (!selection->stopped_at_time_limit) return;
  const int floor = std::min(GridSelectionOptions{}.substeps, selection->max_substeps);
  if (selection->substeps >= floor) return;
  spdlog::warn(
      "time step: {} substeps per frame taken instead of {}, the step the grid check "
      "compares at",
      floor, selection->substeps);
  selection->substeps = floor;
}

// The grid and time step of a fresh fit: as configured, or chosen (grid first) when "auto", at
// the central start with its launch measured in flight (discretisation_launch.h).
Status ChooseDiscretisation(const capture::Capture& capture, const FitSetup& setup,
                            const JobConfig& config, const std::atomic<bool>* cancel,
                            fem::SimulationOptions* simulation, FitResult* result) {
  const auto begin = Clock::now();
  const geometry::TriangleMesh& mesh = setup.mesh;
  fem::PhysicalParameters central = CentralStart(config, result->base);
  SOFTID_ASSIGN_OR_RETURN(
      result->discretisation_launch,
      MeasureLaunchForDiscretisation(mesh, capture.fixed_region, central, *simulation, config,
                                     setup.space->names(), setup.frames, capture.fps, cancel));
  if (result->discretisation_launch) central = result->discretisation_launch->parameters;
  const int last_frame = LastNominalFrame(*setup.frames, capture.fps);
  SOFTID_RETURN_IF_ERROR(
      ChooseGrid(capture, mesh, config, central, last_frame, cancel, simulation, result));
  result->substeps = config.solver.substeps;
  if (config.solver.substeps != kAutoSubsteps) return Status::Ok();
  SubstepSelectionOptions selection_options;
  selection_options.cancel = cancel;
  if (config.solver.max_seconds > 0.0) {
    // What the grid's choice left of the discretisation's share (the first run, at the coarsest
    // step, is made whatever is left).
    selection_options.max_seconds =
        std::max(1e-3, DiscretisationSeconds(config.solver) - SecondsSince(begin));
  }
  SOFTID_ASSIGN_OR_RETURN(SubstepSelection selection,
                          SelectSubsteps(mesh, capture.fixed_region, central, *simulation,
                                         capture.fps, last_frame, selection_options));
  TakeAtLeastTheGridChecksStep(&selection);
  result->substeps = selection.substeps;
  result->substep_selection = std::move(selection);
  return Status::Ok();
}

// The grid and time step a checkpoint of this fit chose. InvalidArgument when it cannot be this
// config's (another number of starts, grid or time step).
Status TakeDiscretisation(const FitCheckpoint& checkpoint, const JobConfig& config, int num_starts,
                          fem::SimulationOptions* simulation, FitResult* result) {
  const bool same_grid =
      config.solver.cell_size_m > 0.0
          ? checkpoint.cell_size_m == config.solver.cell_size_m
          : config.solver.cells == kAutoCells || checkpoint.cells == config.solver.cells;
  const bool same_time_step =
      config.solver.substeps == kAutoSubsteps || checkpoint.substeps == config.solver.substeps;
  if (checkpoint.num_starts != num_starts || !same_grid || !same_time_step) {
    return Status::InvalidArgument(
        "resume_from: the checkpoint (" + std::to_string(checkpoint.num_starts) + " starts, " +
        std::to_string(checkpoint.cells) + " cells, " + std::to_string(checkpoint.substeps) +
        " substeps) is not of this config (" + std::to_string(num_starts) + " starts)");
  }
  for (const StartResult& finished : checkpoint.finished) {
    if (finished.index < 0 || finished.index >= num_starts) {
      return Status::InvalidArgument("resume_from: finished start " +
                                     std::to_string(finished.index) + " does not exist");
    }
  }
  result->cells = checkpoint.cells;
  result->cell_size_m = checkpoint.cell_size_m;
  result->element = config.solver.element;
  result->cut_cell_samples = config.solver.cut_cell_samples;
  result->grid_selection = checkpoint.grid_selection;
  result->substeps = checkpoint.substeps;
  result->substep_selection = checkpoint.substep_selection;
  if (config.solver.cell_size_m <= 0.0) simulation->cells_along_longest_side = checkpoint.cells;
  return Status::Ok();
}

// The starts this call runs: options.only_starts (or every one), less those a checkpoint
// finished, in index order.
Result<std::vector<int>> StartsToRun(const FitOptions& options, int num_starts) {
  std::vector<int> wanted = options.only_starts;
  if (wanted.empty()) {
    for (int s = 0; s < num_starts; ++s) wanted.push_back(s);
  }
  std::sort(wanted.begin(), wanted.end());
  wanted.erase(std::unique(wanted.begin(), wanted.end()), wanted.end());
  std::vector<int> out;
  for (int s : wanted) {
    if (s < 0 || s >= num_starts) {
      return Status::InvalidArgument("only_starts: start " + std::to_string(s) +
                                     " does not exist (the config has " +
                                     std::to_string(num_starts) + " starts)");
    }
    if (options.resume_from == nullptr || !options.resume_from->IsFinished(s)) out.push_back(s);
  }
  return out;
}

FitCheckpoint CheckpointOf(const FitResult& result, int num_starts) {
  FitCheckpoint checkpoint;
  checkpoint.num_starts = num_starts;
  checkpoint.cells = result.cells;
  checkpoint.cell_size_m = result.cell_size_m;
  checkpoint.grid_selection = result.grid_selection;
  checkpoint.substeps = result.substeps;
  checkpoint.substep_selection = result.substep_selection;
  return checkpoint;
}

}  // namespace

JobConfig WithFitDiscretisation(JobConfig config, const FitResult& fit) {
  if (config.solver.cells == kAutoCells && fit.cells > 0) config.solver.cells = fit.cells;
  if (config.solver.substeps == kAutoSubsteps && fit.substeps > 0)
    config.solver.substeps = fit.substeps;
  if (fit.predictable_last_frame >= 0) config.frames.last = fit.predictable_last_frame;
  return config;
}

Result<fem::PhysicalParameters> BaseParameters(const capture::Capture& capture,
                                               const geometry::TriangleMesh& mesh,
                                               const std::vector<ObservedFrame>& frames,
                                               const JobConfig& config) {
  fem::PhysicalParameters base;
  if (capture.mass_kg) {
    if (config.IsFitted("density")) {
      return json::Invalid(
          "fit", "density",
          "cannot be fitted: the capture gives mass_kg = " + std::to_string(*capture.mass_kg));
    }
    if (config.fixed.contains("density")) {
      return json::Invalid(
          "fixed.density", config.fixed["density"],
          "conflicts with the capture's mass_kg = " + std::to_string(*capture.mass_kg));
    }
    const double volume = std::abs(geometry::SignedVolume(mesh));
    if (!(volume > 0.0)) {
      return Status::InvalidArgument("capture mesh encloses no volume: cannot turn mass_kg = " +
                                     std::to_string(*capture.mass_kg) + " into a density");
    }
    base.density = *capture.mass_kg / volume;
  }
  // A fitted ground plane without a start: normal against gravity, through the lowest point the
  // cameras saw.
  const bool ground_given =
      config.fixed.contains("ground") || (config.initial.count("ground_plane") > 0 &&
                                          config.initial.at("ground_plane").value.has_value());
  if (capture.floor && !ground_given) {
    // The floor the station measured starts (or, when not fitted, is) the ground.
    base.ground = fem::GroundPlane{capture.floor->normal, capture.floor->offset_m};
  } else if (config.IsFitted("ground_plane") && !ground_given) {
    const Eigen::Vector3d normal = -base.gravity.normalized();
    double lowest = std::numeric_limits<double>::infinity();
    for (const ObservedFrame& frame : frames) {
      for (const Eigen::Vector3d& p : frame.points) lowest = std::min(lowest, normal.dot(p));
    }
    for (const Eigen::Vector3d& v : mesh.vertices) lowest = std::min(lowest, normal.dot(v));
    base.ground = fem::GroundPlane{normal, lowest};
  }
  return ApplyToParameters(config, base);
}

namespace {

Result<FitSetup> SetUpFit(const capture::Capture& capture, const JobConfig& config) {
  SOFTID_RETURN_IF_ERROR(config.Validate());
  FitSetup setup;
  // config.diagnose is for the callers (core/diagnosis runs after the fit); the fit ignores it.
  SOFTID_ASSIGN_OR_RETURN(setup.mesh, capture::LoadCaptureMesh(capture));
  SOFTID_ASSIGN_OR_RETURN(setup.frames, LoadFittedFrames(capture, config));
  SOFTID_ASSIGN_OR_RETURN(setup.base, BaseParameters(capture, setup.mesh, *setup.frames, config));
  const double length = setup.mesh.Bounds().sizes().maxCoeff();
  SOFTID_ASSIGN_OR_RETURN(setup.space, ParameterSpace::Create(config.fit, setup.base, length));
  setup.starts = DrawStarts(config, setup.base);
  setup.cores = std::max(1, config.solver.threads > 0
                                ? config.solver.threads
                                : static_cast<int>(std::thread::hardware_concurrency()));
  setup.threads = std::clamp(setup.cores, 1, static_cast<int>(setup.starts.size()));
  setup.simulation = SimulationOptionsFor(config.solver);
  // Cores the concurrent starts leave idle go to their simulations: a single start on 2 cores
  // steps ~1.6x faster on both (softid-lab bench --threads). The count depends on the whole fit
  // only, never on which starts a call runs, so that every part of a fit computes the same.
  setup.simulation.threads = std::max(1, setup.cores / setup.threads);
  return setup;
}

// The grid and time step of the fit: those of the checkpoint resumed from, else chosen afresh.
Status DiscretiseFit(const capture::Capture& capture, const JobConfig& config,
                     const FitOptions& options, FitSetup* setup, FitResult* result) {
  const int num_starts = static_cast<int>(setup->starts.size());
  if (options.resume_from != nullptr) {
    RecordGridAxes(capture, setup->mesh, config, setup->simulation, result);
    return TakeDiscretisation(*options.resume_from, config, num_starts, &setup->simulation, result);
  }
  return ChooseDiscretisation(capture, *setup, config, options.cancel, &setup->simulation, result);
}

// The frame loss of the config (frame_loss.h), scaled by the depth noise of frame 0 (the depth
// quantum without points there).
void ChooseFrameLoss(const capture::Capture& capture, const geometry::TriangleMesh& mesh,
                     const JobConfig& config, FitResult* result) {
  const CostSettings& cost = config.solver.cost;
  if (cost.frame_loss == FrameLossKind::kSquared) return;
  Result<RestFrameNoise> noise = EstimateRestFrameNoise(capture, mesh);
  result->depth_noise_m = noise.ok() ? noise->sigma_m : DepthQuantisationSigma(capture);
  result->frame_loss =
      MakeFrameLoss(cost.frame_loss, cost.frame_loss_noise_multiple, result->depth_noise_m);
}

// Leaves out the frames after the motion turns chaotic (SolverOptions::predictable_frames_only)
// when the time-step choice found where: setup->frames keeps those up to the last predictable
// one, if at least two of them are fitted.
void KeepPredictableFrames(const JobConfig& config, double fps, FitSetup* setup,
                           FitResult* result) {
  if (!config.solver.predictable_frames_only || !result->substep_selection) return;
  const int last_frame = LastNominalFrame(*setup->frames, fps);
  const int last = PredictableLastFrame(*result->substep_selection, last_frame);
  if (last < 0) return;
  std::vector<ObservedFrame> kept;
  for (const ObservedFrame& frame : *setup->frames) {
    if (frame.time * fps <= last + 1e-9) kept.push_back(frame);
  }
  const auto fitted =
      std::count_if(kept.begin(), kept.end(), [](const ObservedFrame& f) { return !f.heldout; });
  if (fitted < 2) return;
  spdlog::warn(
      "fit: frames {}-{} left out: halving the time step no longer converges there (no affordable "
      "step predicts them; they would carry the step's error), so the fit compares frames up to {} "
      "only "
      "(\"predictable_frames_only\": false fits them all)",
      last + 1, last_frame, last);
  setup->frames = std::make_shared<const std::vector<ObservedFrame>>(std::move(kept));
  result->predictable_last_frame = last;
}

// An evaluation of the cost and its gradient costs a forward run and an adjoint one; the adjoint
// took 0.7-2.7 times the forward run's time in the fits of docs/benchmarks.md' independent
// captures, so two forward runs are a low estimate.
constexpr double kForwardRunsPerEvaluation = 2.0;

// The wall time of one evaluation over the fitted frames at the chosen grid and time step [s],
// scaled from the time per step the grid or time-step choice measured on that grid; 0 when
// neither ran (a given discretisation, a resumed fit).
double EstimatedEvaluationSeconds(const FitResult& result, const std::vector<ObservedFrame>& frames,
                                  double fps) {
  double seconds_per_step = 0.0;
  if (result.substep_selection) seconds_per_step = result.substep_selection->seconds_per_step;
  if (seconds_per_step <= 0.0 && result.grid_selection)
    seconds_per_step = result.grid_selection->seconds_per_step;
  const double steps = static_cast<double>(result.substeps) * LastNominalFrame(frames, fps);
  return kForwardRunsPerEvaluation * seconds_per_step * steps;
}

// DeadlineExceeded when the time the grid and time-step choices left of max_seconds cannot hold
// one evaluation at their choice: the fit would overrun its limit before its first step (a
// diagnosis' final refit of a friction cube took 257 s of 197 s that way).
Status CheckTimeForAnEvaluation(const JobConfig& config, double fps, const FitSetup& setup,
                                const FitResult& result, Clock::time_point fit_begin) {
  if (config.solver.max_seconds <= 0.0) return Status::Ok();
  const double needed_s = EstimatedEvaluationSeconds(result, *setup.frames, fps);
  const double left_s = config.solver.max_seconds - SecondsSince(fit_begin);
  if (needed_s <= 0.0 || needed_s <= left_s) return Status::Ok();  // unmeasured, or it fits
  return Status::DeadlineExceeded(fmt::format(
      "max_seconds = {:.4g}: one evaluation at {} cells and {} substeps per frame takes about "
      "{:.3g} s (scaled from the grid and time-step choices' runs), and they left {:.3g} s",
      config.solver.max_seconds, result.cells, result.substeps, needed_s, std::max(0.0, left_s)));
}

// The fit's checkpoint with the starts a resumed checkpoint finished, which also go into
// result->starts.
FitCheckpoint ResumedCheckpoint(const FitOptions& options, int num_starts, FitResult* result) {
  FitCheckpoint checkpoint = CheckpointOf(*result, num_starts);
  if (options.resume_from != nullptr) {
    for (const StartResult& finished : options.resume_from->finished) {
      result->starts[finished.index] = finished;
      checkpoint.finished.push_back(finished);
    }
  }
  return checkpoint;
}

// Runs the starts to_run on up to setup.threads threads (this one among them), each with its own
// objective, into result->starts; every start that finishes joins *checkpoint and is reported.
Status RunStarts(const capture::Capture& capture, const JobConfig& config,
                 const FitOptions& options, const FitSetup& setup,
                 const cost::SurfaceCostOptions& cost_options, const std::vector<int>& to_run,
                 Clock::time_point fit_begin, FitCheckpoint* checkpoint, FitResult* result) {
  const std::vector<fem::PhysicalParameters>& starts = setup.starts;
  std::mutex checkpoint_mutex;
  auto finished = [&](const StartResult& start) {
    std::lock_guard lock(checkpoint_mutex);
    checkpoint->finished.push_back(start);
    if (options.on_checkpoint) options.on_checkpoint(*checkpoint);
  };

  ProgressBoard board(options, config, static_cast<int>(starts.size()), setup.threads);
  for (size_t i = 0; i < starts.size() - to_run.size(); ++i) board.StartBegins();
  std::atomic<int> next_start{0};
  std::mutex error_mutex;
  Status error;
  auto worker = [&]() {
    std::unique_ptr<TrajectoryObjective> objective;
    try {
      objective = std::make_unique<TrajectoryObjective>(
          setup.mesh, capture.fixed_region, starts[0], setup.simulation, cost_options, setup.frames,
          capture.fps, result->substeps);
    } catch (const std::invalid_argument& e) {
      std::lock_guard lock(error_mutex);
      error = Status::InvalidArgument(e.what());
      return;
    }
    objective->SetCancelFlag(options.cancel);
    objective->SetFrameLoss(result->frame_loss);
    for (int next = next_start++; next < static_cast<int>(to_run.size()); next = next_start++) {
      if (options.cancel != nullptr && options.cancel->load()) break;
      const int s = to_run[next];
      board.StartBegins();
      RunStart(s, starts[s], *objective, *setup.space, result->base, config, options, board,
               fit_begin, &result->starts[s]);
      // A start stopped by a cancel did not finish: a resumed fit runs it again.
      if (options.cancel == nullptr || !options.cancel->load()) finished(result->starts[s]);
    }
  };
  if (!to_run.empty()) {
    // The simulations keep the thread count of the whole fit (above), so that a resumed fit
    // computes exactly what the uninterrupted one would have.
    const int pool_threads = std::min(setup.threads, static_cast<int>(to_run.size()));
    std::vector<std::jthread> pool;
    for (int t = 1; t < pool_threads; ++t) pool.emplace_back(worker);
    worker();
  }
  return error;
}

// Sets result->best to the start of least final cost among those that ran and did not fail.
void ChooseBestStart(FitResult* result) {
  for (size_t s = 0; s < result->starts.size(); ++s) {
    const StartResult& start = result->starts[s];
    if (start.failed || start.evaluations == 0) continue;
    if (result->best < 0 || start.final_cost < result->starts[result->best].final_cost)
      result->best = static_cast<int>(s);
  }
}

}  // namespace

Result<FitCheckpoint> PrepareFit(const capture::Capture& capture, const JobConfig& config,
                                 const std::atomic<bool>* cancel) {
  SOFTID_ASSIGN_OR_RETURN(FitSetup setup, SetUpFit(capture, config));
  FitResult chosen;
  chosen.base = setup.base;
  SOFTID_RETURN_IF_ERROR(
      ChooseDiscretisation(capture, setup, config, cancel, &setup.simulation, &chosen));
  return CheckpointOf(chosen, static_cast<int>(setup.starts.size()));
}

Result<TimeStepCheck> CheckTimeStep(const capture::Capture& capture, const JobConfig& config,
                                    const std::atomic<bool>* cancel) {
  SOFTID_ASSIGN_OR_RETURN(FitSetup setup, SetUpFit(capture, config));
  JobConfig automatic = config;
  automatic.solver.substeps = kAutoSubsteps;
  FitResult chosen;
  chosen.base = setup.base;
  SOFTID_RETURN_IF_ERROR(
      ChooseDiscretisation(capture, setup, automatic, cancel, &setup.simulation, &chosen));
  TimeStepCheck out;
  out.selection = std::move(*chosen.substep_selection);
  out.predictable_last_frame =
      PredictableLastFrame(out.selection, LastNominalFrame(*setup.frames, capture.fps));
  return out;
}

Result<FitResult> Fit(const capture::Capture& capture, const JobConfig& config,
                      const FitOptions& options) {
  const auto begin = Clock::now();
  SOFTID_ASSIGN_OR_RETURN(FitSetup setup, SetUpFit(capture, config));
  const int num_starts = static_cast<int>(setup.starts.size());
  FitResult result;
  result.fitted = config.fit;
  result.base = setup.base;
  result.starts.resize(setup.starts.size());
  const cost::SurfaceCostOptions cost_options = CostOptionsFor(config.solver);
  SOFTID_RETURN_IF_ERROR(DiscretiseFit(capture, config, options, &setup, &result));
  ChooseFrameLoss(capture, setup.mesh, config, &result);
  KeepPredictableFrames(config, capture.fps, &setup, &result);
  SOFTID_RETURN_IF_ERROR(CheckTimeForAnEvaluation(config, capture.fps, setup, result, begin));
  SOFTID_ASSIGN_OR_RETURN(std::vector<int> to_run, StartsToRun(options, num_starts));
  FitCheckpoint checkpoint = ResumedCheckpoint(options, num_starts, &result);
  if (options.on_checkpoint) options.on_checkpoint(checkpoint);
  SOFTID_RETURN_IF_ERROR(RunStarts(capture, config, options, setup, cost_options, to_run, begin,
                                   &checkpoint, &result));
  result.cancelled = options.cancel != nullptr && options.cancel->load();
  ChooseBestStart(&result);
  result.total_seconds = SecondsSince(begin);
  if (result.best < 0) {
    if (result.cancelled) return Status::FailedPrecondition("the fit was cancelled");
    std::string why = result.starts.empty() ? "no start" : result.starts[0].termination;
    return Status::FailedPrecondition("every start failed (first start: " + why + ")");
  }
  return result;
}

nlohmann::json ParameterValueJson(const fem::PhysicalParameters& p, const std::string& name) {
  const fem::ParameterInfo* parameter = fem::FindParameter(name);
  return parameter != nullptr ? fem::ToJson(p, *parameter) : nlohmann::json(nullptr);
}

namespace {

// The fitted parameters of a start: value, unit and starting value of each.
nlohmann::json FittedParametersJson(const FitResult& result, const StartResult& start) {
  nlohmann::json out = nlohmann::json::object();
  for (const std::string& name : result.fitted) {
    out[name] = {{"value", ParameterValueJson(start.final, name)},
                 {"unit", std::string(fem::ParameterUnit(name))},
                 {"initial", ParameterValueJson(start.initial, name)}};
  }
  return out;
}

nlohmann::json StagesJson(const StartResult& start) {
  nlohmann::json out = nlohmann::json::array();
  for (const HorizonStageResult& stage : start.stages) {
    out.push_back({{"last_frame", stage.last_frame},
                   {"iterations", stage.iterations},
                   {"cost", CostJson(stage.initial_cost, stage.final_cost)},
                   {"termination", stage.termination}});
  }
  return out;
}

nlohmann::json RefinementJson(const StartResult& start) {
  if (!start.refinement) return nullptr;
  const RefinementResult& r = *start.refinement;
  return {{"method", "levenberg_marquardt"},
          {"iterations", r.iterations},
          {"cost", CostJson(r.initial_cost, r.final_cost)},
          {"converged", r.converged},
          {"termination", r.termination},
          {"evaluations", r.evaluations},
          {"failed_evaluations", r.failed_evaluations}};
}

// A start's cost over the fitted frames and over the held-out ones.
nlohmann::json StartCostJson(const StartResult& start) {
  nlohmann::json cost = CostJson(start.initial_cost, start.final_cost);
  cost["heldout_initial"] = start.initial_heldout_cost;
  cost["heldout_final"] = start.final_heldout_cost;
  return cost;
}

nlohmann::json StartJson(const FitResult& result, const StartResult& start) {
  return nlohmann::json{{"index", start.index},
                        {"parameters", FittedParametersJson(result, start)},
                        {"cost", StartCostJson(start)},
                        {"iterations", start.iterations},
                        {"converged", start.converged},
                        {"failed", start.failed},
                        {"stopped_at_time_limit", start.stopped_at_time_limit},
                        {"termination", start.termination},
                        {"evaluations", start.evaluations},
                        {"failed_evaluations", start.failed_evaluations},
                        {"simulation_steps", start.steps},
                        {"unconverged_steps", start.unconverged_steps},
                        {"seconds", start.seconds},
                        {"stages", StagesJson(start)},
                        {"refinement", RefinementJson(start)},
                        {"flight", start.flight ? ToJson(*start.flight) : nlohmann::json(nullptr)}};
}

// The parameters the fit held: the base without the fitted ones.
nlohmann::json HeldParametersJson(const FitResult& result) {
  nlohmann::json fixed = fem::ToJson(result.base);
  for (const std::string& name : result.fitted)
    fixed.erase(name == "ground_plane" ? std::string("ground") : name);
  return fixed;
}

// Time spent over every start, and per simulated forward plus adjoint step.
// The angle of the turn from the mesh's axes to the grid's [degrees].
double GridTurnDegrees(const Eigen::Matrix3d& mesh_from_grid) {
  return Eigen::AngleAxisd(mesh_from_grid).angle() * 180.0 / M_PI;
}

nlohmann::json TimingJson(const FitResult& result) {
  int evaluations = 0;
  long long steps = 0;
  double forward = 0.0, backward = 0.0;
  for (const StartResult& start : result.starts) {
    evaluations += start.evaluations;
    steps += start.steps;
    forward += start.forward_seconds;
    backward += start.backward_seconds;
  }
  return {
      {"total_seconds", result.total_seconds},
      {"evaluations", evaluations},
      {"simulated_steps", steps},
      {"forward_seconds", forward},
      {"backward_seconds", backward},
      {"ms_per_forward_adjoint_step", steps > 0 ? 1e3 * (forward + backward) / steps : 0.0},
  };
}

}  // namespace

nlohmann::json ToJson(const FitResult& result) {
  const StartResult& best = result.Best();
  nlohmann::json out;
  out["format"] = "softid-result/1";
  out["parameters"] = FittedParametersJson(result, best);
  out["cost"] = StartCostJson(best);
  out["iterations"] = best.iterations;
  out["converged"] = best.converged;
  out["termination"] = best.termination;
  out["cancelled"] = result.cancelled;
  out["best_start"] = best.index;
  out["starts"] = nlohmann::json::array();
  for (const StartResult& start : result.starts) out["starts"].push_back(StartJson(result, start));
  out["cost_history"] = best.cost_history;
  out["cost_history_last_frame"] = best.cost_history_last_frame;
  out["fixed"] = HeldParametersJson(result);
  // How finely space and time were resolved; "selection" only when the job asked for "auto".
  out["grid"] = {{"cells", result.cells},
                 {"cell_size_m", result.cell_size_m},
                 {"element", fem::ToString(result.element)},
                 {"cut_cell_samples", result.cut_cell_samples},
                 {"orientation", fem::ToString(result.grid_orientation)},
                 {"turned_deg", GridTurnDegrees(result.mesh_from_grid)}};
  if (result.grid_selection) out["grid"]["selection"] = ToJson(*result.grid_selection);
  if (!result.frame_loss.IsSquared()) {
    out["frame_loss"] = {{"kind", ToString(FrameLossKind::kCauchy)},
                         {"scale_m2", result.frame_loss.scale_m2},
                         {"depth_noise_m", result.depth_noise_m}};
  }
  out["time_step"] = {{"substeps", result.substeps}};
  if (result.substep_selection) out["time_step"]["selection"] = ToJson(*result.substep_selection);
  if (result.predictable_last_frame >= 0) {
    out["time_step"]["predictable_last_frame"] = result.predictable_last_frame;
  }
  if (result.discretisation_launch) {
    const FlightStageResult& flight = *result.discretisation_launch;
    out["discretisation_launch"] = ToJson(flight);
    for (const std::string& name : flight.held)
      out["discretisation_launch"][name] = ParameterValueJson(flight.parameters, name);
  }
  out["timing"] = TimingJson(result);
  return out;
}

}  // namespace softid::inverse
