#include "core/inverse/fit_uncertainty.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/inverse/parameter_space.h"
#include "core/inverse/public_values.h"

namespace softid::inverse {
namespace {

constexpr double kInfinity = std::numeric_limits<double>::infinity();

// `shape` with its numbers replaced by `numbers` in PublicNumbers' order (+inf: null).
nlohmann::json ReplaceNumbers(const nlohmann::json& shape, const std::vector<double>& numbers,
                              size_t* next) {
  if (shape.is_number()) {
    const double v = *next < numbers.size() ? numbers[(*next)++] : kInfinity;
    return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr);
  }
  nlohmann::json out = shape;
  if (shape.is_array() || shape.is_object()) {
    for (auto it = out.begin(); it != out.end(); ++it) *it = ReplaceNumbers(*it, numbers, next);
  }
  return out;
}

// sqrt(diag(J Cov J^T)); +inf for an entry that moves with a variable of infinite variance.
std::vector<double> PropagatedSigma(const Eigen::MatrixXd& jacobian,
                                    const Eigen::MatrixXd& covariance) {
  std::vector<double> sigma(static_cast<size_t>(jacobian.rows()), 0.0);
  for (Eigen::Index k = 0; k < jacobian.rows(); ++k) {
    const double scale = std::max(1e-300, jacobian.row(k).cwiseAbs().maxCoeff());
    double variance = 0.0;
    for (Eigen::Index i = 0; i < jacobian.cols(); ++i) {
      if (std::abs(jacobian(k, i)) <= 1e-9 * scale) continue;
      if (!std::isfinite(covariance(i, i))) {
        variance = kInfinity;
        break;
      }
      for (Eigen::Index j = 0; j < jacobian.cols(); ++j) {
        if (std::abs(jacobian(k, j)) <= 1e-9 * scale) continue;
        if (std::isfinite(covariance(i, j)))
          variance += jacobian(k, i) * covariance(i, j) * jacobian(k, j);
      }
    }
    sigma[static_cast<size_t>(k)] = std::sqrt(std::max(0.0, variance));
  }
  return sigma;
}

// Each parameter's "discretisation_error" {"grid", "time_step", "total", "corrected"} in its
// value's shape (null
// where undetermined or not estimated) and, for scalars, "relative_discretisation_error"; the
// method under "discretisation".
void AddDiscretisationErrors(const DiscretisationError& error, nlohmann::json* json) {
  for (const ParameterDiscretisationError& parameter : error.parameters) {
    if (!(*json)["parameters"].contains(parameter.name)) continue;
    nlohmann::json& entry = (*json)["parameters"][parameter.name];
    nlohmann::json errors;
    for (const auto& [key, numbers] :
         {std::pair{"grid", &parameter.grid}, std::pair{"time_step", &parameter.time_step},
          std::pair{"total", &parameter.total}, std::pair{"corrected", &parameter.corrected}}) {
      size_t next = 0;
      errors[key] = ReplaceNumbers(entry["value"], *numbers, &next);
    }
    entry["discretisation_error"] = errors;
    if (entry["value"].is_number() && parameter.total.size() == 1) {
      const double value = std::abs(entry["value"].get<double>());
      const double total = parameter.total[0];
      entry["relative_discretisation_error"] = value > 0.0 && std::isfinite(total)
                                                   ? nlohmann::json(total / value)
                                                   : nlohmann::json(nullptr);
    }
  }
  (*json)["discretisation"] = ToJson(error);
}

}  // namespace

Result<FitUncertainty> EstimateFitUncertainty(const capture::Capture& capture,
                                              const JobConfig& config, const FitResult& fit) {
  IdentifiabilityOptions options;
  // Forward runs only: the analysis comes with every result, so its cost counts (a third of
  // it by central differences of the adjoint gradient; docs/benchmarks.md).
  options.curvature = CurvatureMethod::kGaussNewton;
  options.threads = config.solver.threads;
  options.min_residual_sigma = DepthQuantisationSigma(capture);
  FitUncertainty out;
  SOFTID_ASSIGN_OR_RETURN(out.report, AnalyzeIdentifiability(capture, config, fit, options));

  SOFTID_ASSIGN_OR_RETURN(const geometry::TriangleMesh mesh, capture::LoadCaptureMesh(capture));
  SOFTID_ASSIGN_OR_RETURN(
      const ParameterSpace space,
      ParameterSpace::Create(fit.fitted, fit.base, mesh.Bounds().sizes().maxCoeff()));
  const fem::PhysicalParameters& optimum = fit.Best().final;
  const std::vector<double> x = space.ToVariables(optimum);
  for (const std::string& name : fit.fitted) {
    const Eigen::MatrixXd jacobian = PublicJacobian(space, x, optimum, name);
    out.parameters.push_back({name, PropagatedSigma(jacobian, out.report.covariance)});
  }
  Result<DiscretisationError> discretisation =
      EstimateDiscretisationError(capture, config, fit, out.report);
  if (discretisation.ok()) {
    out.discretisation = std::move(*discretisation);
  } else {
    out.discretisation_failure = std::string(discretisation.status().message());
  }
  return out;
}

nlohmann::json ToJson(const FitResult& fit, const FitUncertainty* uncertainty,
                      const std::string& error) {
  nlohmann::json json = ToJson(fit);
  if (uncertainty == nullptr) {
    if (!error.empty()) json["uncertainty"] = {{"error", error}};
    return json;
  }
  for (const ParameterUncertainty& parameter : uncertainty->parameters) {
    if (!json["parameters"].contains(parameter.name)) continue;
    nlohmann::json& entry = json["parameters"][parameter.name];
    size_t next = 0;
    entry["standard_uncertainty"] =
        ReplaceNumbers(entry["value"], parameter.standard_uncertainty, &next);
    if (entry["value"].is_number() && parameter.standard_uncertainty.size() == 1) {
      const double value = std::abs(entry["value"].get<double>());
      const double sigma = parameter.standard_uncertainty[0];
      entry["relative_uncertainty"] = value > 0.0 && std::isfinite(sigma)
                                          ? nlohmann::json(sigma / value)
                                          : nlohmann::json(nullptr);
    }
  }
  json["uncertainty"] = ToJson(uncertainty->report);
  if (uncertainty->discretisation) {
    AddDiscretisationErrors(*uncertainty->discretisation, &json);
  } else if (!uncertainty->discretisation_failure.empty()) {
    json["discretisation"] = {{"error", uncertainty->discretisation_failure}};
  }
  return json;
}

}  // namespace softid::inverse
