#include "core/fem/parameter_gradient.h"

#include <algorithm>

#include "core/common/json_fields.h"

namespace softid::fem {

ParameterGradient& ParameterGradient::operator+=(const ParameterGradient& other) {
  youngs_modulus += other.youngs_modulus;
  poisson_ratio += other.poisson_ratio;
  density += other.density;
  mass_damping += other.mass_damping;
  stiffness_damping += other.stiffness_damping;
  gravity += other.gravity;
  initial_velocity += other.initial_velocity;
  initial_angular_velocity += other.initial_angular_velocity;
  ground_normal += other.ground_normal;
  ground_offset += other.ground_offset;
  contact_stiffness += other.contact_stiffness;
  contact_damping += other.contact_damping;
  friction_coefficient += other.friction_coefficient;
  drag_linear += other.drag_linear;
  drag_quadratic += other.drag_quadratic;
  if (stiffness_field.size() < other.stiffness_field.size())
    stiffness_field.resize(other.stiffness_field.size(), 0.0);
  for (size_t i = 0; i < other.stiffness_field.size(); ++i)
    stiffness_field[i] += other.stiffness_field[i];
  return *this;
}

nlohmann::json ToJson(const ParameterGradient& g) {
  return {
      {"youngs_modulus", g.youngs_modulus},
      {"poisson_ratio", g.poisson_ratio},
      {"density", g.density},
      {"mass_damping", g.mass_damping},
      {"stiffness_damping", g.stiffness_damping},
      {"gravity", json::FromVector3(g.gravity)},
      {"initial_velocity", json::FromVector3(g.initial_velocity)},
      {"initial_angular_velocity", json::FromVector3(g.initial_angular_velocity)},
      {"ground", {{"normal", json::FromVector3(g.ground_normal)}, {"offset", g.ground_offset}}},
      {"contact_stiffness", g.contact_stiffness},
      {"contact_damping", g.contact_damping},
      {"friction_coefficient", g.friction_coefficient},
      {"drag_linear", g.drag_linear},
      {"drag_quadratic", g.drag_quadratic},
      {"stiffness_field", g.stiffness_field},
  };
}

}  // namespace softid::fem
