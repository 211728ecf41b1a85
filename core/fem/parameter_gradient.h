// The derivative of a scalar (a cost) with respect to every physical parameter, under the public
// names of PhysicalParameters, in SI units (e.g. d cost / d youngs_modulus in [cost / Pa]). The
// adjoint fills all of them in one backward pass; the optimiser picks the ones it fits. Scalars
// and vectors are reached through parameter_registry.h.
#pragma once

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <vector>

namespace softid::fem {

struct ParameterGradient {
  double youngs_modulus = 0.0;
  double poisson_ratio = 0.0;
  double density = 0.0;
  double mass_damping = 0.0;
  double stiffness_damping = 0.0;
  Eigen::Vector3d gravity = Eigen::Vector3d::Zero();
  Eigen::Vector3d initial_velocity = Eigen::Vector3d::Zero();
  Eigen::Vector3d initial_angular_velocity = Eigen::Vector3d::Zero();
  // d / d InitialPose::rotation (the rotation vector) and d / d InitialPose::translation.
  Eigen::Vector3d initial_pose_rotation = Eigen::Vector3d::Zero();
  Eigen::Vector3d initial_pose_translation = Eigen::Vector3d::Zero();
  // The ground plane n . x = offset with n treated as a free 3-vector (the force uses n as given,
  // so a parameterisation of the unit normal chains through d n / d angles).
  Eigen::Vector3d ground_normal = Eigen::Vector3d::Zero();
  double ground_offset = 0.0;
  // d / d of the effective contact stiffness k [Pa/m]. When PhysicalParameters::contact_stiffness
  // is 0 (k = DefaultContactStiffness(E, L)), this share is also included in youngs_modulus.
  double contact_stiffness = 0.0;
  double contact_damping = 0.0;
  double friction_coefficient = 0.0;
  double drag_linear = 0.0;
  double drag_quadratic = 0.0;
  // Stiffness field coefficients: per region scale (kRegions), or the 3 components of
  // log_gradient (kLinear); empty for a uniform field.
  std::vector<double> stiffness_field;

  ParameterGradient& operator+=(const ParameterGradient& other);
};

// {"youngs_modulus": .., "ground": {"normal": [..], "offset": ..}, "stiffness_field": [..], ...}
nlohmann::json ToJson(const ParameterGradient& gradient);

}  // namespace softid::fem
