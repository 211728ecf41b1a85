#include "core/inverse/fit_uncertainty.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/inverse/parameter_space.h"

namespace softid::inverse {
namespace {

constexpr double kInfinity = std::numeric_limits<double>::infinity();

// Every number of a JSON value, depth first (objects in key order).
void AppendNumbers(const nlohmann::json& value, std::vector<double>* out) {
  if (value.is_number()) {
    out->push_back(value.get<double>());
  } else if (value.is_array() || value.is_object()) {
    for (const nlohmann::json& element : value) AppendNumbers(element, out);
  }
}

std::vector<double> Numbers(const nlohmann::json& value) {
  std::vector<double> out;
  AppendNumbers(value, &out);
  return out;
}

// `shape` with its numbers replaced by `numbers` in AppendNumbers' order (+inf: null).
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

// d (public numbers of `name`) / d x at x, by central differences of the parameter space.
Eigen::MatrixXd PublicJacobian(const ParameterSpace& space, const std::vector<double>& x,
                               const fem::PhysicalParameters& base, const std::string& name) {
  const size_t rows = Numbers(ParameterValueJson(base, name)).size();
  Eigen::MatrixXd jacobian =
      Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(rows), space.NumVariables());
  for (int j = 0; j < space.NumVariables(); ++j) {
    const double h = 1e-6 * std::max(1.0, std::abs(x[j]));
    std::vector<double> plus = x, minus = x;
    plus[j] += h;
    minus[j] -= h;
    const std::vector<double> up =
        Numbers(ParameterValueJson(space.ToParameters(plus.data(), base), name));
    const std::vector<double> down =
        Numbers(ParameterValueJson(space.ToParameters(minus.data(), base), name));
    for (size_t k = 0; k < std::min({rows, up.size(), down.size()}); ++k) {
      jacobian(static_cast<Eigen::Index>(k), j) = (up[k] - down[k]) / (2.0 * h);
    }
  }
  return jacobian;
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

}  // namespace

double DepthQuantisationSigma(const capture::Capture& capture) {
  double quantum = kInfinity;
  for (const capture::CameraRecording& camera : capture.cameras) {
    quantum = std::min(quantum, camera.depth_scale);
  }
  return std::isfinite(quantum) ? quantum / std::sqrt(12.0) : 0.0;
}

Result<FitUncertainty> EstimateFitUncertainty(const capture::Capture& capture,
                                              const JobConfig& config, const FitResult& fit) {
  IdentifiabilityOptions options;
  options.threads = config.threads;
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
  return json;
}

}  // namespace softid::inverse
