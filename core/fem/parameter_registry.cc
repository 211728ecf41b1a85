#include "core/fem/parameter_registry.h"

#include <array>
#include <cmath>
#include <sstream>

#include "core/common/json_fields.h"

namespace softid::fem {
namespace {

using PP = PhysicalParameters;
using PG = ParameterGradient;
using Shape = ParameterShape;
using Transform = ParameterTransform;

constexpr double kInfinity = std::numeric_limits<double>::infinity();
constexpr ValidRange kPositive{0.0, true, kInfinity, true};
constexpr ValidRange kNonNegative{0.0, false, kInfinity, true};

constexpr ParameterInfo Scalar(std::string_view name, std::string_view unit,
                               std::string_view description, Transform transform, ValidRange range,
                               double minimum_start, double PP::*value, double PG::*gradient) {
  ParameterInfo p;
  p.name = p.json_key = name;
  p.unit = unit;
  p.description = description;
  p.shape = Shape::kScalar;
  p.transform = transform;
  p.range = range;
  p.minimum_start = minimum_start;
  p.scalar = value;
  p.scalar_gradient = gradient;
  return p;
}

constexpr ParameterInfo Vector3(std::string_view name, std::string_view unit,
                                std::string_view description, Eigen::Vector3d PP::*value,
                                Eigen::Vector3d PG::*gradient) {
  ParameterInfo p;
  p.name = p.json_key = name;
  p.unit = unit;
  p.description = description;
  p.shape = Shape::kVector3;
  p.transform = Transform::kIdentity;
  p.vector = value;
  p.vector_gradient = gradient;
  return p;
}

// The plane and the stiffness field: their values and gradients are reached through the shape.
constexpr ParameterInfo Special(std::string_view name, std::string_view json_key,
                                std::string_view unit, std::string_view description, Shape shape,
                                Transform transform) {
  ParameterInfo p;
  p.name = name;
  p.json_key = json_key;
  p.unit = unit;
  p.description = description;
  p.shape = shape;
  p.transform = transform;
  return p;
}

// In report order. A new row also needs its physics (simulator.cc) and its adjoint
// (simulator_adjoint.cc); the static_assert below checks that the row is consistent.
constexpr auto kRegistry = std::to_array<ParameterInfo>({
    Scalar("youngs_modulus", "Pa", "Young's modulus E", Transform::kLog, kPositive, 1e-12,
           &PP::youngs_modulus, &PG::youngs_modulus),
    Scalar("poisson_ratio", "1", "Poisson's ratio nu", Transform::kHalfLogistic,
           {0.0, true, 0.5, true}, 0.0, &PP::poisson_ratio, &PG::poisson_ratio),
    Scalar("density", "kg/m^3",
           "mass density; neither fitted nor fixed when the capture gives `mass_kg`",
           Transform::kLog, kPositive, 1e-12, &PP::density, &PG::density),
    Scalar("mass_damping", "1/s", "Rayleigh damping alpha (D = alpha M + beta K)", Transform::kLog,
           kNonNegative, 1e-3, &PP::mass_damping, &PG::mass_damping),
    Scalar("stiffness_damping", "s", "Rayleigh damping beta", Transform::kLog, kNonNegative, 1e-5,
           &PP::stiffness_damping, &PG::stiffness_damping),
    Vector3("gravity", "m/s^2", "acceleration of gravity", &PP::gravity, &PG::gravity),
    Vector3("initial_velocity", "m/s", "velocity of the centre of mass at the first frame",
            &PP::initial_velocity, &PG::initial_velocity),
    Vector3("initial_angular_velocity", "rad/s",
            "angular velocity about the centre of mass at the first frame",
            &PP::initial_angular_velocity, &PG::initial_angular_velocity),
    Special("initial_pose", "initial_pose", "rad, m",
            "rigid correction of the rest pose at the first frame: a rotation vector about the "
            "rest mesh's bounding-box centre, then a translation",
            Shape::kPose, Transform::kPose),
    Special("ground_plane", "ground", "m",
            "the floor n . x = offset; `\"ground\": null` in `fixed`: free flight", Shape::kPlane,
            Transform::kGroundPlaneTilt),
    Scalar("friction_coefficient", "1",
           "Coulomb friction mu with the ground (regularised); 0: frictionless",
           Transform::kSoftplus, kNonNegative, 1e-2, &PP::friction_coefficient,
           &PG::friction_coefficient),
    Scalar("drag_linear", "kg/(m^2 s)", "air drag per projected area, linear in the speed",
           Transform::kLog, kNonNegative, 1e-3, &PP::drag_linear, &PG::drag_linear),
    Scalar("drag_quadratic", "kg/m^3",
           "air drag per projected area, quadratic in the speed (rho_air C_d / 2)", Transform::kLog,
           kNonNegative, 1e-3, &PP::drag_quadratic, &PG::drag_quadratic),
    Special("stiffness_field", "stiffness_field", "1",
            "spatial variation of E: a scale per region, or a log-linear gradient",
            Shape::kStiffnessField, Transform::kStiffnessField),
    Scalar("contact_stiffness", "Pa/m",
           "ground contact pressure per metre of penetration; 0: 100 E / L", Transform::kLog,
           kNonNegative, 1e-12, &PP::contact_stiffness, &PG::contact_stiffness),
    Scalar("contact_damping", "s",
           "contact damping force per contact stiffness and penetration speed", Transform::kLog,
           kNonNegative, 1e-5, &PP::contact_damping, &PG::contact_damping),
});

// Whether a row's transform fits its shape and the accessors its shape needs are set.
constexpr bool IsConsistent(const ParameterInfo& p) {
  const bool scalar = p.shape == Shape::kScalar && p.scalar != nullptr &&
                      p.scalar_gradient != nullptr && p.vector == nullptr;
  switch (p.transform) {
    case Transform::kLog:
    case Transform::kSoftplus: return scalar && p.minimum_start > 0.0;
    case Transform::kHalfLogistic: return scalar;
    case Transform::kIdentity:
      return p.shape == Shape::kVector3 && p.vector != nullptr && p.vector_gradient != nullptr &&
             p.scalar == nullptr;
    case Transform::kGroundPlaneTilt: return p.shape == Shape::kPlane;
    case Transform::kStiffnessField: return p.shape == Shape::kStiffnessField;
    case Transform::kPose: return p.shape == Shape::kPose;
  }
  return false;
}

// Every row is consistent, and no name or key is spelled twice (FindParameter would be ambiguous).
constexpr bool IsValidRegistry() {
  for (size_t i = 0; i < kRegistry.size(); ++i) {
    if (!IsConsistent(kRegistry[i]) || kRegistry[i].name.empty()) return false;
    for (size_t j = i + 1; j < kRegistry.size(); ++j) {
      for (std::string_view a : {kRegistry[i].name, kRegistry[i].json_key}) {
        if (a == kRegistry[j].name || a == kRegistry[j].json_key) return false;
      }
    }
  }
  return true;
}
static_assert(IsValidRegistry());

std::string FormatBound(double value) {
  if (std::isinf(value)) return value > 0.0 ? "inf" : "-inf";
  std::ostringstream out;
  out << value;
  return out.str();
}

}  // namespace

std::string_view Describe(ParameterTransform transform) {
  switch (transform) {
    case Transform::kLog: return "log";
    case Transform::kHalfLogistic: return "0.5 logistic, in (0, 0.5)";
    case Transform::kSoftplus: return "softplus (reaches 0)";
    case Transform::kIdentity: return "the vector";
    case Transform::kGroundPlaneTilt: return "tilt of the normal, offset";
    case Transform::kStiffnessField: return "log scales, or a log gradient";
    case Transform::kPose: return "rotation x 5, translation x 10 / L";
  }
  return "?";
}

bool ValidRange::Contains(double value) const {
  return std::isfinite(value) && (lower_open ? value > lower : value >= lower) &&
         (upper_open ? value < upper : value <= upper);
}

std::string ValidRange::Requirement() const {
  if (lower == 0.0 && std::isinf(upper)) {
    return lower_open ? "must be positive and finite" : "must be non-negative and finite";
  }
  if (std::isinf(lower) && std::isinf(upper)) return "must be finite";
  return "must lie in " + ToString();
}

std::string ValidRange::ToString() const {
  std::string out = lower_open ? "(" : "[";
  out += FormatBound(lower);
  out += ", ";
  out += FormatBound(upper);
  out += upper_open ? ")" : "]";
  return out;
}

std::span<const ParameterInfo> ParameterRegistry() {
  return kRegistry;
}

const ParameterInfo* FindParameter(std::string_view name_or_key) {
  for (const ParameterInfo& p : kRegistry) {
    if (p.name == name_or_key || p.json_key == name_or_key) return &p;
  }
  return nullptr;
}

std::string_view ParameterUnit(std::string_view name_or_key) {
  const ParameterInfo* parameter = FindParameter(name_or_key);
  return parameter != nullptr ? parameter->unit : std::string_view();
}

double* ScalarParameter(PhysicalParameters& p, std::string_view name_or_key) {
  const ParameterInfo* parameter = FindParameter(name_or_key);
  if (parameter == nullptr || parameter->shape != Shape::kScalar) return nullptr;
  return &(p.*parameter->scalar);
}

const double* ScalarParameter(const PhysicalParameters& p, std::string_view name_or_key) {
  const ParameterInfo* parameter = FindParameter(name_or_key);
  if (parameter == nullptr || parameter->shape != Shape::kScalar) return nullptr;
  return &(p.*parameter->scalar);
}

nlohmann::json ToJson(const PhysicalParameters& p, const ParameterInfo& parameter) {
  switch (parameter.shape) {
    case Shape::kScalar: return p.*parameter.scalar;
    case Shape::kVector3: return json::FromVector3(p.*parameter.vector);
    case Shape::kPlane: return p.ground ? ToJson(*p.ground) : nlohmann::json(nullptr);
    case Shape::kStiffnessField: return ToJson(p.stiffness_field);
    case Shape::kPose: return ToJson(p.initial_pose);
  }
  return nullptr;
}

Status ParameterFromJson(const nlohmann::json& value, const ParameterInfo& parameter,
                         const std::string& field, PhysicalParameters* p) {
  switch (parameter.shape) {
    case Shape::kScalar: {
      SOFTID_ASSIGN_OR_RETURN(p->*parameter.scalar, json::ToFiniteNumber(value, field));
      break;
    }
    case Shape::kVector3: {
      SOFTID_ASSIGN_OR_RETURN(p->*parameter.vector, json::ToVector3(value, field));
      break;
    }
    case Shape::kPlane: {
      if (value.is_null()) {
        p->ground.reset();
      } else {
        SOFTID_ASSIGN_OR_RETURN(p->ground, GroundPlaneFromJson(value, field));
      }
      break;
    }
    case Shape::kStiffnessField: {
      SOFTID_ASSIGN_OR_RETURN(p->stiffness_field, StiffnessFieldFromJson(value, field));
      break;
    }
    case Shape::kPose: {
      SOFTID_ASSIGN_OR_RETURN(p->initial_pose, InitialPoseFromJson(value, field));
      break;
    }
  }
  return Status::Ok();
}

void CopyParameter(const ParameterInfo& parameter, const PhysicalParameters& from,
                   PhysicalParameters* to) {
  switch (parameter.shape) {
    case Shape::kScalar: to->*parameter.scalar = from.*parameter.scalar; break;
    case Shape::kVector3: to->*parameter.vector = from.*parameter.vector; break;
    case Shape::kPlane: to->ground = from.ground; break;
    case Shape::kStiffnessField: to->stiffness_field = from.stiffness_field; break;
    case Shape::kPose: to->initial_pose = from.initial_pose; break;
  }
}

}  // namespace softid::fem
