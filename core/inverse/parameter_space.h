// The optimiser's variables: the fitted physical parameters mapped to an unconstrained vector x,
// so that no step of the line search can leave the valid range and steps have comparable scales.
// Each parameter's map is its fem::ParameterTransform (fem/parameter_registry.h).
#pragma once

#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/fem/parameter_gradient.h"
#include "core/fem/parameter_registry.h"
#include "core/fem/physical_parameters.h"

namespace softid::inverse {

class ParameterSpace {
 public:
  // @param names fittable parameter names (fem::ParameterInfo::name); each at most once. Any
  //   other name is refused.
  // @param reference the starting parameters: they fix the ground plane's tangent basis and the
  //   size of a stiffness field's coefficient vector. The ground plane must be set when fitted.
  // @param length_scale L [m], the body's size.
  static Result<ParameterSpace> Create(const std::vector<std::string>& names,
                                       const fem::PhysicalParameters& reference,
                                       double length_scale);

  int NumVariables() const { return static_cast<int>(variable_names_.size()); }
  // "youngs_modulus", "gravity[2]", "ground_plane.tilt[0]", ...
  const std::vector<std::string>& variable_names() const { return variable_names_; }
  const std::vector<std::string>& names() const { return names_; }

  // x for parameters p (fitted entries only). Values at the edge of a transform's range (a zero
  // damping or friction) are moved just inside it: fem::ParameterInfo::minimum_start. A zero
  // contact stiffness starts at the default it selects.
  std::vector<double> ToVariables(const fem::PhysicalParameters& p) const;
  // `base` with the fitted entries replaced by those encoded in x.
  fem::PhysicalParameters ToParameters(const double* x, const fem::PhysicalParameters& base) const;
  // d cost / d x from d cost / d p, at x.
  void ChainGradient(const fem::ParameterGradient& gradient, const double* x,
                     double* gradient_x) const;

 private:
  struct Entry {
    const fem::ParameterInfo* parameter = nullptr;
    int offset = 0;  // first variable
    int size = 1;
  };
  // Create's step for one fitted parameter `name` (listed at `field`): sets entry->size, appends
  // the variables' names and takes what the transform needs from `reference`.
  Status AddVariables(const std::string& name, const std::string& field,
                      const fem::PhysicalParameters& reference, Entry* entry);
  std::vector<Entry> entries_;
  std::vector<std::string> names_;
  std::vector<std::string> variable_names_;
  Eigen::Vector3d ground_normal_ = Eigen::Vector3d::UnitZ();
  Eigen::Vector3d ground_tangent_[2];
  fem::StiffnessField::Kind field_kind_ = fem::StiffnessField::Kind::kUniform;
  double length_scale_ = 1.0;
};

}  // namespace softid::inverse
