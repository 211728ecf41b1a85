#include "core/inverse/solver_options.h"

#include <algorithm>
#include <cmath>
#include <initializer_list>
#include <string>
#include <utility>

#include "core/common/json_fields.h"
#include "core/geometry/cut_cell_weights.h"

namespace softid::inverse {
namespace {

using Json = nlohmann::json;

// The requirements, shared by the parser and Validate so both say the same.
constexpr const char* kCellsRequirement = "must be \"auto\" or an integer >= 2";
constexpr const char* kSubstepsRequirement = "must be \"auto\" or an integer >= 1";
constexpr const char* kRhoInfinityRequirement = "must be a number in [0, 1]";
constexpr const char* kPositiveRequirement = "must be a finite number > 0";
constexpr const char* kGradientRequirement = "must be \"adjoint\" or \"finite_difference\"";
constexpr const char* kElementRequirement = "must be \"trilinear\" or \"incompatible_modes\"";
constexpr const char* kGridOrientationRequirement = "must be \"world\" or \"body\"";
constexpr const char* kCutCellSamplesRequirement = "must be 1, 2, 4 or 8";
constexpr const char* kRestSdfRequirement = "must be \"surface_fitted\", \"exact\" or \"sampled\"";
constexpr const char* kFrameLossRequirement = "must be \"squared\" or \"cauchy\"";
constexpr auto kCostKeys = std::to_array<std::string_view>(
    {"band_cells", "truncation_cells", "rest_sdf", "frame_loss", "frame_loss_noise_multiple"});

std::string AtLeast(int min) {
  return "must be an integer >= " + std::to_string(min);
}

bool IsPositiveFinite(double x) {
  return std::isfinite(x) && x > 0.0;
}

Result<CostSettings> ParseCost(const Json& value) {
  if (!value.is_object()) {
    return json::Invalid(
        "cost", value,
        "must be an object {\"band_cells\": n, \"truncation_cells\": x, \"rest_sdf\": s}");
  }
  for (const auto& item : value.items()) {
    if (std::find(kCostKeys.begin(), kCostKeys.end(), item.key()) == kCostKeys.end()) {
      return Status::InvalidArgument("cost: unknown key \"" + item.key() + "\"");
    }
  }
  CostSettings settings;
  if (value.contains("band_cells")) {
    SOFTID_ASSIGN_OR_RETURN(settings.band_cells,
                            json::ToIntegerAtLeast(value["band_cells"], "cost.band_cells", 1));
  }
  if (value.contains("truncation_cells")) {
    SOFTID_ASSIGN_OR_RETURN(
        settings.truncation_cells,
        json::ToPositiveNumber(value["truncation_cells"], "cost.truncation_cells"));
  }
  if (value.contains("rest_sdf")) {
    const Json& rest_sdf = value["rest_sdf"];
    bool known = false;
    for (cost::RestSdf mode :
         {cost::RestSdf::kSurfaceFitted, cost::RestSdf::kExact, cost::RestSdf::kSampled}) {
      if (rest_sdf.is_string() && rest_sdf.get<std::string>() == cost::ToString(mode)) {
        settings.rest_sdf = mode;
        known = true;
      }
    }
    if (!known) return json::Invalid("cost.rest_sdf", rest_sdf, kRestSdfRequirement);
  }
  if (value.contains("frame_loss")) {
    const Json& loss = value["frame_loss"];
    bool known = false;
    for (FrameLossKind kind : {FrameLossKind::kSquared, FrameLossKind::kCauchy}) {
      if (loss.is_string() && loss.get<std::string>() == ToString(kind)) {
        settings.frame_loss = kind;
        known = true;
      }
    }
    if (!known) return json::Invalid("cost.frame_loss", loss, kFrameLossRequirement);
  }
  if (value.contains("frame_loss_noise_multiple")) {
    SOFTID_ASSIGN_OR_RETURN(settings.frame_loss_noise_multiple,
                            json::ToPositiveNumber(value["frame_loss_noise_multiple"],
                                                   "cost.frame_loss_noise_multiple"));
  }
  return settings;
}

Result<fem::ElementFormulation> ParseElement(const Json& value) {
  for (fem::ElementFormulation element :
       {fem::ElementFormulation::kIncompatibleModes, fem::ElementFormulation::kTrilinear}) {
    if (value.is_string() && value.get<std::string>() == fem::ToString(element)) return element;
  }
  return json::Invalid("element", value, kElementRequirement);
}

Result<fem::GridOrientation> ParseGridOrientation(const Json& value) {
  for (fem::GridOrientation orientation :
       {fem::GridOrientation::kWorld, fem::GridOrientation::kBody}) {
    if (value.is_string() && value.get<std::string>() == fem::ToString(orientation))
      return orientation;
  }
  return json::Invalid("grid_orientation", value, kGridOrientationRequirement);
}

Result<GradientMethod> ParseGradient(const Json& value) {
  for (GradientMethod method : {GradientMethod::kAdjoint, GradientMethod::kFiniteDifference}) {
    if (value.is_string() && value.get<std::string>() == ToString(method)) return method;
  }
  return json::Invalid("gradient", value, kGradientRequirement);
}

// "auto" -> `auto_value`, otherwise an integer >= min.
Result<int> ParseAutoOrInteger(const Json& value, const std::string& field, int auto_value, int min,
                               const char* requirement) {
  if (value == Json("auto")) return auto_value;
  return json::ToIntegerAtLeast(value, field, min, requirement);
}

Result<bool> ParseBool(const Json& value, const std::string& field) {
  if (!value.is_boolean()) return json::Invalid(field, value, "must be true or false");
  return value.get<bool>();
}

// The grid, time step and integrator keys.
Status ParseDiscretisation(const Json& j, SolverOptions* options) {
  if (j.contains("cells")) {
    SOFTID_ASSIGN_OR_RETURN(
        options->cells, ParseAutoOrInteger(j["cells"], "cells", kAutoCells, 2, kCellsRequirement));
  }
  if (j.contains("cell_size")) {
    SOFTID_ASSIGN_OR_RETURN(options->cell_size_m,
                            json::ToPositiveNumber(j["cell_size"], "cell_size"));
  }
  if (j.contains("substeps")) {
    SOFTID_ASSIGN_OR_RETURN(
        options->substeps,
        ParseAutoOrInteger(j["substeps"], "substeps", kAutoSubsteps, 1, kSubstepsRequirement));
  }
  if (j.contains("rho_infinity")) {
    const Json& value = j["rho_infinity"];
    if (!value.is_number() || !(value.get<double>() >= 0.0 && value.get<double>() <= 1.0))
      return json::Invalid("rho_infinity", value, kRhoInfinityRequirement);
    options->rho_infinity = value.get<double>();
  }
  if (j.contains("element")) {
    SOFTID_ASSIGN_OR_RETURN(options->element, ParseElement(j["element"]));
  }
  if (j.contains("grid_orientation")) {
    SOFTID_ASSIGN_OR_RETURN(options->grid_orientation, ParseGridOrientation(j["grid_orientation"]));
  }
  if (j.contains("cut_cell_samples")) {
    const Json& value = j["cut_cell_samples"];
    if (!value.is_number_integer() || !geometry::IsCutCellSampling(value.get<int>())) {
      return json::Invalid("cut_cell_samples", value, kCutCellSamplesRequirement);
    }
    options->cut_cell_samples = value.get<int>();
  }
  return Status::Ok();
}

// The starts, threads and seed.
Status ParseStarts(const Json& j, SolverOptions* options) {
  if (j.contains("starts")) {
    SOFTID_ASSIGN_OR_RETURN(options->starts, json::ToIntegerAtLeast(j["starts"], "starts", 1));
  }
  if (j.contains("threads")) {
    SOFTID_ASSIGN_OR_RETURN(options->threads, json::ToIntegerAtLeast(j["threads"], "threads", 0));
  }
  if (j.contains("seed")) {
    const Json& seed = j["seed"];
    if (!seed.is_number_unsigned() &&
        !(seed.is_number_integer() && seed.get<std::int64_t>() >= 0)) {
      return json::Invalid("seed", seed, "must be an integer >= 0");
    }
    options->seed = seed.get<std::uint64_t>();
  }
  return Status::Ok();
}

// The optimiser's stopping criteria, gradient, continuation and refinement.
Status ParseOptimiser(const Json& j, SolverOptions* options) {
  if (j.contains("max_iterations")) {
    SOFTID_ASSIGN_OR_RETURN(options->max_iterations,
                            json::ToIntegerAtLeast(j["max_iterations"], "max_iterations", 1));
  }
  for (auto [key, target] :
       {std::pair{"function_tolerance", &options->function_tolerance},
        std::pair{"gradient_tolerance", &options->gradient_tolerance},
        std::pair{"parameter_tolerance", &options->parameter_tolerance},
        std::pair{"finite_difference_step", &options->finite_difference_step}}) {
    if (j.contains(key)) {
      SOFTID_ASSIGN_OR_RETURN(*target, json::ToPositiveNumber(j[key], key));
    }
  }
  if (j.contains("max_seconds")) {
    SOFTID_ASSIGN_OR_RETURN(options->max_seconds,
                            json::ToFiniteNumber(j["max_seconds"], "max_seconds"));
    if (options->max_seconds < 0.0)
      return json::Invalid("max_seconds", j["max_seconds"], "must be a finite number >= 0");
  }
  if (j.contains("refine_iterations")) {
    SOFTID_ASSIGN_OR_RETURN(options->refine_iterations,
                            json::ToIntegerAtLeast(j["refine_iterations"], "refine_iterations", 0));
  }
  if (j.contains("gradient")) {
    SOFTID_ASSIGN_OR_RETURN(options->gradient, ParseGradient(j["gradient"]));
  }
  if (j.contains("continuation")) {
    SOFTID_ASSIGN_OR_RETURN(options->continuation, ParseBool(j["continuation"], "continuation"));
  }
  if (j.contains("launch_from_flight")) {
    SOFTID_ASSIGN_OR_RETURN(options->launch_from_flight,
                            ParseBool(j["launch_from_flight"], "launch_from_flight"));
  }
  if (j.contains("predictable_frames_only")) {
    SOFTID_ASSIGN_OR_RETURN(options->predictable_frames_only,
                            ParseBool(j["predictable_frames_only"], "predictable_frames_only"));
  }
  return Status::Ok();
}

Status ValidateCost(const CostSettings& cost) {
  if (cost.band_cells < 1) return json::Invalid("cost.band_cells", cost.band_cells, AtLeast(1));
  if (!IsPositiveFinite(cost.truncation_cells)) {
    return json::Invalid("cost.truncation_cells", cost.truncation_cells, kPositiveRequirement);
  }
  if (!IsPositiveFinite(cost.frame_loss_noise_multiple)) {
    return json::Invalid("cost.frame_loss_noise_multiple", cost.frame_loss_noise_multiple,
                         kPositiveRequirement);
  }
  if (cost.frame_loss != FrameLossKind::kSquared && cost.frame_loss != FrameLossKind::kCauchy) {
    return json::Invalid("cost.frame_loss", static_cast<int>(cost.frame_loss),
                         kFrameLossRequirement);
  }
  for (cost::RestSdf mode :
       {cost::RestSdf::kSurfaceFitted, cost::RestSdf::kExact, cost::RestSdf::kSampled}) {
    if (cost.rest_sdf == mode) return Status::Ok();
  }
  return json::Invalid("cost.rest_sdf", static_cast<int>(cost.rest_sdf), kRestSdfRequirement);
}

}  // namespace

const char* ToString(GradientMethod method) {
  switch (method) {
    case GradientMethod::kAdjoint: return "adjoint";
    case GradientMethod::kFiniteDifference: return "finite_difference";
  }
  return "invalid";  // a value cast from an out-of-range integer; Validate rejects it
}

Status SolverOptions::Validate() const {
  if (cells != kAutoCells && cells < 2) return json::Invalid("cells", cells, kCellsRequirement);
  if (cell_size_m != 0.0 && !IsPositiveFinite(cell_size_m)) {
    return json::Invalid("cell_size", cell_size_m, kPositiveRequirement);
  }
  if (substeps != kAutoSubsteps && substeps < 1) {
    return json::Invalid("substeps", substeps, kSubstepsRequirement);
  }
  if (rho_infinity != kNewmark && !(rho_infinity >= 0.0 && rho_infinity <= 1.0)) {
    return json::Invalid("rho_infinity", rho_infinity, kRhoInfinityRequirement);
  }
  if (element != fem::ElementFormulation::kIncompatibleModes &&
      element != fem::ElementFormulation::kTrilinear) {
    return json::Invalid("element", static_cast<int>(element), kElementRequirement);
  }
  if (grid_orientation != fem::GridOrientation::kWorld &&
      grid_orientation != fem::GridOrientation::kBody) {
    return json::Invalid("grid_orientation", static_cast<int>(grid_orientation),
                         kGridOrientationRequirement);
  }
  if (!geometry::IsCutCellSampling(cut_cell_samples)) {
    return json::Invalid("cut_cell_samples", cut_cell_samples, kCutCellSamplesRequirement);
  }
  if (starts < 1) return json::Invalid("starts", starts, AtLeast(1));
  if (threads < 0) return json::Invalid("threads", threads, AtLeast(0));
  if (max_iterations < 1) return json::Invalid("max_iterations", max_iterations, AtLeast(1));
  for (auto [key, value] : {std::pair{"function_tolerance", function_tolerance},
                            std::pair{"gradient_tolerance", gradient_tolerance},
                            std::pair{"parameter_tolerance", parameter_tolerance},
                            std::pair{"finite_difference_step", finite_difference_step}}) {
    if (!IsPositiveFinite(value)) return json::Invalid(key, value, kPositiveRequirement);
  }
  if (!(max_seconds >= 0.0 && std::isfinite(max_seconds)))
    return json::Invalid("max_seconds", max_seconds, "must be a finite number >= 0");
  if (refine_iterations < 0)
    return json::Invalid("refine_iterations", refine_iterations, AtLeast(0));
  if (gradient != GradientMethod::kAdjoint && gradient != GradientMethod::kFiniteDifference) {
    return json::Invalid("gradient", static_cast<int>(gradient), kGradientRequirement);
  }
  return ValidateCost(cost);
}

Result<SolverOptions> SolverOptionsFromJson(const Json& job_config) {
  if (!job_config.is_object())
    return json::Invalid("job config", job_config, "must be a JSON object");
  SolverOptions options;
  SOFTID_RETURN_IF_ERROR(ParseDiscretisation(job_config, &options));
  SOFTID_RETURN_IF_ERROR(ParseStarts(job_config, &options));
  SOFTID_RETURN_IF_ERROR(ParseOptimiser(job_config, &options));
  if (job_config.contains("cost")) {
    SOFTID_ASSIGN_OR_RETURN(options.cost, ParseCost(job_config["cost"]));
  }
  return options;
}

void WriteJson(const SolverOptions& options, Json* job_config) {
  Json& j = *job_config;
  j["cells"] = options.cells == kAutoCells ? Json("auto") : Json(options.cells);
  j["substeps"] = options.substeps == kAutoSubsteps ? Json("auto") : Json(options.substeps);
  j["element"] = fem::ToString(options.element);
  j["grid_orientation"] = fem::ToString(options.grid_orientation);
  j["cut_cell_samples"] = options.cut_cell_samples;
  j["starts"] = options.starts;
  j["threads"] = options.threads;
  j["seed"] = options.seed;
  j["max_iterations"] = options.max_iterations;
  j["function_tolerance"] = options.function_tolerance;
  j["gradient_tolerance"] = options.gradient_tolerance;
  j["parameter_tolerance"] = options.parameter_tolerance;
  j["max_seconds"] = options.max_seconds;
  j["gradient"] = ToString(options.gradient);
  j["finite_difference_step"] = options.finite_difference_step;
  j["continuation"] = options.continuation;
  j["launch_from_flight"] = options.launch_from_flight;
  j["predictable_frames_only"] = options.predictable_frames_only;
  j["refine_iterations"] = options.refine_iterations;
  j["cost"] = {{"band_cells", options.cost.band_cells},
               {"truncation_cells", options.cost.truncation_cells},
               {"rest_sdf", cost::ToString(options.cost.rest_sdf)},
               {"frame_loss", ToString(options.cost.frame_loss)},
               {"frame_loss_noise_multiple", options.cost.frame_loss_noise_multiple}};
  // 0 means "absent" (use cells); written only when set so the round trip keeps it absent.
  if (options.cell_size_m != 0.0) j["cell_size"] = options.cell_size_m;
  if (options.rho_infinity != SolverOptions::kNewmark) j["rho_infinity"] = options.rho_infinity;
}

}  // namespace softid::inverse
