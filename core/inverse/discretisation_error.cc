#include "core/inverse/discretisation_error.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <thread>

#include "core/inverse/objective_settings.h"
#include "core/inverse/public_values.h"
#include "core/inverse/trajectory_objective.h"

namespace softid::inverse {
namespace {

constexpr double kInfinity = std::numeric_limits<double>::infinity();
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
// Refinement ratio of the grid level compared with: the step of GridSelectionOptions' candidates.
constexpr double kGridRatio = 1.5;
// Assumed order of convergence in h and dt (see the header).
constexpr double kOrder = 1.0;

// What the fit saw: its mesh, frames and variables.
struct FitSetting {
  geometry::TriangleMesh mesh;
  std::shared_ptr<const std::vector<ObservedFrame>> frames;
  FrameLoss frame_loss;  // the fit's
};

Result<FitSetting> LoadFitSetting(const capture::Capture& capture, const JobConfig& config) {
  FitSetting setting;
  SOFTID_ASSIGN_OR_RETURN(setting.mesh, capture::LoadCaptureMesh(capture));
  SOFTID_ASSIGN_OR_RETURN(setting.frames, LoadFittedFrames(capture, config));
  return setting;
}

// The finer level at x*: its objective, gradient in the optimiser's variables and cost.
struct FinerLevel {
  std::unique_ptr<TrajectoryObjective> objective;
  Eigen::VectorXd gradient;
  double cost = 0.0;
};

// The finer level with the given simulation and time step, evaluated at x*; an error when the run
// diverges.
Result<FinerLevel> EvaluateFinerLevel(const FitSetting& setting, const capture::Capture& capture,
                                      const JobConfig& config,
                                      const fem::SimulationOptions& simulation, int substeps,
                                      const ParameterSpace& space,
                                      const fem::PhysicalParameters& optimum) {
  FinerLevel out;
  try {
    out.objective = std::make_unique<TrajectoryObjective>(
        setting.mesh, capture.fixed_region, optimum, simulation, CostOptionsFor(config.solver),
        setting.frames, capture.fps, substeps);
  } catch (const std::invalid_argument& e) {
    return Status::InvalidArgument(e.what());
  }
  out.objective->SetFrameLoss(setting.frame_loss);
  SOFTID_ASSIGN_OR_RETURN(ObjectiveEvaluation evaluation, out.objective->Evaluate(optimum, true));
  if (evaluation.diverged) return Status::FailedPrecondition("the simulation diverged");
  out.cost = evaluation.cost;
  out.gradient.resize(space.NumVariables());
  const std::vector<double> x = space.ToVariables(optimum);
  space.ChainGradient(evaluation.gradient, x.data(), out.gradient.data());
  return out;
}

// Scales shift->variables by the share of the Newton step the finer level's cost follows
// (StepScaleAlong, from one forward run at x* + dx); unbounded variables do not move.
Status FollowTheFinerCost(FinerLevel& finer, const ParameterSpace& space,
                          const fem::PhysicalParameters& optimum, const Eigen::MatrixXd& hessian,
                          DiscretisationShift* shift) {
  Eigen::VectorXd step = shift->variables;
  for (Eigen::Index i = 0; i < step.size(); ++i) {
    if (!std::isfinite(step[i])) step[i] = 0.0;
  }
  if (step.isZero(0.0)) return Status::Ok();
  const std::vector<double> x = space.ToVariables(optimum);
  std::vector<double> stepped = x;
  for (size_t i = 0; i < stepped.size(); ++i) stepped[i] += step[static_cast<Eigen::Index>(i)];
  SOFTID_ASSIGN_OR_RETURN(
      const ObjectiveEvaluation at_step,
      finer.objective->Evaluate(space.ToParameters(stepped.data(), optimum), false));
  if (at_step.diverged) return Status::FailedPrecondition("the simulation diverged at x* + dx");
  shift->cost_at_optimum = finer.cost;
  shift->cost_at_step = at_step.cost;
  shift->step_scale = StepScaleAlong(finer.cost, at_step.cost, 0.5 * step.dot(hessian * step));
  if (shift->step_scale == 0.0) {
    return Status::FailedPrecondition(fmt::format(
        "the finer level's cost rises along the Newton step ({:.4g} m^2 at the optimum, {:.4g} "
        "at the step): its gradient does not lead to its optimum here, so no estimate",
        finer.cost, at_step.cost));
  }
  for (Eigen::Index i = 0; i < shift->variables.size(); ++i) {
    if (std::isfinite(shift->variables[i])) shift->variables[i] *= shift->step_scale;
  }
  return Status::Ok();
}

// dx = -H^-1 (g_finer - g) over the free variables, through the analysis' pseudo-inverse of
// their block of H: +inf for unbounded variables, 0 for held ones.
Eigen::VectorXd NewtonShift(const IdentifiabilityReport& report, const Eigen::VectorXd& finer,
                            const std::vector<bool>& held) {
  std::vector<Eigen::Index> free;
  for (Eigen::Index i = 0; i < finer.size(); ++i) {
    if (!held[static_cast<size_t>(i)]) free.push_back(i);
  }
  const Eigen::Index n = static_cast<Eigen::Index>(free.size());
  if (n == 0) return Eigen::VectorXd::Zero(finer.size());
  Eigen::MatrixXd block(n, n);
  for (Eigen::Index a = 0; a < n; ++a) {
    for (Eigen::Index b = 0; b < n; ++b) block(a, b) = report.hessian(free[a], free[b]);
  }
  const HessianCovariance inverse = CovarianceFromHessian(block, 1.0);
  const Eigen::VectorXd difference = finer - report.gradient;
  Eigen::VectorXd shift = Eigen::VectorXd::Zero(finer.size());
  for (Eigen::Index a = 0; a < n; ++a) {
    double& entry = shift[free[a]];
    if (!std::isfinite(inverse.covariance(a, a))) {
      entry = kInfinity;
      continue;
    }
    for (Eigen::Index b = 0; b < n; ++b) {
      if (std::isfinite(inverse.covariance(a, b)))
        entry -= inverse.covariance(a, b) * difference[free[b]];
    }
  }
  return shift;
}

// Per variable, whether the fit held it after measuring it on its own frames (the launch,
// measured in flight: flight_stage.h). A refit on a finer level would measure it again on those
// frames of rigid motion, where the discretisation barely matters, and hold it: it does not move.
std::vector<bool> HeldVariables(const ParameterSpace& space, const FitResult& fit) {
  std::vector<bool> held(static_cast<size_t>(space.NumVariables()), false);
  if (!fit.Best().flight) return held;
  for (const std::string& name : fit.Best().flight->held) {
    for (size_t i = 0; i < held.size(); ++i) {
      const std::string& variable = space.variable_names()[i];
      if (variable == name || variable.rfind(name + "[", 0) == 0) held[i] = true;
    }
  }
  return held;
}

// J dx scaled by the level's error factor: the signed correction of each public number towards
// the continuum; NaN when the shift is missing, +-inf where unbounded.
std::vector<double> PublicCorrection(const Eigen::MatrixXd& jacobian,
                                     const DiscretisationShift& shift) {
  std::vector<double> out(static_cast<size_t>(jacobian.rows()), kNaN);
  if (!shift.error.empty() || shift.variables.size() != jacobian.cols()) return out;
  for (Eigen::Index k = 0; k < jacobian.rows(); ++k) {
    const double scale = std::max(1e-300, jacobian.row(k).cwiseAbs().maxCoeff());
    double sum = 0.0;
    for (Eigen::Index j = 0; j < jacobian.cols(); ++j) {
      if (std::abs(jacobian(k, j)) <= 1e-9 * scale) continue;
      sum += jacobian(k, j) * shift.variables[j];
    }
    out[static_cast<size_t>(k)] = sum * shift.error_factor;
  }
  return out;
}

// The estimates of one fitted parameter from the two signed corrections.
ParameterDiscretisationError ParameterError(const std::string& name,
                                            const std::vector<double>& value,
                                            const std::vector<double>& grid,
                                            const std::vector<double>& time) {
  ParameterDiscretisationError entry{name, {}, {}, {}, {}};
  for (size_t k = 0; k < grid.size(); ++k) {
    const double g = grid[k], t = time[k];
    entry.grid.push_back(std::abs(g));
    entry.time_step.push_back(std::abs(t));
    // A missing level counts as 0 in the sum only if the other is there; both missing: NaN.
    entry.total.push_back(std::isnan(g) && std::isnan(t) ? kNaN
                                                         : (std::isnan(g) ? 0.0 : std::abs(g)) +
                                                               (std::isnan(t) ? 0.0 : std::abs(t)));
    const double corrected = k < value.size() ? value[k] + g + t : kNaN;
    entry.corrected.push_back(std::isfinite(corrected) ? corrected : kNaN);
  }
  return entry;
}

// Estimates one level's shift of the optimum: a Newton step onto a finer discretisation.
struct ShiftEstimator {
  const FitSetting& setting;
  const capture::Capture& capture;
  const JobConfig& config;
  const ParameterSpace& space;
  const fem::PhysicalParameters& optimum;
  const IdentifiabilityReport& report;
  const std::vector<bool>& held;

  // Fills shift's error factor and variables (or error) from a run with the finer simulation
  // options or substeps; shift->ratio is set.
  // `level` names the level in the progress line ("cells", "substeps").
  void operator()(const char* level, DiscretisationShift* shift,
                  const fem::SimulationOptions& finer_simulation, int finer_substeps) const {
    // Richardson: x_h - x_exact ~ (x_h - x_{h/r}) r^p / (r^p - 1).
    const double gain = std::pow(shift->ratio, kOrder);
    shift->error_factor = gain / (gain - 1.0);
    const auto begin = std::chrono::steady_clock::now();
    Result<FinerLevel> finer = EvaluateFinerLevel(setting, capture, config, finer_simulation,
                                                  finer_substeps, space, optimum);
    if (!finer.ok()) {
      shift->error = std::string(finer.status().message());
    } else {
      shift->variables = NewtonShift(report, finer->gradient, held);
      const Status followed = FollowTheFinerCost(*finer, space, optimum, report.hessian, shift);
      if (!followed.ok()) {
        shift->error = std::string(followed.message());
        shift->variables.resize(0);
      }
    }
    spdlog::info("discretisation error: {} {} vs {} done in {:.0f} s{}", level, shift->chosen,
                 shift->compared,
                 std::chrono::duration<double>(std::chrono::steady_clock::now() - begin).count(),
                 shift->error.empty() ? "" : " (no estimate: " + shift->error + ")");
  }
};

// The grid 1.5 x finer: sets grid's levels and ratio, returns the finer grid's options.
fem::SimulationOptions FinerGrid(const JobConfig& config, const fem::SimulationOptions& simulation,
                                 DiscretisationShift* grid) {
  grid->chosen = config.solver.cell_size_m > 0.0 ? 0 : config.solver.cells;
  fem::SimulationOptions finer_grid = simulation;
  if (config.solver.cell_size_m > 0.0) {
    finer_grid.cell_size = config.solver.cell_size_m / kGridRatio;
    grid->ratio = kGridRatio;
  } else {
    grid->compared = static_cast<int>(std::lround(config.solver.cells * kGridRatio));
    finer_grid.cells_along_longest_side = grid->compared;
    grid->ratio = static_cast<double>(grid->compared) / config.solver.cells;
  }
  return finer_grid;
}

// The per-parameter estimates of both levels' shifts, in the order of `fitted`.
std::vector<ParameterDiscretisationError> ParameterErrors(const std::vector<std::string>& fitted,
                                                          const ParameterSpace& space,
                                                          const fem::PhysicalParameters& optimum,
                                                          const DiscretisationShift& grid,
                                                          const DiscretisationShift& time) {
  std::vector<ParameterDiscretisationError> out;
  const std::vector<double> x = space.ToVariables(optimum);
  for (const std::string& name : fitted) {
    const Eigen::MatrixXd jacobian = PublicJacobian(space, x, optimum, name);
    const std::vector<double> value = PublicNumbers(ParameterValueJson(optimum, name));
    ParameterDiscretisationError entry = ParameterError(
        name, value, PublicCorrection(jacobian, grid), PublicCorrection(jacobian, time));
    out.push_back(std::move(entry));
  }
  return out;
}

}  // namespace

double StepScaleAlong(double c0, double c1, double b) {
  if (!(b > 0.0) || !std::isfinite(c0) || !std::isfinite(c1)) return 1.0;
  const double a = c1 - c0 - b;
  return std::clamp(-a / (2.0 * b), 0.0, 1.0);
}

Result<DiscretisationError> EstimateDiscretisationError(const capture::Capture& capture,
                                                        const JobConfig& config_in,
                                                        const FitResult& fit,
                                                        const IdentifiabilityReport& report) {
  const auto begin = std::chrono::steady_clock::now();
  if (fit.best < 0 || fit.best >= static_cast<int>(fit.starts.size()))
    return Status::FailedPrecondition("discretisation error: the fit has no usable start");
  const JobConfig config = WithFitDiscretisation(config_in, fit);
  SOFTID_ASSIGN_OR_RETURN(FitSetting setting, LoadFitSetting(capture, config));
  setting.frame_loss = fit.frame_loss;
  SOFTID_ASSIGN_OR_RETURN(
      const ParameterSpace space,
      ParameterSpace::Create(fit.fitted, fit.base, setting.mesh.Bounds().sizes().maxCoeff()));
  const int n = space.NumVariables();
  if (report.hessian.rows() != n || report.gradient.size() != n) {
    return Status::InvalidArgument(
        fmt::format("report: Hessian of {} variables for a fit of {}", report.hessian.rows(), n));
  }
  const fem::PhysicalParameters& optimum = fit.Best().final;
  fem::SimulationOptions simulation = SimulationOptionsFor(config.solver);
  // The two estimates run side by side when there are two cores, one simulation thread each.
  const int cores = config.solver.threads > 0
                        ? config.solver.threads
                        : static_cast<int>(std::thread::hardware_concurrency());
  simulation.threads = std::max(1, cores / 2);
  DiscretisationError out;
  const std::vector<bool> held = HeldVariables(space, fit);
  const ShiftEstimator estimate{setting, capture, config, space, optimum, report, held};

  DiscretisationShift& grid = out.grid;
  const fem::SimulationOptions finer_grid = FinerGrid(config, simulation, &grid);
  // Twice the time steps.
  DiscretisationShift& time = out.time_step;
  time.chosen = config.solver.substeps;
  time.compared = 2 * config.solver.substeps;
  time.ratio = 2.0;
  const std::string finer_grid_name =
      grid.chosen > 0 ? fmt::format("{} cells (chosen {})", grid.compared, grid.chosen)
                      : fmt::format("cells of {:.3g} mm (chosen {:.3g} mm)",
                                    1e3 * finer_grid.cell_size, 1e3 * config.solver.cell_size_m);
  spdlog::info(
      "discretisation error: the optimum's cost and gradient on {} and at {} substeps (chosen {})",
      finer_grid_name, time.compared, time.chosen);
  {
    std::jthread time_worker;
    if (cores >= 2) {
      time_worker = std::jthread([&] { estimate("substeps", &time, simulation, time.compared); });
    } else {
      estimate("substeps", &time, simulation, time.compared);
    }
    estimate("cells", &grid, finer_grid, config.solver.substeps);
  }

  out.parameters = ParameterErrors(fit.fitted, space, optimum, grid, time);
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - begin).count();
  spdlog::info("discretisation error: grid {} vs {} cells, time step {} vs {} substeps, {:.1f} s",
               grid.chosen, grid.compared, time.chosen, time.compared, out.seconds);
  return out;
}

nlohmann::json ToJson(const DiscretisationError& error) {
  auto shift_json = [](const DiscretisationShift& shift, const char* level, const char* compared) {
    nlohmann::json out = {{level, shift.chosen},
                          {compared, shift.compared},
                          {"ratio", shift.ratio},
                          {"error_factor", shift.error_factor}};
    if (std::isfinite(shift.step_scale)) {
      out["step_scale"] = shift.step_scale;
      out["cost_at_optimum"] = shift.cost_at_optimum;
      out["cost_at_step"] = shift.cost_at_step;
    }
    if (!shift.error.empty()) out["error"] = shift.error;
    return out;
  };
  return {{"method",
           "one Newton step of the optimum onto a finer grid (h / 1.5) and time step (dt / 2), "
           "scaled to the minimum of the finer level's cost along it (step_scale); error = shift "
           "r / (r - 1) (Richardson, first order)"},
          {"grid", shift_json(error.grid, "cells", "compared_cells")},
          {"time_step", shift_json(error.time_step, "substeps", "compared_substeps")},
          {"seconds", error.seconds}};
}

}  // namespace softid::inverse
