#include "core/inverse/parameter_space.h"

#include <algorithm>
#include <cmath>
#include <set>

#include "core/common/json_fields.h"

namespace softid::inverse {
namespace {

using Transform = fem::ParameterTransform;

double Logistic(double x) {
  return 1.0 / (1.0 + std::exp(-x));
}
double Softplus(double x) {
  return x > 0.0 ? x + std::log1p(std::exp(-x)) : std::log1p(std::exp(x));
}
// Inverse of softplus: log(e^p - 1), stable for small and large p.
double InverseSoftplus(double p) {
  return p > 30.0 ? p : std::log(std::expm1(p));
}

// The initial pose's variables (fem::ParameterTransform::kPose): a unit moves the surface of a
// body of size L by about L / 10, through the rotation (L / 2 arms) or the translation.
constexpr double kPoseRotationPerVariable = 0.2;     // [rad]
constexpr double kPoseTranslationPerVariable = 0.1;  // [L]

}  // namespace

Result<ParameterSpace> ParameterSpace::Create(const std::vector<std::string>& names,
                                              const fem::PhysicalParameters& reference,
                                              double length_scale) {
  ParameterSpace space;
  space.names_ = names;
  space.length_scale_ = length_scale;
  std::set<std::string> seen;
  int offset = 0;
  for (size_t i = 0; i < names.size(); ++i) {
    const std::string& name = names[i];
    const std::string field = "fit[" + std::to_string(i) + "]";
    if (!seen.insert(name).second) return json::Invalid(field, name, "is listed twice");
    const fem::ParameterInfo* parameter = fem::FindParameter(name);
    // Fittable names only: the alias "ground" is resolved by the job config.
    if (parameter == nullptr || parameter->name != name) {
      return json::Invalid(field, name, "is not a fittable parameter");
    }
    Entry entry{parameter, offset, 1};
    SOFTID_RETURN_IF_ERROR(space.AddVariables(name, field, reference, &entry));
    offset += entry.size;
    space.entries_.push_back(entry);
  }
  return space;
}

Status ParameterSpace::AddVariables(const std::string& name, const std::string& field,
                                    const fem::PhysicalParameters& reference, Entry* entry) {
  switch (entry->parameter->transform) {
    case Transform::kLog:
    case Transform::kHalfLogistic:
    case Transform::kSoftplus: variable_names_.push_back(name); break;
    case Transform::kIdentity:
      entry->size = 3;
      for (int k = 0; k < 3; ++k) variable_names_.push_back(name + "[" + std::to_string(k) + "]");
      break;
    case Transform::kGroundPlaneTilt: {
      if (!reference.ground) {
        return json::Invalid(field, name,
                             "needs a starting plane: give initial.ground_plane or "
                             "fixed.ground");
      }
      entry->size = 3;
      ground_normal_ = reference.ground->normal;
      const Eigen::Vector3d n = ground_normal_;
      const Eigen::Vector3d helper =
          std::abs(n.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
      ground_tangent_[0] = n.cross(helper).normalized();
      ground_tangent_[1] = n.cross(ground_tangent_[0]);
      variable_names_.insert(variable_names_.end(),
                             {name + ".tilt[0]", name + ".tilt[1]", name + ".offset"});
      break;
    }
    case Transform::kStiffnessField: {
      const fem::StiffnessField& f = reference.stiffness_field;
      if (f.kind == fem::StiffnessField::Kind::kUniform) {
        return json::Invalid(field, name,
                             "needs a field shape: give initial.stiffness_field or "
                             "fixed.stiffness_field as {\"kind\": \"regions\", ...} or "
                             "{\"kind\": \"linear\", ...}");
      }
      field_kind_ = f.kind;
      entry->size =
          f.kind == fem::StiffnessField::Kind::kRegions ? static_cast<int>(f.regions.size()) : 3;
      for (int k = 0; k < entry->size; ++k)
        variable_names_.push_back(name + "[" + std::to_string(k) + "]");
      break;
    }
    case Transform::kPose:
      entry->size = 6;
      for (const char* part : {".rotation[", ".translation["}) {
        for (int k = 0; k < 3; ++k)
          variable_names_.push_back(name + part + std::to_string(k) + "]");
      }
      break;
  }
  return Status::Ok();
}

std::vector<double> ParameterSpace::ToVariables(const fem::PhysicalParameters& p) const {
  std::vector<double> x(NumVariables(), 0.0);
  for (const Entry& e : entries_) {
    const fem::ParameterInfo& parameter = *e.parameter;
    double* xe = x.data() + e.offset;
    switch (parameter.transform) {
      case Transform::kLog: {
        double v = p.*parameter.scalar;
        // 0 selects the simulator's default, which is where the fit starts.
        if (parameter.scalar == &fem::PhysicalParameters::contact_stiffness && v <= 0.0 && p.ground)
          v = fem::DefaultContactStiffness(p.youngs_modulus, length_scale_);
        xe[0] = std::log(std::max(v, parameter.minimum_start));
        break;
      }
      case Transform::kHalfLogistic: {
        const double v = p.*parameter.scalar;
        xe[0] = std::log((2.0 * v) / (1.0 - 2.0 * v));
        break;
      }
      case Transform::kSoftplus:
        xe[0] = InverseSoftplus(std::max(p.*parameter.scalar, parameter.minimum_start));
        break;
      case Transform::kIdentity:
        for (int k = 0; k < 3; ++k) xe[k] = (p.*parameter.vector)[k];
        break;
      case Transform::kGroundPlaneTilt: {
        // Tilt relative to the reference normal: n / (n . n0) = n0 + x0 t1 + x1 t2.
        const Eigen::Vector3d n = p.ground->normal / p.ground->normal.dot(ground_normal_);
        xe[0] = n.dot(ground_tangent_[0]);
        xe[1] = n.dot(ground_tangent_[1]);
        xe[2] = p.ground->offset / (0.1 * length_scale_);
        break;
      }
      case Transform::kStiffnessField: {
        const fem::StiffnessField& f = p.stiffness_field;
        if (f.kind == fem::StiffnessField::Kind::kRegions) {
          for (int k = 0; k < e.size; ++k) xe[k] = std::log(f.regions[k].scale);
        } else {
          for (int k = 0; k < 3; ++k) xe[k] = f.log_gradient[k] * length_scale_;
        }
        break;
      }
      case Transform::kPose:
        for (int k = 0; k < 3; ++k) {
          xe[k] = p.initial_pose.rotation[k] / kPoseRotationPerVariable;
          xe[3 + k] = p.initial_pose.translation[k] / (kPoseTranslationPerVariable * length_scale_);
        }
        break;
    }
  }
  return x;
}

fem::PhysicalParameters ParameterSpace::ToParameters(const double* x,
                                                     const fem::PhysicalParameters& base) const {
  fem::PhysicalParameters p = base;
  for (const Entry& e : entries_) {
    const fem::ParameterInfo& parameter = *e.parameter;
    const double* xe = x + e.offset;
    switch (parameter.transform) {
      case Transform::kLog: p.*parameter.scalar = std::exp(xe[0]); break;
      case Transform::kHalfLogistic: p.*parameter.scalar = 0.5 * Logistic(xe[0]); break;
      case Transform::kSoftplus: p.*parameter.scalar = Softplus(xe[0]); break;
      case Transform::kIdentity: p.*parameter.vector = Eigen::Vector3d(xe[0], xe[1], xe[2]); break;
      case Transform::kGroundPlaneTilt: {
        const Eigen::Vector3d raw =
            ground_normal_ + xe[0] * ground_tangent_[0] + xe[1] * ground_tangent_[1];
        p.ground = fem::GroundPlane{raw.normalized(), xe[2] * 0.1 * length_scale_};
        break;
      }
      case Transform::kStiffnessField:
        if (p.stiffness_field.kind == fem::StiffnessField::Kind::kRegions) {
          for (int k = 0; k < e.size; ++k) p.stiffness_field.regions[k].scale = std::exp(xe[k]);
        } else {
          for (int k = 0; k < 3; ++k) p.stiffness_field.log_gradient[k] = xe[k] / length_scale_;
        }
        break;
      case Transform::kPose:
        for (int k = 0; k < 3; ++k) {
          p.initial_pose.rotation[k] = xe[k] * kPoseRotationPerVariable;
          p.initial_pose.translation[k] = xe[3 + k] * kPoseTranslationPerVariable * length_scale_;
        }
        break;
    }
  }
  return p;
}

void ParameterSpace::ChainGradient(const fem::ParameterGradient& g, const double* x,
                                   double* gx) const {
  for (const Entry& e : entries_) {
    const fem::ParameterInfo& parameter = *e.parameter;
    const double* xe = x + e.offset;
    double* ge = gx + e.offset;
    switch (parameter.transform) {
      case Transform::kLog: ge[0] = g.*parameter.scalar_gradient * std::exp(xe[0]); break;
      case Transform::kHalfLogistic: {
        const double s = Logistic(xe[0]);
        ge[0] = g.*parameter.scalar_gradient * 0.5 * s * (1.0 - s);
        break;
      }
      case Transform::kSoftplus: ge[0] = g.*parameter.scalar_gradient * Logistic(xe[0]); break;
      case Transform::kIdentity:
        for (int k = 0; k < 3; ++k) ge[k] = (g.*parameter.vector_gradient)[k];
        break;
      case Transform::kGroundPlaneTilt: {
        // n = m / |m|, m = n0 + x0 t1 + x1 t2: dn/dm = (I - n n^T) / |m|.
        const Eigen::Vector3d m =
            ground_normal_ + xe[0] * ground_tangent_[0] + xe[1] * ground_tangent_[1];
        const Eigen::Vector3d n = m.normalized();
        const Eigen::Vector3d dm = (g.ground_normal - n * n.dot(g.ground_normal)) / m.norm();
        ge[0] = dm.dot(ground_tangent_[0]);
        ge[1] = dm.dot(ground_tangent_[1]);
        ge[2] = g.ground_offset * 0.1 * length_scale_;
        break;
      }
      case Transform::kStiffnessField:
        // Regions: x = log(scale), d/dx = scale d/dscale; linear: x = L g, d/dx = (d/dg) / L.
        for (int k = 0; k < e.size; ++k) {
          const double dk =
              k < static_cast<int>(g.stiffness_field.size()) ? g.stiffness_field[k] : 0.0;
          ge[k] = field_kind_ == fem::StiffnessField::Kind::kLinear ? dk / length_scale_
                                                                    : dk * std::exp(xe[k]);
        }
        break;
      case Transform::kPose:
        for (int k = 0; k < 3; ++k) {
          ge[k] = g.initial_pose_rotation[k] * kPoseRotationPerVariable;
          ge[3 + k] = g.initial_pose_translation[k] * kPoseTranslationPerVariable * length_scale_;
        }
        break;
    }
  }
}

}  // namespace softid::inverse
