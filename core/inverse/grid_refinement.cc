#include "core/inverse/grid_refinement.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <utility>

#include "core/common/json_fields.h"
#include "core/inverse/grid_selection.h"
#include "core/inverse/objective_settings.h"
#include "core/inverse/public_values.h"

namespace softid::inverse {
namespace {

double Length(const std::vector<double>& numbers) {
  double sum = 0.0;
  for (double x : numbers) sum += x * x;
  return std::sqrt(sum);
}

// The value whose grid error exceeds its threshold by the largest factor; decision->parameter
// stays empty when none does.
void FindWorstValue(const FitResult& fit, const FitUncertainty& uncertainty,
                    const DiscretisationError& errors, const GridRefinementOptions& options,
                    GridRefinementDecision* decision) {
  double worst = 0.0;
  for (size_t i = 0;
       i < fit.fitted.size() && i < errors.parameters.size() && i < uncertainty.parameters.size();
       ++i) {
    const std::string& name = fit.fitted[i];
    const std::vector<double> values = PublicNumbers(ParameterValueJson(fit.Best().final, name));
    const std::vector<double>& grid = errors.parameters[i].grid;
    const std::vector<double>& sigma = uncertainty.parameters[i].standard_uncertainty;
    const double magnitude = Length(values);
    for (size_t k = 0; k < grid.size() && k < sigma.size(); ++k) {
      // An undetermined value (sigma +inf) or a missing estimate says nothing of the grid.
      if (!std::isfinite(grid[k]) || !std::isfinite(sigma[k])) continue;
      const double threshold =
          std::max(options.sigma_multiple * sigma[k], options.relative_floor * magnitude);
      if (!(threshold > 0.0)) continue;
      if (grid[k] / threshold > std::max(worst, 1.0)) {
        worst = grid[k] / threshold;
        decision->parameter = name;
        decision->grid_error = grid[k];
        decision->threshold = threshold;
      }
    }
  }
}

Result<int> CountFinerGridNodes(const capture::Capture& capture, const JobConfig& config,
                                int finer_cells) {
  SOFTID_ASSIGN_OR_RETURN(geometry::TriangleMesh mesh, capture::LoadCaptureMesh(capture));
  JobConfig finer = config;
  finer.solver.cells = finer_cells;
  finer.solver.cell_size_m = 0.0;
  return CountGridNodes(mesh, SimulationOptionsFor(finer.solver), capture.fixed_region.has_value(),
                        finer_cells);
}

double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

Status GridRefinementOptions::Validate() const {
  if (!(sigma_multiple > 0.0 && std::isfinite(sigma_multiple)))
    return json::Invalid("sigma_multiple", sigma_multiple, "must be a finite number > 0");
  if (!(relative_floor >= 0.0 && std::isfinite(relative_floor)))
    return json::Invalid("relative_floor", relative_floor, "must be a finite number >= 0");
  if (max_grid_nodes < 1)
    return json::Invalid("max_grid_nodes", max_grid_nodes, "must be an integer >= 1");
  return Status::Ok();
}

GridRefinementDecision DecideGridRefinement(const FitResult& fit, const FitUncertainty& uncertainty,
                                            int finer_grid_nodes,
                                            const GridRefinementOptions& options) {
  GridRefinementDecision decision;
  decision.finer_grid_nodes = finer_grid_nodes;
  if (!uncertainty.discretisation) {
    decision.reason = "no discretisation estimate to judge the grid by";
    return decision;
  }
  const DiscretisationShift& shift = uncertainty.discretisation->grid;
  decision.cells = shift.chosen;
  decision.finer_cells = shift.compared;
  decision.ratio = shift.ratio > 1.0 ? shift.ratio : 1.5;
  if (!shift.error.empty()) {
    decision.reason = "the grid's error was not estimated: " + shift.error;
    return decision;
  }
  if (fit.best < 0) {
    decision.reason = "the fit has no result";
    return decision;
  }
  FindWorstValue(fit, uncertainty, *uncertainty.discretisation, options, &decision);
  const std::string grid =
      decision.cells > 0 ? fmt::format("{} cells", decision.cells) : std::string("the cell size");
  if (decision.parameter.empty()) {
    decision.reason =
        fmt::format("every fitted value's grid error is within max({} sigma, {:g} %) on {}",
                    options.sigma_multiple, 100.0 * options.relative_floor, grid);
    return decision;
  }
  const std::string asked =
      fmt::format("{}'s grid error {:.4g} exceeds {:.4g} (max({} sigma, {:g} %)) on {}",
                  decision.parameter, decision.grid_error, decision.threshold,
                  options.sigma_multiple, 100.0 * options.relative_floor, grid);
  if (finer_grid_nodes > options.max_grid_nodes) {
    decision.reason = fmt::format("{}, but {} cells keep {} nodes, above the budget of {}", asked,
                                  decision.finer_cells, finer_grid_nodes, options.max_grid_nodes);
    return decision;
  }
  decision.refine = true;
  decision.reason = decision.finer_cells > 0
                        ? fmt::format("{}: refit on {} cells", asked, decision.finer_cells)
                        : fmt::format("{}: refit on cells {:g} x smaller", asked, decision.ratio);
  return decision;
}

JobConfig WithFinerGrid(JobConfig config, const GridRefinementDecision& decision) {
  if (config.solver.cell_size_m > 0.0) {
    config.solver.cell_size_m /= decision.ratio;
  } else {
    config.solver.cells = decision.finer_cells;
  }
  return config;
}

JobConfig RefinementConfig(const JobConfig& config, const FitResult& fit,
                           const GridRefinementDecision& decision) {
  JobConfig out = WithFinerGrid(WithFitDiscretisation(config, fit), decision);
  out.initial.clear();
  for (const std::string& name : fit.fitted) {
    InitialValue start;
    start.value = ParameterValueJson(fit.Best().final, name);
    out.initial[name] = start;
  }
  out.solver.starts = 1;
  // Local: the refit starts at the optimum of a grid that differs by its discretisation error
  // only, inside the basin the first fit found over every frame.
  out.solver.continuation = false;
  return out;
}

namespace {

// The decision, with the finer grid's nodes counted on the capture's mesh when it would refine.
GridRefinementDecision DecideOnCapture(const capture::Capture& capture, const JobConfig& config,
                                       const FitResult& fit, const FitUncertainty& uncertainty,
                                       const GridRefinementOptions& options) {
  GridRefinementDecision decision = DecideGridRefinement(fit, uncertainty, -1, options);
  if (!decision.refine || decision.finer_cells <= 0) return decision;
  const Result<int> nodes = CountFinerGridNodes(capture, config, decision.finer_cells);
  if (nodes.ok()) return DecideGridRefinement(fit, uncertainty, *nodes, options);
  spdlog::warn("grid refinement: the finer grid's nodes were not counted: {}",
               nodes.status().message());
  return decision;
}

// The refit `decision` asks for under `refit_config`, or why it was not made or did not finish
// (then appended to the decision's reason). A time limit covers the fit and its refit: the refit
// gets what the first fit left.
Result<FitResult> Refit(const capture::Capture& capture, JobConfig* refit_config,
                        const FitResult& fit, const FitOptions& options, double seconds_since_fit,
                        GridRefinementDecision* decision) {
  const double limit = refit_config->solver.max_seconds;
  if (limit > 0.0) {
    const double left = limit - fit.total_seconds - seconds_since_fit;
    if (left <= 0.0) {
      decision->reason +=
          fmt::format("; not made: the fit's max_seconds = {:g} has run out", limit);
      return Status::DeadlineExceeded(decision->reason);
    }
    refit_config->solver.max_seconds = left;
  }
  Result<FitResult> refit = Fit(capture, *refit_config, options);
  if (!refit.ok() || refit->cancelled) {
    decision->reason +=
        refit.ok() ? "; cancelled: the first fit is the result"
                   : "; failed (" + refit.status().message() + "): the first fit is the result";
    spdlog::warn("grid refinement: {}", decision->reason);
    if (refit.ok()) return Status::Cancelled(decision->reason);
  }
  return refit;
}

}  // namespace

ControlledFit ControlGrid(const capture::Capture& capture, const JobConfig& config, FitResult fit,
                          FitUncertainty uncertainty, const FitOptions& options,
                          const GridRefinementOptions& refinement) {
  const auto start = std::chrono::steady_clock::now();
  ControlledFit out;
  GridRefinementDecision decision = DecideOnCapture(capture, config, fit, uncertainty, refinement);
  spdlog::info("grid refinement: {}", decision.reason);
  JobConfig refit_config;
  Result<FitResult> refit = Status::Internal("not refitted");
  if (decision.refine) {
    refit_config = RefinementConfig(config, fit, decision);
    refit = Refit(capture, &refit_config, fit, options, SecondsSince(start), &decision);
  }
  out.refinement.decision = decision;
  if (!refit.ok()) {
    out.config = config;
    out.fit = std::move(fit);
    out.uncertainty = std::move(uncertainty);
    out.refinement.seconds = SecondsSince(start);
    return out;
  }
  out.refinement.refined = true;
  out.refinement.first_fit = ToJson(fit, &uncertainty);
  // The refit's grid, time step and frames with the caller's starts: what later analyses (the
  // report, the diagnosis) must see.
  out.config = WithFinerGrid(WithFitDiscretisation(config, fit), decision);
  out.fit = std::move(refit).value();
  Result<FitUncertainty> analysed = EstimateFitUncertainty(capture, refit_config, out.fit);
  if (analysed.ok()) {
    out.uncertainty = std::move(analysed).value();
  } else {
    out.uncertainty_error = analysed.status().message();
  }
  out.refinement.seconds = SecondsSince(start);
  return out;
}

nlohmann::json ToJson(const GridRefinement& refinement) {
  const GridRefinementDecision& d = refinement.decision;
  nlohmann::json json = {
      {"refined", refinement.refined},
      {"cells", d.cells},
      {"finer_cells", d.finer_cells},
      {"finer_grid_nodes",
       d.finer_grid_nodes >= 0 ? nlohmann::json(d.finer_grid_nodes) : nlohmann::json(nullptr)},
      {"reason", d.reason},
      {"seconds", refinement.seconds},
  };
  if (!d.parameter.empty()) {
    json["parameter"] = d.parameter;
    json["grid_error"] = d.grid_error;
    json["threshold"] = d.threshold;
  }
  if (refinement.refined) json["first_fit"] = refinement.first_fit;
  return json;
}

}  // namespace softid::inverse
