#include "core/fem/parameter_gradient.h"

#include <algorithm>

#include "core/common/json_fields.h"
#include "core/fem/parameter_registry.h"

namespace softid::fem {

ParameterGradient& ParameterGradient::operator+=(const ParameterGradient& other) {
  for (const ParameterInfo& parameter : ParameterRegistry()) {
    switch (parameter.shape) {
      case ParameterShape::kScalar:
        this->*parameter.scalar_gradient += other.*parameter.scalar_gradient;
        break;
      case ParameterShape::kVector3:
        this->*parameter.vector_gradient += other.*parameter.vector_gradient;
        break;
      case ParameterShape::kPlane:
        ground_normal += other.ground_normal;
        ground_offset += other.ground_offset;
        break;
      case ParameterShape::kPose:
        initial_pose_rotation += other.initial_pose_rotation;
        initial_pose_translation += other.initial_pose_translation;
        break;
      case ParameterShape::kStiffnessField:
        if (stiffness_field.size() < other.stiffness_field.size())
          stiffness_field.resize(other.stiffness_field.size(), 0.0);
        for (size_t i = 0; i < other.stiffness_field.size(); ++i)
          stiffness_field[i] += other.stiffness_field[i];
        break;
    }
  }
  return *this;
}

nlohmann::json ToJson(const ParameterGradient& g) {
  nlohmann::json j = nlohmann::json::object();
  for (const ParameterInfo& parameter : ParameterRegistry()) {
    nlohmann::json& entry = j[std::string(parameter.json_key)];
    switch (parameter.shape) {
      case ParameterShape::kScalar: entry = g.*parameter.scalar_gradient; break;
      case ParameterShape::kVector3: entry = json::FromVector3(g.*parameter.vector_gradient); break;
      case ParameterShape::kPlane:
        entry = {{"normal", json::FromVector3(g.ground_normal)}, {"offset", g.ground_offset}};
        break;
      case ParameterShape::kPose:
        entry = {{"rotation", json::FromVector3(g.initial_pose_rotation)},
                 {"translation", json::FromVector3(g.initial_pose_translation)}};
        break;
      case ParameterShape::kStiffnessField: entry = g.stiffness_field; break;
    }
  }
  return j;
}

}  // namespace softid::fem
