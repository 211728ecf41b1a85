#include "core/inverse/public_values.h"

#include <algorithm>
#include <cmath>

#include "core/inverse/fit.h"

namespace softid::inverse {
namespace {

void AppendNumbers(const nlohmann::json& value, std::vector<double>* out) {
  if (value.is_number()) {
    out->push_back(value.get<double>());
  } else if (value.is_array() || value.is_object()) {
    for (const nlohmann::json& element : value) AppendNumbers(element, out);
  }
}

}  // namespace

std::vector<double> PublicNumbers(const nlohmann::json& value) {
  std::vector<double> out;
  AppendNumbers(value, &out);
  return out;
}

Eigen::MatrixXd PublicJacobian(const ParameterSpace& space, const std::vector<double>& x,
                               const fem::PhysicalParameters& base, const std::string& name) {
  const size_t rows = PublicNumbers(ParameterValueJson(base, name)).size();
  Eigen::MatrixXd jacobian =
      Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(rows), space.NumVariables());
  for (int j = 0; j < space.NumVariables(); ++j) {
    const double h = 1e-6 * std::max(1.0, std::abs(x[j]));
    std::vector<double> plus = x, minus = x;
    plus[j] += h;
    minus[j] -= h;
    const std::vector<double> up =
        PublicNumbers(ParameterValueJson(space.ToParameters(plus.data(), base), name));
    const std::vector<double> down =
        PublicNumbers(ParameterValueJson(space.ToParameters(minus.data(), base), name));
    for (size_t k = 0; k < std::min({rows, up.size(), down.size()}); ++k) {
      jacobian(static_cast<Eigen::Index>(k), j) = (up[k] - down[k]) / (2.0 * h);
    }
  }
  return jacobian;
}

}  // namespace softid::inverse
