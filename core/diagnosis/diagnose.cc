#include "core/diagnosis/diagnose.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iomanip>
#include <limits>
#include <memory>
#include <optional>
#include <sstream>

#include "core/common/for_each_index.h"
#include "core/common/json_fields.h"
#include "core/diagnosis/fit_batch.h"
#include "core/diagnosis/likelihood_ratio.h"
#include "core/diagnosis/plots.h"
#include "core/diagnosis/report.h"
#include "core/inverse/identifiability.h"
#include "core/inverse/objective_settings.h"
#include "core/inverse/trajectory_objective.h"

namespace softid::diagnosis {
namespace {

using Clock = std::chrono::steady_clock;

// Everything needed to evaluate any parameters on the capture as the fit does.
struct Context {
  geometry::TriangleMesh mesh;
  Observations observations;
  // observations.frames, shared by every objective built on them (one copy per diagnosis).
  std::shared_ptr<const std::vector<inverse::ObservedFrame>> frames;
  std::unique_ptr<inverse::TrajectoryObjective> objective;
  inverse::ObjectiveFactory make_objective;  // another objective like `objective`
  Eigen::AlignedBox3d rest_bounds;
  Patches patches;
  double truncation = 0.0;
  std::vector<FrameAt> frame_times;
};

struct ModelResiduals {
  double cost = 0.0, heldout = 0.0;
  ResidualMap map;
};

// The residuals of `objective` (one over the context's observations) at p.
Result<ModelResiduals> ResidualsOf(inverse::TrajectoryObjective& objective, const Context& context,
                                   const fem::PhysicalParameters& p) {
  SOFTID_ASSIGN_OR_RETURN(inverse::ObjectiveEvaluation evaluation, objective.Evaluate(p, false));
  if (evaluation.diverged) return Status::FailedPrecondition("the simulation diverged");
  SOFTID_ASSIGN_OR_RETURN(auto matches, objective.MatchPoints(p));
  ModelResiduals out;
  out.cost = evaluation.cost;
  out.heldout = evaluation.heldout_cost;
  out.map = BuildResidualMap(context.observations, matches, context.patches, context.truncation);
  return out;
}

Result<ModelResiduals> ResidualsAt(Context& context, const fem::PhysicalParameters& p) {
  return ResidualsOf(*context.objective, context, p);
}

// The refit of a model extension: the base config with `freed` parameters fitted as well and
// every fitted parameter starting from `start` (one start: the base optimum plus the extension's
// screened value).
inverse::JobConfig RefitConfig(const inverse::JobConfig& base,
                               const std::vector<std::string>& freed,
                               const fem::PhysicalParameters& start) {
  inverse::JobConfig out = base;
  for (const std::string& name : freed) {
    if (!out.IsFitted(name)) out.fit.push_back(name);
    out.fixed.erase(std::string(inverse::PhysicalParameterKey(name)));
  }
  out.initial.clear();
  for (const std::string& name : out.fit) {
    inverse::InitialValue value;
    value.value = inverse::ParameterValueJson(start, name);
    out.initial[name] = value;
  }
  out.solver.starts = 1;
  // A refit is local: it starts at the base optimum, inside the basin the base fit found over
  // every frame. Refitting a prefix first would let the frames before the extension shows (a
  // block's landing before it slides) pull the shared parameters away (ramp friction 0.3 came
  // back as 0.19).
  out.solver.continuation = false;
  return out;
}

// Standard uncertainties of the extension's values from the identifiability analysis, and
// whether the motion determines them: finite, sensitive, relative uncertainty <= 50 %.
nlohmann::json ExtensionUncertainty(const Candidate& candidate,
                                    const inverse::IdentifiabilityReport& report, bool* ok,
                                    std::string* note) {
  nlohmann::json out = nlohmann::json::object();
  *ok = true;
  for (const inverse::VariableIdentifiability& v : report.variables) {
    if (std::find(candidate.parameters.begin(), candidate.parameters.end(), v.parameter) ==
        candidate.parameters.end())
      continue;
    const bool finite = std::isfinite(v.standard_uncertainty);
    out[v.name] = finite ? nlohmann::json(v.standard_uncertainty) : nlohmann::json(nullptr);
    const bool insensitive =
        std::find(v.flags.begin(), v.flags.end(), inverse::IdentifiabilityFlag::kNoSensitivity) !=
        v.flags.end();
    const bool vague = v.relative_uncertainty >= 0.0 && v.relative_uncertainty > 0.5;
    if (!finite || insensitive || vague) {
      *ok = false;
      *note += (note->empty() ? "" : ", ") + v.name +
               (insensitive ? ": no sensitivity"
                : !finite   ? ": unbounded"
                            : ": > 50 % uncertain");
    }
  }
  return out;
}

// `p` with the extension's value moved by the relative `change` (log-scale quantities, the
// stiffness ratio, in log space).
fem::PhysicalParameters MoveExtension(Extension extension, fem::PhysicalParameters p, double change,
                                      double default_contact_stiffness) {
  switch (extension) {
    case Extension::kFriction: p.friction_coefficient *= 1.0 + change; break;
    case Extension::kAirDrag: p.drag_quadratic *= 1.0 + change; break;
    case Extension::kHeterogeneousStiffness:
      if (p.stiffness_field.regions.size() == 1) {
        double& r = p.stiffness_field.regions[0].scale;
        r = std::pow(r, 1.0 + change);
      }
      break;
    case Extension::kContact:
      if (!(p.contact_stiffness > 0.0)) p.contact_stiffness = default_contact_stiffness;
      p.contact_stiffness *= 1.0 + change;
      break;
    case Extension::kInitialSpin: p.initial_angular_velocity *= 1.0 + change; break;
  }
  return p;
}

// The profile of the found value: the cost with it moved by +-`change` (the other parameters at
// the refit). Determined when both moves are rejected by the likelihood-ratio test at the
// candidate's critical value; the standard uncertainty of the moved quantity (mu, drag, log ratio,
// log k, spin rate) follows from the curvature, sigma = change |value| / sqrt(LR).
struct Profile {
  bool determined = false;
  double lr_minus = 0.0, lr_plus = 0.0;
  double relative_uncertainty = -1.0;  // of the moved quantity [-]; -1 when not determined
};

Profile ProfileExtension(inverse::TrajectoryObjective& objective, Extension extension,
                         const fem::PhysicalParameters& fitted, double cost, double n_eff,
                         double critical_value, double change, double k0) {
  Profile out;
  auto lr_at = [&](double c) {
    const fem::PhysicalParameters p = MoveExtension(extension, fitted, c, k0);
    if (!p.Validate().ok()) return 0.0;
    Result<inverse::ObjectiveEvaluation> e = objective.Evaluate(p, false);
    if (!e.ok() || e->diverged) return std::numeric_limits<double>::infinity();
    return LikelihoodRatioStatistic(e->cost, cost, n_eff);
  };
  out.lr_minus = lr_at(-change);
  out.lr_plus = lr_at(change);
  out.determined = std::min(out.lr_minus, out.lr_plus) > critical_value;
  const double mean = 0.5 * (out.lr_minus + out.lr_plus);
  if (out.determined && std::isfinite(mean)) out.relative_uncertainty = change / std::sqrt(mean);
  return out;
}

// Identifiability with the diagnosis' effective sample size (correlated residuals count less).
inverse::IdentifiabilityOptions IdentifiabilityOptionsFor(const inverse::JobConfig& config,
                                                          double n_eff) {
  inverse::IdentifiabilityOptions options;
  options.threads = config.solver.threads;
  options.num_effective_samples = n_eff;
  return options;
}

// The job's config with its grid and time step capped at the options' comparison discretisation,
// and without the job's time limit: a refit cut short would compare the models unequally (only the
// final refit gives way to a budget, DiagnoseOptions::max_seconds).
inverse::JobConfig ComparisonConfig(inverse::JobConfig config, const DiagnoseOptions& options) {
  inverse::SolverOptions& solver = config.solver;
  solver.max_seconds = 0.0;
  if (options.comparison_cells > 0 && solver.cell_size_m == 0.0 &&
      (solver.cells == inverse::kAutoCells || solver.cells > options.comparison_cells)) {
    solver.cells = options.comparison_cells;
  }
  if (options.comparison_substeps > 0 && (solver.substeps == inverse::kAutoSubsteps ||
                                          solver.substeps > options.comparison_substeps)) {
    solver.substeps = options.comparison_substeps;
  }
  return config;
}

bool SameDiscretisation(const inverse::SolverOptions& a, const inverse::SolverOptions& b) {
  return a.cells == b.cells && a.cell_size_m == b.cell_size_m && a.substeps == b.substeps;
}

// Whether `fit` ran on the grid and time step `solver` asks for ("auto" accepts any).
bool RanAt(const inverse::FitResult& fit, const inverse::SolverOptions& solver) {
  const bool grid =
      solver.cells == inverse::kAutoCells || solver.cell_size_m > 0.0 || fit.cells == solver.cells;
  const bool step = solver.substeps == inverse::kAutoSubsteps || fit.substeps == solver.substeps;
  return grid && step;
}

// The diagnosis of `job` with the models compared under `compared` (ComparisonConfig); a base
// restart runs it again from a better base. `compared_coarser`: whether ComparisonConfig changed
// the job's grid or time step (decided before "auto" resolves, so a restart passes it on).
// `job_fit`: the job's own fit, if given, on the job's discretisation (the final model when that
// is the base model).
Result<DiagnosisReport> DiagnoseAt(const capture::Capture& capture, const inverse::JobConfig& job,
                                   inverse::JobConfig compared, bool compared_coarser,
                                   const DiagnoseOptions& options,
                                   const inverse::FitResult* base_fit,
                                   const inverse::FitResult* job_fit);

// One diagnosis: the base fit and the evaluation context every later stage shares, the report it
// fills, and the stages (numbered as in diagnose.h) as methods.
struct DiagnosisRun {
  const capture::Capture& capture;
  const DiagnoseOptions& options;
  const DecisionOptions& rule;
  const Clock::time_point begin = Clock::now();
  const inverse::JobConfig job;   // as the job gave it: its discretisation is the final model's
  bool compared_coarser = false;  // the models are compared on a coarser grid or time step
  const inverse::FitResult* job_fit = nullptr;  // the job's own fit of the base model, if given
  inverse::JobConfig config;  // the base config compared on, "auto" resolved after the base fit
  DiagnosisReport report;
  inverse::FitResult base;
  fem::PhysicalParameters p0;  // the base fit's parameters
  Context context;
  ModelResiduals r0;  // at p0
  // The base's objective at twice the compared substeps, when the step's error was estimated.
  std::unique_ptr<inverse::TrajectoryObjective> finer_objective;
  double sigma = 0.0;  // noise floor [m]
  EffectiveSampleSize ess0;
  ModelResiduals final_residuals;
  nlohmann::json base_identifiability;  // computed when the base misfits (screening needs H_bb)

  DiagnosisRun(const capture::Capture& capture, inverse::JobConfig job, inverse::JobConfig config,
               const DiagnoseOptions& options)
      : capture(capture),
        options(options),
        rule(options.decision),
        job(std::move(job)),
        config(std::move(config)) {}
  DiagnosisRun(const DiagnosisRun&) = delete;  // context.make_objective holds `this`
  DiagnosisRun& operator=(const DiagnosisRun&) = delete;

  void Stage(const std::string& message) const {
    if (options.on_stage) options.on_stage(message);
  }
  bool Cancelled() const { return options.fit.cancel != nullptr && options.fit.cancel->load(); }
  double ElapsedSeconds() const {
    return std::chrono::duration<double>(Clock::now() - begin).count();
  }
  double DefaultK(const fem::PhysicalParameters& p) const {
    return fem::DefaultContactStiffness(p.youngs_modulus, context.rest_bounds.sizes().maxCoeff());
  }

  // The whole diagnosis, or the diagnosis restarted from a better base fit (4b).
  Result<DiagnosisReport> Run(const inverse::FitResult* base_fit) {
    SOFTID_RETURN_IF_ERROR(FitBase(base_fit));
    SOFTID_RETURN_IF_ERROR(BuildContext());
    SOFTID_RETURN_IF_ERROR(LocateMismatch());
    final_residuals = r0;
    if (report.before.flagged) {
      SOFTID_RETURN_IF_ERROR(Screen());
      TestCandidatesAlone();
      TestPhysicsGivenNuisances();
    }
    DecideFromTheTests();
    SOFTID_ASSIGN_OR_RETURN(std::optional<DiagnosisReport> restarted, RestartFromABetterBase());
    if (restarted) return *std::move(restarted);
    ListNuisances();
    SOFTID_RETURN_IF_ERROR(SettleFinalModel());
    SOFTID_RETURN_IF_ERROR(WritePlots());
    RefitAtTheJobsDiscretisation();
    report.seconds = std::chrono::duration<double>(Clock::now() - begin).count();
    return report;
  }

  // 1. The base model: the given fit, or a new one.
  Status FitBase(const inverse::FitResult* base_fit) {
    if (base_fit != nullptr) {
      base = *base_fit;
    } else {
      Stage("base fit: " + std::to_string(config.fit.size()) + " parameter(s)");
      SOFTID_ASSIGN_OR_RETURN(base, inverse::Fit(capture, config, options.fit));
    }
    report.base_fit = inverse::ToJson(base);
    p0 = base.Best().final;
    // Every refit and the likelihood ratios compare models on the base fit's grid and time step: an
    // "auto" choice redone at other parameters could change the discretisation between the models.
    config = inverse::WithFitDiscretisation(config, base);
    return Status::Ok();
  }

  // The objective on the fitted frames at the base fit's discretisation, the surface patches and
  // the frame times.
  Status BuildContext() {
    SOFTID_ASSIGN_OR_RETURN(context.mesh, capture::LoadCaptureMesh(capture));
    SOFTID_ASSIGN_OR_RETURN(
        context.observations,
        LoadObservations(capture, config.frames.first, config.frames.last, config.heldout_every));
    context.frames =
        std::make_shared<const std::vector<inverse::ObservedFrame>>(context.observations.frames);
    // Each objective simulates on one thread (SimulationOptions' default): parallel work runs
    // whole evaluations side by side (the screening's tries), which scales better.
    context.make_objective = [this] {
      auto objective = std::make_unique<inverse::TrajectoryObjective>(
          context.mesh, capture.fixed_region, p0, inverse::SimulationOptionsFor(config.solver),
          inverse::CostOptionsFor(config.solver), context.frames, capture.fps,
          config.solver.substeps);
      objective->SetCancelFlag(options.fit.cancel);
      return objective;
    };
    try {
      context.objective = context.make_objective();
    } catch (const std::invalid_argument& e) {
      return Status::InvalidArgument(e.what());
    }
    context.rest_bounds = context.mesh.Bounds();
    const double h = context.objective->simulator().hex_mesh().CellSize();
    context.truncation = config.solver.cost.truncation_cells * h;
    // The rest surface lies in the grid's frame (fem::Simulator::mesh_from_grid), and so must up.
    const fem::Simulator& sim = context.objective->simulator();
    const Eigen::Vector3d up_in_grid =
        sim.rest_frame().world_from_rest().linear().transpose() * -p0.gravity;
    context.patches = MakePatches(sim.rest_surface(), options.patches, up_in_grid);
    for (const auto& f : context.observations.frames) {
      context.frame_times.push_back({f.frame, f.time});
      report.frames.push_back(f.frame);
      report.heldout.push_back(f.heldout);
    }
    return Status::Ok();
  }

  // 2. Locate the mismatch: residual map, noise floor, motion phases, flagged phases and patches.
  Status LocateMismatch() {
    Stage("residual map, noise floor and motion phases");
    SOFTID_ASSIGN_OR_RETURN(r0, ResidualsAt(context, p0));
    report.base_cost = r0.cost;
    report.base_heldout = r0.heldout;
    SOFTID_ASSIGN_OR_RETURN(report.noise_floor, EstimateNoiseFloor(r0.map, options.noise_floor));
    sigma = report.noise_floor.sigma;
    SOFTID_ASSIGN_OR_RETURN(report.motion, SplitMotionPhases(context.objective->simulator(), p0,
                                                             context.frame_times, options.phases));
    SOFTID_RETURN_IF_ERROR(EstimateComparedStepError());
    std::vector<double> share;
    report.before = Locate(LessStepError(r0.map, &share), report.motion, sigma,
                           rule.misfit_threshold, rule.min_phase_frames, rule.min_patch_points);
    if (report.time_step_error) report.time_step_error->frame_share = share;
    report.after = report.before;
    ess0 = ComputeEffectiveSampleSize(FittedResiduals(r0.map));
    report.n_eff = ess0.n_eff;
    if (report.noise_floor.frame0_excess) {
      report.nuisances.push_back(
          {{"nuisance", "camera_pose_or_time_offset"},
           {"evidence", "frame 0, whose pose is given, misfits " +
                            std::to_string(report.noise_floor.frame0_misfit /
                                           report.noise_floor.quantile_misfit) +
                            " x the floor of the moving frames"},
           {"modelled", false}});
    }
    return Status::Ok();
  }

  // 2b. The compared time step's own share of the misfit (time_step_error.h): the base model once
  // more at half the step, and once per base variable for its sensitivities.
  Status EstimateComparedStepError() {
    const int substeps = config.solver.substeps;
    if (!options.remove_time_step_error || substeps <= 0) return Status::Ok();
    Stage("the compared time step's error: the base model at " + std::to_string(2 * substeps) +
          " substeps per frame");
    std::unique_ptr<inverse::TrajectoryObjective> finer;
    try {
      finer = std::make_unique<inverse::TrajectoryObjective>(
          context.mesh, capture.fixed_region, p0, inverse::SimulationOptionsFor(config.solver),
          inverse::CostOptionsFor(config.solver), context.frames, capture.fps, 2 * substeps);
    } catch (const std::invalid_argument& e) {
      return Status::InvalidArgument(e.what());
    }
    finer->SetCancelFlag(options.fit.cancel);
    Result<ModelResiduals> at_half_step = ResidualsOf(*finer, context, p0);
    if (!at_half_step.ok()) {
      spdlog::warn("diagnosis: the base model at half the step: {} (its error stays in the misfit)",
                   at_half_step.status().message());
      return Status::Ok();
    }
    finer_objective = std::move(finer);
    const std::optional<Sensitivities> sensitivities = BaseSensitivities();
    report.time_step_error =
        EstimateTimeStepError(r0.map, at_half_step->map, sensitivities ? &*sensitivities : nullptr,
                              substeps, 2 * substeps);
    return Status::Ok();
  }
  // The residual maps with each base variable moved by 0.01 (optimiser units: 1 % of a modulus,
  // a hundredth of the body's length per second of a launch), one run each; nullopt when a run
  // fails (nothing is then absorbed).
  std::optional<Sensitivities> BaseSensitivities() {
    Result<inverse::ParameterSpace> space = inverse::ParameterSpace::Create(
        base.fitted, base.base, context.rest_bounds.sizes().maxCoeff());
    if (!space.ok()) return std::nullopt;
    const std::vector<double> x0 = space->ToVariables(p0);
    Sensitivities out;
    out.step = 0.01;
    Result<ModelResiduals> at = ResidualsAt(context, space->ToParameters(x0.data(), p0));
    if (!at.ok()) return std::nullopt;
    out.at = std::move(at->map);
    for (size_t v = 0; v < x0.size(); ++v) {
      std::vector<double> x = x0;
      x[v] += out.step;
      Result<ModelResiduals> moved = ResidualsAt(context, space->ToParameters(x.data(), p0));
      if (!moved.ok()) return std::nullopt;
      out.moved.push_back(std::move(moved->map));
    }
    return out;
  }
  // `map` less the compared time step's component (time_step_error.h), when estimated.
  ResidualMap LessStepError(const ResidualMap& map, std::vector<double>* share = nullptr) const {
    if (!report.time_step_error) return map;
    return WithoutTimeStepComponent(map, *report.time_step_error, share);
  }
  // The cost of `map` less the compared step's component: the mean of its fitted frames' costs,
  // as the objective's [m^2]; -1 when that component was not estimated.
  double StepFreeCost(const ResidualMap& map) const {
    if (!report.time_step_error) return -1.0;
    const ResidualMap less = LessStepError(map);
    double sum = 0.0;
    int fitted = 0;
    for (const FrameResiduals& frame : less.frames) {
      if (frame.heldout) continue;
      sum += frame.cost;
      ++fitted;
    }
    return fitted > 0 ? sum / fitted : -1.0;
  }

  // 3. Screen every candidate around the base fit (its parameters profiled out).
  Status Screen() {
    std::vector<double> excess;
    for (const FrameResiduals& f : r0.map.frames)
      excess.push_back(std::max(0.0, f.misfit * f.misfit - sigma * sigma));
    SOFTID_ASSIGN_OR_RETURN(inverse::ParameterSpace space,
                            inverse::ParameterSpace::Create(
                                base.fitted, base.base, context.rest_bounds.sizes().maxCoeff()));
    ScreeningBase screening_base;
    screening_base.parameters = p0;
    screening_base.fitted = base.fitted;
    screening_base.space = &space;
    screening_base.cost = r0.cost;
    screening_base.n_eff = ess0.n_eff;
    screening_base.floor_cost = 0.5 * sigma * sigma;
    screening_base.rest_bounds = context.rest_bounds;
    screening_base.make_objective = context.make_objective;
    screening_base.workers = Cores();
    Stage("curvature of the base fit (identifiability)");
    Result<inverse::IdentifiabilityReport> base_id = inverse::AnalyzeIdentifiability(
        capture, config, base, IdentifiabilityOptionsFor(config, ess0.n_eff));
    if (base_id.ok()) {
      screening_base.hessian = base_id->hessian;
      base_identifiability = inverse::ToJson(*base_id);
    } else {
      base_identifiability = {{"error", base_id.status().message()}};
    }
    Stage("screening " + std::to_string(CandidateLibrary().size()) + " candidates");
    const auto screening_begin = Clock::now();
    SOFTID_ASSIGN_OR_RETURN(report.screening,
                            ScreenCandidates(*context.objective, screening_base, report.motion,
                                             excess, options.screening));
    report.screening_seconds =
        std::chrono::duration<double>(Clock::now() - screening_begin).count();
    return Status::Ok();
  }

  // The cores the diagnosis may use: the job's threads, or every core.
  int Cores() const { return config.solver.threads > 0 ? config.solver.threads : CoreCount(); }

  // The fits of `configs`, in their order: by options.run_fits (another worker may run them), by
  // default here, side by side on the cores, each given an equal share of them (whole fits in
  // parallel scale better than one fit's simulation on several threads).
  std::vector<Result<inverse::FitResult>> RunFits(std::vector<inverse::JobConfig> configs) const {
    if (configs.empty()) return {};
    if (!options.run_fits) {
      const int per_fit = std::max(1, Cores() / static_cast<int>(configs.size()));
      for (inverse::JobConfig& fit_config : configs) fit_config.solver.threads = per_fit;
      return RunFitsInProcess(capture, configs, options.fit, Cores() / per_fit);
    }
    std::vector<Result<inverse::FitResult>> results = options.run_fits(configs);
    if (results.size() == configs.size()) return results;
    const Status wrong =
        Status::Internal("the fit batch runner returned " + std::to_string(results.size()) +
                         " results for " + std::to_string(configs.size()) + " fits");
    return std::vector<Result<inverse::FitResult>>(configs.size(), wrong);
  }

  // A refit of `freed` (every base parameter free as well) from each of `starts`; `fallbacks`
  // only while no start succeeded. The refits of a stage are planned first and run as one batch.
  struct RefitPlan {
    const Candidate* candidate = nullptr;
    std::vector<std::string> freed;
    std::vector<fem::PhysicalParameters> starts;
    std::vector<fem::PhysicalParameters> fallbacks;
    std::vector<Result<inverse::FitResult>> fits;  // one per start, once run
  };

  // Every plan's starts in one batch.
  void RunRefits(std::vector<RefitPlan>* plans) const {
    std::vector<inverse::JobConfig> configs;
    for (const RefitPlan& plan : *plans) {
      for (const fem::PhysicalParameters& start : plan.starts)
        configs.push_back(RefitConfig(config, plan.freed, start));
    }
    std::vector<Result<inverse::FitResult>> results = RunFits(configs);
    size_t next = 0;
    for (RefitPlan& plan : *plans) {
      for (size_t i = 0; i < plan.starts.size(); ++i)
        plan.fits.push_back(std::move(results[next++]));
    }
  }

  // The plan's refit with the lowest fitted cost, running fallback starts one by one while none
  // succeeded. *tried lists each start's extension values and fitted cost, *used the winner's
  // config.
  Result<inverse::FitResult> BestRefit(RefitPlan& plan, nlohmann::json* tried,
                                       inverse::JobConfig* used) const {
    Result<inverse::FitResult> best = Status::Internal("no refit start");
    const double k0 =
        fem::DefaultContactStiffness(p0.youngs_modulus, context.rest_bounds.sizes().maxCoeff());
    const Extension extension = plan.candidate->extension;
    auto consider = [&](const fem::PhysicalParameters& start, Result<inverse::FitResult> fit,
                        bool fallback) {
      nlohmann::json entry = {{"start", ExtensionValues(extension, start, k0)}};
      if (fallback) entry["fallback"] = true;
      if (fit.ok()) {
        entry["cost"] = fit->Best().final_cost;
        entry["found"] = ExtensionValues(extension, fit->Best().final, k0);
      } else {
        entry["error"] = fit.status().message();
      }
      tried->push_back(entry);
      if (fit.ok() && (!best.ok() || fit->Best().final_cost < best->Best().final_cost)) {
        best = std::move(fit);
        *used = RefitConfig(config, plan.freed, start);
      } else if (!best.ok() && !fit.ok()) {
        best = fit.status();
      }
    };
    for (size_t i = 0; i < plan.starts.size(); ++i)
      consider(plan.starts[i], std::move(plan.fits[i]), false);
    for (const fem::PhysicalParameters& start : plan.fallbacks) {
      if (best.ok()) break;
      consider(start, std::move(RunFits({RefitConfig(config, plan.freed, start)}).front()), true);
    }
    return best;
  }

  // "refits with friction, contact (3 fits)": what a batch of refits is about to run.
  static std::string RefitStage(const std::vector<RefitPlan>& plans, const std::string& given) {
    std::string names;
    size_t fits = 0;
    for (const RefitPlan& plan : plans) {
      names += (names.empty() ? "" : ", ") + std::string(ToString(plan.candidate->extension));
      fits += plan.starts.size();
    }
    return "refits with " + names + given + " (" + std::to_string(fits) + " fits)";
  }

  // 4. Steps 1a-1e of the rule for a finished refit: `tested.test` holds the null's costs
  // (cost_before, heldout_before); LR, gates, profile and (when accepted) identifiability follow.
  void Judge(const Candidate& candidate, const Result<inverse::FitResult>& fit,
             const inverse::JobConfig& fit_config, TestedCandidate* tested) {
    Result<ModelResiduals> r1 = Status::Internal("not evaluated");
    if (fit.ok()) {
      tested->parameters = fit->Best().final;
      r1 = ResidualsAt(context, tested->parameters);
    }
    if (!fit.ok() || !r1.ok()) {
      tested->test.refit_error = !fit.ok() ? fit.status().message() : r1.status().message();
      ApplyDecisionRule(rule, candidate, &tested->test);
      return;
    }
    tested->fit = inverse::ToJson(*fit);
    tested->test.cost_after = r1->cost;
    tested->test.step_free_cost_after = StepFreeCost(r1->map);
    tested->test.heldout_after = r1->heldout;
    const EffectiveSampleSize ess = ComputeEffectiveSampleSize(FittedResiduals(r1->map));
    tested->test.n_eff = ess.n_eff;
    tested->test.tau_pixels = ess.tau_pixels;
    tested->test.tau_frames = ess.tau_frames;
    tested->test.lr = LikelihoodRatioStatistic(tested->test.cost_before, r1->cost, ess.n_eff);
    tested->after = Locate(LessStepError(r1->map), report.motion, sigma, rule.misfit_threshold,
                           rule.min_phase_frames, rule.min_patch_points);
    // The phases and patches flagged at the base fit must be back at the noise level.
    for (size_t i = 0; i < report.before.phases.size(); ++i) {
      if (!report.before.phases[i].flagged) continue;
      for (const PhaseMisfit& after : tested->after.phases)
        if (after.phase == report.before.phases[i].phase &&
            after.normalised > rule.misfit_threshold)
          tested->test.still_flagged.push_back(ToString(after.phase));
    }
    for (size_t i = 0; i < report.before.patches.size(); ++i) {
      if (report.before.patches[i].flagged &&
          tested->after.patches[i].normalised > rule.misfit_threshold)
        tested->test.still_flagged.push_back("patch " + std::to_string(i) + " (" +
                                             tested->after.patches[i].label + ")");
    }
    const double k0 = fem::DefaultContactStiffness(tested->parameters.youngs_modulus,
                                                   context.rest_bounds.sizes().maxCoeff());
    tested->test.plausible =
        IsPlausible(candidate.extension, tested->parameters, k0, &tested->test.plausibility_note);
    tested->values = ExtensionValues(candidate.extension, tested->parameters, k0);
    tested->uncertainty = nullptr;
    ApplyDecisionRule(rule, candidate, &tested->test);
    if (tested->test.accepted) RefitTheNullModel(candidate, fit_config, *r1, ess, tested);
    if (tested->test.accepted && !candidate.nuisance) CheckAtHalfTheStep(candidate, tested);
    if (tested->test.accepted) ProfileTheFoundValue(candidate, *r1, ess, tested);
    if (tested->test.accepted && options.identifiability) {
      CheckIdentifiability(candidate, *fit, fit_config, ess, tested);
    }
    tested->cost_history.push_back(fit->Best().initial_cost);
    for (double c : fit->Best().CostHistoryOverEveryFrame()) tested->cost_history.push_back(c);
  }

  // 1a'. The null's cost is the lowest the null model reaches, also from the refit's values
  // with the extension back at its null: a base fit that stopped in a local minimum (control
  // s119: beta 0.0066 instead of 0.0025) let any extension "improve" it by escaping there.
  void RefitTheNullModel(const Candidate& candidate, const inverse::JobConfig& fit_config,
                         const ModelResiduals& r1, const EffectiveSampleSize& ess,
                         TestedCandidate* tested) {
    std::vector<std::string> null_freed;
    for (const std::string& name : fit_config.fit) {
      const bool extension_parameter =
          std::find(candidate.parameters.begin(), candidate.parameters.end(), name) !=
          candidate.parameters.end();
      if (!extension_parameter && !config.IsFitted(name)) null_freed.push_back(name);
    }
    const fem::PhysicalParameters null_start =
        NullModelStart(candidate.extension, p0, tested->parameters, context.rest_bounds);
    Stage(std::string("null model refitted from the ") + ToString(candidate.extension) + " refit");
    Result<inverse::FitResult> null_fit =
        inverse::Fit(capture, RefitConfig(config, null_freed, null_start), options.fit);
    Result<ModelResiduals> rn = Status::Internal("not evaluated");
    if (null_fit.ok()) rn = ResidualsAt(context, null_fit->Best().final);
    if (null_fit.ok() && null_freed.empty()) tested->null_fit = *null_fit;
    if (rn.ok()) {
      const bool lower = rn->cost < tested->test.cost_before;
      tested->null_refit = {{"cost", rn->cost}, {"heldout", rn->heldout}, {"replaced_null", lower}};
      if (lower) {
        tested->before_parameters = null_fit->Best().final;
        tested->test.cost_before = rn->cost;
        tested->test.step_free_cost_before = StepFreeCost(rn->map);
        tested->test.heldout_before = rn->heldout;
        tested->test.lr = LikelihoodRatioStatistic(rn->cost, r1.cost, ess.n_eff);
        ApplyDecisionRule(rule, candidate, &tested->test);
      }
    } else {
      tested->null_refit = {
          {"error", !null_fit.ok() ? null_fit.status().message() : rn.status().message()}};
    }
  }

  // 1f. Does the improvement hold at half the step? The null and the candidate once more on the
  // finer objective of EstimateComparedStepError (decision.h).
  void CheckAtHalfTheStep(const Candidate& candidate, TestedCandidate* tested) {
    if (!finer_objective || !report.time_step_error) return;
    Stage(std::string("the ") + ToString(candidate.extension) + " refit at " +
          std::to_string(report.time_step_error->finer_substeps) + " substeps per frame");
    Result<ModelResiduals> before =
        ResidualsOf(*finer_objective, context, tested->before_parameters);
    Result<ModelResiduals> after = ResidualsOf(*finer_objective, context, tested->parameters);
    for (const Result<ModelResiduals>* run : {&before, &after}) {
      if (!run->ok()) {
        spdlog::warn("diagnosis: gate f not checked for {}: {}", ToString(candidate.extension),
                     run->status().message());
        return;
      }
    }
    CandidateTest& test = tested->test;
    test.step_checked = true;
    test.cost_before_at_finer_step = before->cost;
    test.cost_after_at_finer_step = after->cost;
    test.lr_at_finer_step = LikelihoodRatioStatistic(before->cost, after->cost, test.n_eff);
    ApplyDecisionRule(rule, candidate, &test);
  }

  // 1e. Does the motion determine the found value? Its profile at +-25 %.
  void ProfileTheFoundValue(const Candidate& candidate, const ModelResiduals& r1,
                            const EffectiveSampleSize& ess, TestedCandidate* tested) {
    const double k0 = DefaultK(tested->parameters);
    const Profile profile =
        ProfileExtension(*context.objective, candidate.extension, tested->parameters, r1.cost,
                         ess.n_eff, tested->test.critical_value, 0.25, k0);
    tested->profile = {{"change", 0.25},
                       {"lr_minus", profile.lr_minus},
                       {"lr_plus", profile.lr_plus},
                       {"determined", profile.determined},
                       {"relative_uncertainty", profile.relative_uncertainty}};
    tested->test.identifiability_checked = true;
    tested->test.identifiable = profile.determined;
    if (!profile.determined) {
      tested->test.identifiability_note = "a 25 % change of the value is not rejected (LR " +
                                          std::to_string(profile.lr_minus) + ", " +
                                          std::to_string(profile.lr_plus) + ")";
    }
    ApplyDecisionRule(rule, candidate, &tested->test);
  }

  // Identifiability, only where everything else passed (it costs 2 runs per variable).
  void CheckIdentifiability(const Candidate& candidate, const inverse::FitResult& fit,
                            const inverse::JobConfig& fit_config, const EffectiveSampleSize& ess,
                            TestedCandidate* tested) {
    Stage(std::string("identifiability of ") + ToString(candidate.extension));
    Result<inverse::IdentifiabilityReport> id = inverse::AnalyzeIdentifiability(
        capture, fit_config, fit, IdentifiabilityOptionsFor(config, ess.n_eff));
    if (id.ok()) {
      bool ok = true;
      std::string note;
      tested->uncertainty = ExtensionUncertainty(candidate, *id, &ok, &note);
      // Reported, not a gate: a Hessian from differences of adjoint gradients can miss the
      // curvature of a piecewise-smooth cost (contact switching), the profile above cannot.
      if (!ok) tested->profile["hessian_note"] = note;
      tested->fit["identifiability"] = inverse::ToJson(*id);
    } else {
      tested->profile["hessian_note"] = id.status().message();
    }
  }

  // 4. One refit per screened extension that predicts an improvement, judged alone; the refits
  // run as one batch.
  void TestCandidatesAlone() {
    std::vector<RefitPlan> plans = PlanRefitsAlone();
    if (plans.empty()) return;
    Stage(RefitStage(plans, ""));
    RunRefits(&plans);
    for (RefitPlan& plan : plans) {
      TestedCandidate tested;
      tested.test.extension = plan.candidate->extension;
      tested.before_parameters = p0;
      tested.test.cost_before = r0.cost;
      tested.test.step_free_cost_before = StepFreeCost(r0.map);
      tested.test.floor_cost = 0.5 * sigma * sigma;
      tested.test.heldout_before = r0.heldout;
      tested.starts = nlohmann::json::array();
      inverse::JobConfig used = config;
      const Result<inverse::FitResult> fit = BestRefit(plan, &tested.starts, &used);
      tested.fitted = used.fit;
      Judge(*plan.candidate, fit, used, &tested);
      report.tested.push_back(std::move(tested));
    }
  }

  // The refits TestCandidatesAlone runs: at most max_refits, one per extension (the stiffness
  // split is screened once per axis), a two-sided variable from its best start on each side.
  std::vector<RefitPlan> PlanRefitsAlone() const {
    std::vector<RefitPlan> plans;
    for (const ScreenedCandidate& s : report.screening) {
      if (static_cast<int>(plans.size()) >= rule.max_refits) break;
      if (!s.applicable || !(s.predicted_lr > 0.0)) continue;
      if (std::any_of(plans.begin(), plans.end(),
                      [&](const RefitPlan& p) { return p.candidate->extension == s.extension; }))
        continue;
      if (Cancelled()) break;
      RefitPlan plan;
      plan.candidate = &GetCandidate(s.extension);
      plan.freed = plan.candidate->parameters;
      plan.starts = s.refit_starts;
      if (plan.starts.empty()) plan.starts = {s.start};
      plan.fallbacks = s.fallback_starts;
      for (auto* list : {&plan.starts, &plan.fallbacks}) {
        for (fem::PhysicalParameters& start : *list) {
          if (s.extension == Extension::kContact && !(start.contact_stiffness > 0.0)) {
            start.contact_stiffness = fem::DefaultContactStiffness(
                p0.youngs_modulus, context.rest_bounds.sizes().maxCoeff());
          }
        }
      }
      plans.push_back(std::move(plan));
    }
    return plans;
  }

  // Step 2 of the rule: a physics candidate that improves the fit, tested given each nuisance
  // that improves it too with a plausible value (the two are not nested). The joint refit starts
  // from the better (forward cost) of the nuisance's refit with the candidate's found values and
  // the candidate's refit with the nuisance's found values.
  void TestPhysicsGivenNuisances() {
    std::vector<JointRefit> joints = PlanJointRefits();
    if (joints.empty()) return;
    std::vector<RefitPlan> plans;
    for (const JointRefit& joint : joints) plans.push_back(joint.plan);
    Stage(RefitStage(plans, " given a nuisance"));
    RunRefits(&plans);
    report.tested.reserve(report.tested.size() + joints.size());  // references stay valid
    for (size_t j = 0; j < joints.size(); ++j) {
      const TestedCandidate& nuisance = report.tested[joints[j].nuisance];
      const TestedCandidate& physics = report.tested[joints[j].physics];
      const Candidate& candidate = *plans[j].candidate;
      const Candidate& nuisance_candidate = GetCandidate(nuisance.test.extension);
      TestedCandidate tested;
      tested.test.extension = candidate.extension;
      tested.test.conditional = true;
      tested.test.given = nuisance_candidate.extension;
      tested.before_parameters = nuisance.parameters;
      tested.test.cost_before = nuisance.test.cost_after;
      tested.test.step_free_cost_before = nuisance.test.step_free_cost_after;
      tested.test.floor_cost = 0.5 * sigma * sigma;
      tested.test.heldout_before = nuisance.test.heldout_after;
      tested.test.physics_cost = physics.test.cost_after;
      tested.test.physics_heldout = physics.test.heldout_after;
      tested.starts = nlohmann::json::array();
      inverse::JobConfig used = config;
      const Result<inverse::FitResult> fit = BestRefit(plans[j], &tested.starts, &used);
      tested.fitted = used.fit;
      Judge(candidate, fit, used, &tested);
      if (tested.test.refit_error.empty()) {
        tested.test.nuisance_lr = LikelihoodRatioStatistic(
            tested.test.physics_cost, tested.test.cost_after, tested.test.n_eff);
        tested.nuisance_values = ExtensionValues(nuisance_candidate.extension, tested.parameters,
                                                 DefaultK(tested.parameters));
      }
      ApplyNuisanceCheck(rule, nuisance_candidate, &tested.test);
      report.tested.push_back(std::move(tested));
    }
  }

  // A joint refit of the physics candidate report.tested[physics] given the nuisance
  // report.tested[nuisance].
  struct JointRefit {
    size_t nuisance = 0;
    size_t physics = 0;
    RefitPlan plan;
  };

  // The joint refits step 2 runs: each nuisance that improves the fit with a plausible value with
  // each physics candidate that improves it, from the best start (forward cost).
  std::vector<JointRefit> PlanJointRefits() const {
    std::vector<JointRefit> joints;
    const size_t num_single = report.tested.size();
    for (size_t n = 0; n < num_single; ++n) {
      const CandidateTest& fitted_nuisance = report.tested[n].test;
      if (!fitted_nuisance.nuisance || !fitted_nuisance.refit_error.empty() ||
          !fitted_nuisance.lr_passed || !fitted_nuisance.plausible)
        continue;
      for (size_t i = 0; i < num_single; ++i) {
        const CandidateTest& alone = report.tested[i].test;
        if (alone.nuisance || !alone.refit_error.empty() || !alone.lr_passed) continue;
        if (Cancelled()) break;
        const TestedCandidate& nuisance = report.tested[n];
        const TestedCandidate& physics = report.tested[i];
        const Candidate& candidate = GetCandidate(physics.test.extension);
        const Candidate& nuisance_candidate = GetCandidate(nuisance.test.extension);
        // Each refit with the other's found values, and each refit as it is (the other at its
        // null): the joint model nests both, so its refit must end at least as low as either.
        const fem::PhysicalParameters starts[] = {
            CopyExtension(candidate.extension, physics.parameters, nuisance.parameters),
            CopyExtension(nuisance_candidate.extension, nuisance.parameters, physics.parameters),
            WithExtensionAtNull(candidate.extension, physics.parameters, nuisance.parameters,
                                context.rest_bounds),
            physics.parameters};
        fem::PhysicalParameters start = starts[0];
        double lowest = std::numeric_limits<double>::infinity();
        for (const fem::PhysicalParameters& p : starts) {
          Result<inverse::ObjectiveEvaluation> e = context.objective->Evaluate(p, false);
          if (e.ok() && !e->diverged && e->cost < lowest) {
            lowest = e->cost;
            start = p;
          }
        }
        JointRefit joint;
        joint.nuisance = n;
        joint.physics = i;
        joint.plan.candidate = &candidate;
        joint.plan.freed = nuisance_candidate.parameters;
        for (const std::string& name : candidate.parameters) joint.plan.freed.push_back(name);
        joint.plan.starts = {start};
        joints.push_back(std::move(joint));
      }
    }
    return joints;
  }

  // 5. The decision from the tests.
  void DecideFromTheTests() {
    std::vector<CandidateTest> tests;
    for (const TestedCandidate& t : report.tested) tests.push_back(t.test);
    report.decision = Decide(report.before.flagged, tests, &report.winner);
  }

  // 4b. Nothing explains a misfit that refits did lower a lot: the base fit may have stopped in a
  // local minimum that the extra freedom let the refits leave (halves 2x at 4 sub-steps: base E
  // 7.2 kPa with cost 6.0e-6, while E 3.2 kPa, reached from the contact refit, gives 3.1e-6). The
  // null model refitted from each such refit (extension at its null); when one lands
  // significantly lower than the base (LR above the 1-parameter critical value), the whole
  // diagnosis restarts from it as the base fit.
  Result<std::optional<DiagnosisReport>> RestartFromABetterBase() {
    if (report.decision == "unexplained" && options.max_base_restarts > 0) {
      const double critical = ChiBarSquareCriticalValue(1, 0, rule.alpha);
      // The null model refitted from each refit that lowered the first base's cost
      // significantly (gate 1a' may have fitted that very start already); the rest in a batch.
      std::vector<const TestedCandidate*> sources;
      std::vector<inverse::JobConfig> configs;
      for (const TestedCandidate& t : report.tested) {
        // Against the first base (a null refitted in gate 1a' may have replaced cost_before).
        if (t.test.conditional || !t.test.refit_error.empty() ||
            !(LikelihoodRatioStatistic(r0.cost, t.test.cost_after, ess0.n_eff) > critical))
          continue;
        sources.push_back(&t);
        if (t.null_fit) continue;
        const fem::PhysicalParameters start =
            NullModelStart(t.test.extension, p0, t.parameters, context.rest_bounds);
        configs.push_back(RefitConfig(config, {}, start));
      }
      if (Cancelled()) return std::optional<DiagnosisReport>();
      if (!configs.empty()) {
        Stage("base model refitted from " + std::to_string(configs.size()) + " refit(s)");
      }
      std::vector<Result<inverse::FitResult>> fits = RunFits(configs);
      std::optional<inverse::FitResult> better;
      double better_cost = r0.cost;
      std::string via;
      size_t next = 0;
      for (const TestedCandidate* t : sources) {
        Result<inverse::FitResult> fit = t->null_fit ? *t->null_fit : std::move(fits[next++]);
        if (!fit.ok() || !(fit->Best().final_cost < better_cost)) continue;
        better_cost = fit->Best().final_cost;
        better = std::move(*fit);
        via = ToString(t->test.extension);
      }
      if (better && LikelihoodRatioStatistic(r0.cost, better_cost, ess0.n_eff) > critical) {
        std::ostringstream why;
        why << std::setprecision(3) << "restart: the base fit stopped in a local minimum (cost "
            << r0.cost << " m^2; refitted from the " << via << " refit " << better_cost << " m^2)";
        Stage(why.str());
        DiagnoseOptions next = options;
        next.max_base_restarts = options.max_base_restarts - 1;
        // The budget counts from the first run's start.
        if (options.max_seconds > 0.0)
          next.max_seconds = std::max(1e-3, options.max_seconds - ElapsedSeconds());
        SOFTID_ASSIGN_OR_RETURN(
            DiagnosisReport restarted,
            DiagnoseAt(capture, job, config, compared_coarser, next, &*better, nullptr));
        report.seconds = ElapsedSeconds();
        nlohmann::json restart = {{"reason", "base fit in a local minimum"},
                                  {"via", via},
                                  {"cost_before", r0.cost},
                                  {"cost_after", better_cost},
                                  {"first_decision", report.decision},
                                  {"first_report", ToJson(report)}};
        restarted.base_restarts.insert(restarted.base_restarts.begin(), restart);
        restarted.seconds = std::chrono::duration<double>(Clock::now() - begin).count();
        return std::optional<DiagnosisReport>(std::move(restarted));
      }
    }
    return std::optional<DiagnosisReport>();
  }

  // Nuisances: accepted on their own, or part of the final model (physics found given them).
  void ListNuisances() {
    const TestedCandidate* winning = report.winner >= 0 ? &report.tested[report.winner] : nullptr;
    for (const TestedCandidate& t : report.tested) {
      if (t.test.conditional || !t.test.nuisance) continue;
      const bool in_final_model = winning != nullptr && winning->test.conditional &&
                                  winning->test.given == t.test.extension;
      if (!t.test.accepted && !in_final_model) continue;
      nlohmann::json entry = {
          {"nuisance", ToString(t.test.extension)}, {"parameters", t.values},
          {"uncertainty", t.uncertainty},           {"modelled", true},
          {"accepted_alone", t.test.accepted},      {"explains_mismatch", winning == &t}};
      if (winning == &t && FinalModelTest() == nullptr) entry["in_final_model"] = false;
      // Physics found despite the nuisance: whether the nuisance is still needed given it (then it
      // is part of the final model, with these values).
      if (report.winner >= 0 && !report.tested[report.winner].test.nuisance) {
        for (const TestedCandidate& c : report.tested) {
          if (!c.test.conditional || c.test.given != t.test.extension ||
              c.test.extension != report.tested[report.winner].test.extension)
            continue;
          entry["needed_given_physics"] = c.test.nuisance_needed;
          if (&c == &report.tested[report.winner])
            entry["parameters_in_final_model"] = c.nuisance_values;
        }
      }
      report.nuisances.push_back(entry);
    }
  }

  // The final model's fit, residuals and identifiability: the winner's, or the base's.
  // The test whose model is the final one: the winner's, except a nuisance that alone explained
  // the mismatch on a coarser step than the job's while its values take up that step's error
  // (Candidate::absorbs_step_error: the modulus follows them). It stays a reported nuisance; the
  // final model is then the base model.
  const TestedCandidate* FinalModelTest() const {
    if (report.winner < 0) return nullptr;
    const TestedCandidate& w = report.tested[report.winner];
    const bool step_bound_alone =
        w.test.nuisance && !w.test.conditional && GetCandidate(w.test.extension).absorbs_step_error;
    return compared_coarser && step_bound_alone ? nullptr : &w;
  }

  Status SettleFinalModel() {
    if (const TestedCandidate* final_test = FinalModelTest()) {
      const TestedCandidate& w = *final_test;
      report.after = w.after;
      report.final_fit = w.fit;
      report.identifiability =
          w.fit.contains("identifiability") ? w.fit["identifiability"] : nlohmann::json(nullptr);
      SOFTID_ASSIGN_OR_RETURN(final_residuals, ResidualsAt(context, w.parameters));
    } else {
      report.final_fit = report.base_fit;
      final_residuals = r0;
      if (!base_identifiability.is_null()) {
        report.identifiability = base_identifiability;
      } else if (options.identifiability) {
        Stage("identifiability of the base model");
        Result<inverse::IdentifiabilityReport> id = inverse::AnalyzeIdentifiability(
            capture, config, base, IdentifiabilityOptionsFor(config, ess0.n_eff));
        report.identifiability =
            id.ok() ? inverse::ToJson(*id) : nlohmann::json{{"error", id.status().message()}};
      }
    }
    return Status::Ok();
  }

  // 7. The final model refitted at the job's own discretisation from the compared optimum, when
  // the models were compared on a coarser one: the report's final parameters are then the job's
  // grid's and time step's. A failed refit leaves the compared final fit, with the error.
  void RefitAtTheJobsDiscretisation() {
    report.compared_at = {{"cells", config.solver.cells}, {"substeps", config.solver.substeps}};
    if (config.frames.last != job.frames.last)
      report.compared_at["predictable_last_frame"] = config.frames.last;
    if (!compared_coarser || Cancelled()) return;
    const TestedCandidate* winner = FinalModelTest();
    if (winner == nullptr && job_fit != nullptr) {
      // The final model is the base model, which the job has just fitted on its discretisation.
      report.final_fit = inverse::ToJson(*job_fit);
      report.compared_at["final_refit"] = {{"cells", job_fit->cells},
                                           {"substeps", job_fit->substeps},
                                           {"seconds", 0.0},
                                           {"reused", "the job's fit"}};
      return;
    }
    inverse::JobConfig final_config =
        RefitConfig(job, winner != nullptr ? winner->fitted : base.fitted,
                    winner != nullptr ? winner->parameters : p0);
    // On the grid and time step the job's own fit chose, when given: its values compare with the
    // job's, and its "auto" checks are not run again.
    if (job_fit != nullptr) final_config = inverse::WithFitDiscretisation(final_config, *job_fit);
    double& limit = final_config.solver.max_seconds;
    if (options.max_seconds > 0.0) {
      const double left = options.max_seconds - ElapsedSeconds();
      if (left <= 0.0) {
        report.compared_at["final_refit"] = {
            {"skipped", "the comparison took the whole time budget (max_seconds " +
                            std::to_string(options.max_seconds) + " s)"}};
        return;
      }
      limit = limit > 0.0 ? std::min(limit, left) : left;
    }
    Stage("final model refitted at the job's discretisation (compared at " +
          std::to_string(config.solver.cells) + " cells, " +
          std::to_string(config.solver.substeps) + " substeps per frame)");
    const auto refit_begin = Clock::now();
    Result<inverse::FitResult> fit = std::move(RunFits({final_config}).front());
    const double seconds = std::chrono::duration<double>(Clock::now() - refit_begin).count();
    if (fit.status().code() == StatusCode::kDeadlineExceeded) {
      // Its grid and time-step choices left too little of the budget for one evaluation.
      report.compared_at["final_refit"] = {{"skipped", fit.status().message()},
                                           {"seconds", seconds}};
      return;
    }
    if (!fit.ok()) {
      report.compared_at["final_refit"] = {{"error", fit.status().message()}, {"seconds", seconds}};
      return;
    }
    report.final_fit = inverse::ToJson(*fit);
    if (winner != nullptr) {
      report.final_values =
          ExtensionValues(winner->test.extension, fit->Best().final, DefaultK(fit->Best().final));
    }
    const inverse::StartResult& best = fit->Best();
    report.compared_at["final_refit"] = {{"cells", fit->cells},
                                         {"substeps", fit->substeps},
                                         {"seconds", seconds},
                                         {"iterations", best.iterations},
                                         {"converged", best.converged}};
    if (best.stopped_at_time_limit)
      report.compared_at["final_refit"]["stopped_at_time_limit_s"] = limit;
  }

  // The PNG plots, when a folder is given.
  Status WritePlots() {
    if (options.plot_directory.empty()) return Status::Ok();
    Stage("plots");
    const std::filesystem::path dir = options.plot_directory;
    const bool changed = report.winner >= 0;
    const std::string misfit_png = (dir / "residual_per_frame.png").string();
    std::vector<double> as_compared;  // with the time step's component
    if (report.time_step_error)
      for (const FrameResiduals& f : r0.map.frames) as_compared.push_back(f.misfit / sigma);
    SOFTID_RETURN_IF_ERROR(
        WriteFrameMisfitPlot(misfit_png, report.frames, report.before.frame_normalised,
                             changed ? report.after.frame_normalised : std::vector<double>{},
                             report.motion, rule.misfit_threshold, "before", as_compared));
    report.plots.push_back(misfit_png);
    int worst = 0;
    for (size_t k = 0; k < report.frames.size(); ++k)
      if (report.frames[k] == report.before.worst_frame) worst = static_cast<int>(k);
    std::vector<std::pair<std::string, const ResidualMap*>> rows = {{"before", &r0.map}};
    if (changed) rows.emplace_back("after", &final_residuals.map);
    const std::string painting_png = (dir / "residual_on_object.png").string();
    SOFTID_RETURN_IF_ERROR(
        WriteResidualPainting(painting_png, capture, context.observations, worst, rows, sigma));
    report.plots.push_back(painting_png);
    std::vector<Series> series;
    auto history = [](const std::string& label, const std::vector<double>& y) {
      Series out;
      out.label = label;
      out.y = y;
      for (size_t i = 0; i < out.y.size(); ++i) out.x.push_back(static_cast<double>(i));
      return out;
    };
    std::vector<double> base_history = {base.Best().initial_cost};
    for (double c : base.Best().CostHistoryOverEveryFrame()) base_history.push_back(c);
    series.push_back(history("base fit", base_history));
    for (const TestedCandidate& t : report.tested) {
      if (!t.cost_history.empty())
        series.push_back(history(
            std::string("+ ") + ToString(t.test.extension) +
                (t.test.conditional ? std::string(" + ") + ToString(t.test.given) : std::string()),
            t.cost_history));
    }
    const std::string cost_png = (dir / "cost_per_iteration.png").string();
    SOFTID_RETURN_IF_ERROR(WriteCostHistoryPlot(cost_png, series));
    report.plots.push_back(cost_png);
    return Status::Ok();
  }
};

}  // namespace

Status DiagnoseOptions::Validate() const {
  if (max_base_restarts < 0)
    return json::Invalid("max_base_restarts", max_base_restarts, "must be >= 0");
  SOFTID_RETURN_IF_ERROR(noise_floor.Validate());
  SOFTID_RETURN_IF_ERROR(phases.Validate());
  SOFTID_RETURN_IF_ERROR(screening.Validate());
  SOFTID_RETURN_IF_ERROR(decision.Validate());
  if (patches < 1) return json::Invalid("patches", patches, "must be >= 1");
  if (default_heldout_every < 2)
    return json::Invalid("default_heldout_every", default_heldout_every, "must be >= 2");
  if (comparison_cells != 0 && comparison_cells < 2)
    return json::Invalid("comparison_cells", comparison_cells, "must be 0 (the job's) or >= 2");
  if (comparison_substeps < 0)
    return json::Invalid("comparison_substeps", comparison_substeps, "must be >= 0");
  if (!(max_seconds >= 0.0 && std::isfinite(max_seconds)))
    return json::Invalid("max_seconds", max_seconds, "must be a finite number >= 0");
  return Status::Ok();
}

namespace {

// When the job lets "auto" choose its step and leaves the unpredictable frames out
// (predictable_frames_only), but the models are compared on a fixed coarser step, that step's
// check (inverse::CheckTimeStep, at the compared grid) finds where the motion turns chaotic, and
// the comparison stops there too: no model predicts those frames, and their misfit would be
// flagged as unexplained. Returns whether frames were cut.
Result<bool> KeepPredictableComparedFrames(const capture::Capture& capture,
                                           const inverse::JobConfig& job,
                                           const DiagnoseOptions& options,
                                           inverse::JobConfig* compared) {
  if (job.solver.substeps != inverse::kAutoSubsteps || !job.solver.predictable_frames_only ||
      compared->solver.substeps == inverse::kAutoSubsteps)
    return false;
  if (options.on_stage) options.on_stage("the time-step check at the compared grid");
  Result<inverse::TimeStepCheck> check =
      inverse::CheckTimeStep(capture, *compared, options.fit.cancel);
  if (!check.ok()) {
    if (check.status().code() == StatusCode::kInvalidArgument) return check.status();
    spdlog::warn("diagnosis: the time-step check: {} (every frame compared)",
                 check.status().message());
    return false;
  }
  const int last = check->predictable_last_frame;
  if (last < 0 || (compared->frames.last >= 0 && last >= compared->frames.last)) return false;
  spdlog::warn(
      "diagnosis: the frames after frame {} are not compared: halving the step no longer "
      "converges there (no affordable step predicts them), and the job's fit leaves them out too",
      last);
  compared->frames.last = last;
  return true;
}

Result<DiagnosisReport> DiagnoseAt(const capture::Capture& capture, const inverse::JobConfig& job,
                                   inverse::JobConfig compared, bool compared_coarser,
                                   const DiagnoseOptions& options,
                                   const inverse::FitResult* base_fit,
                                   const inverse::FitResult* job_fit) {
  DiagnosisRun run(capture, job, std::move(compared), options);
  run.compared_coarser = compared_coarser;
  run.job_fit = job_fit;
  return run.Run(base_fit);
}

}  // namespace

Result<DiagnosisReport> Diagnose(const capture::Capture& capture,
                                 const inverse::JobConfig& config_in,
                                 const DiagnoseOptions& options,
                                 const inverse::FitResult* base_fit) {
  SOFTID_RETURN_IF_ERROR(options.Validate());
  inverse::JobConfig config = config_in;
  config.diagnose = false;
  if (config.heldout_every == 0) config.heldout_every = options.default_heldout_every;
  SOFTID_RETURN_IF_ERROR(config.Validate());
  inverse::JobConfig compared = ComparisonConfig(config, options);
  // The likelihood ratios are those of least squares (Gaussian noise): the models are fitted and
  // compared by it whatever frame loss the job's own fit used.
  compared.solver.cost.frame_loss = inverse::FrameLossKind::kSquared;
  const bool compared_coarser = !SameDiscretisation(config.solver, compared.solver);
  SOFTID_ASSIGN_OR_RETURN(const bool frames_cut,
                          KeepPredictableComparedFrames(capture, config, options, &compared));
  // A given fit serves only when it held out the frames the diagnosis holds out, by least squares,
  // on the grid and time step the models are compared on.
  const bool usable = base_fit != nullptr && config_in.heldout_every > 0 && !frames_cut &&
                      RanAt(*base_fit, compared.solver) && base_fit->frame_loss.IsSquared();
  const inverse::FitResult* job_fit =
      base_fit != nullptr && RanAt(*base_fit, config.solver) ? base_fit : nullptr;
  return DiagnoseAt(capture, config, std::move(compared), compared_coarser, options,
                    usable ? base_fit : nullptr, job_fit);
}

}  // namespace softid::diagnosis
