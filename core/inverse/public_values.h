// A fitted parameter's public numbers (the numbers of its result.json value, depth first) and
// their derivatives with respect to the optimiser's variables: how uncertainties and errors in the
// variables become ones a user reads in the parameter's own unit.
#pragma once

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/fem/physical_parameters.h"
#include "core/inverse/parameter_space.h"

namespace softid::inverse {

// Every number of a JSON value, depth first (objects in key order).
std::vector<double> PublicNumbers(const nlohmann::json& value);

// d (public numbers of `name`) / d x at x, by central differences of the parameter space.
Eigen::MatrixXd PublicJacobian(const ParameterSpace& space, const std::vector<double>& x,
                               const fem::PhysicalParameters& base, const std::string& name);

}  // namespace softid::inverse
