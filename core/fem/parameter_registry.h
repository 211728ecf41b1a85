// Every public physical parameter once: its name, unit, shape, valid range, the optimiser's
// transform, and where its value (PhysicalParameters) and its gradient (ParameterGradient) live.
// Validation, the parameters' JSON, job configs, the optimiser's parameter space, reports and the
// table in docs/job-config.md all read this registry, so adding a parameter is one row in
// parameter_registry.cc plus its physics (simulator.cc) and its adjoint (simulator_adjoint.cc).
// Default values are PhysicalParameters' member initialisers, read through the accessors.
#pragma once

#include <Eigen/Core>
#include <limits>
#include <nlohmann/json.hpp>
#include <span>
#include <string>
#include <string_view>

#include "core/fem/parameter_gradient.h"
#include "core/fem/physical_parameters.h"

namespace softid::fem {

// Whether the parameter is a scalar, a 3-vector, the ground plane, the stiffness field or the
// initial pose.
enum class ParameterShape { kScalar, kVector3, kPlane, kStiffnessField, kPose };

// How the optimiser maps a parameter p to unconstrained variables x (inverse/parameter_space.h),
// so that no step can leave the valid range and steps have comparable scales.
enum class ParameterTransform {
  kLog,              // p > 0: x = log(p)
  kHalfLogistic,     // p in (0, 0.5): p = 0.5 logistic(x)
  kSoftplus,         // p >= 0: p = softplus(x), reaches 0 smoothly, unbounded above
  kIdentity,         // a 3-vector: x = p
  kGroundPlaneTilt,  // n = normalise(n0 + x0 t1 + x1 t2) around the start normal n0 (no pole
                     // singularity), offset = x2 L / 10 (L the body size)
  kStiffnessField,   // region scales: x = log(scale); linear: log_gradient = x / L
  kPose,             // rotation = x[0..2] / 5 [rad], translation = x[3..5] L / 10: a unit of
                     // x moves the surface by about L / 10 either way, as the plane's offset
};

// The optimiser variable in words ("log", ...), for the docs' table.
std::string_view Describe(ParameterTransform transform);

// The valid values of a scalar parameter: an interval of the finite numbers.
struct ValidRange {
  double lower = -std::numeric_limits<double>::infinity();
  bool lower_open = true;
  double upper = std::numeric_limits<double>::infinity();
  bool upper_open = true;

  bool Contains(double value) const;
  // The rule in an error message: "must be positive and finite", "must lie in (0, 0.5)", ...
  std::string Requirement() const;
  // Interval notation: "(0, inf)", "[0, inf)", "(0, 0.5)".
  std::string ToString() const;
};

struct ParameterInfo {
  // The name in job configs and reports ("ground_plane").
  std::string_view name;
  // The PhysicalParameters JSON key (truth.json, "fixed"): the name, except "ground" for
  // "ground_plane" (jobs spell it out: "ground" alone reads like a switch, not a plane to fit).
  std::string_view json_key;
  std::string_view unit;  // SI; "1" when dimensionless
  std::string_view description;
  ParameterShape shape = ParameterShape::kScalar;
  ParameterTransform transform = ParameterTransform::kLog;
  ValidRange range;  // scalars only; the other shapes have their own rules (Validate)
  // The start of a kLog or kSoftplus parameter whose value is below it (0, where the transform
  // has no finite x): small next to any physically meaningful value, so the data decide.
  double minimum_start = 0.0;
  // Where the value and d cost / d value live: the scalar pair for kScalar, the vector pair for
  // kVector3; the plane and the stiffness field are reached through their shape.
  double PhysicalParameters::*scalar = nullptr;
  double ParameterGradient::*scalar_gradient = nullptr;
  Eigen::Vector3d PhysicalParameters::*vector = nullptr;
  Eigen::Vector3d ParameterGradient::*vector_gradient = nullptr;
};

// Every parameter, in the order reports and error messages list them.
std::span<const ParameterInfo> ParameterRegistry();
// The parameter with this name or JSON key ("ground" and "ground_plane" both find the plane), or
// null. Callers that accept only one spelling compare `name` or `json_key` of the result.
const ParameterInfo* FindParameter(std::string_view name_or_key);

// The unit of a parameter name or JSON key ("Pa", "1/s", ...); "" when unknown.
std::string_view ParameterUnit(std::string_view name_or_key);

// The value of the scalar parameter `name_or_key` in p, or null when it is not a scalar.
double* ScalarParameter(PhysicalParameters& p, std::string_view name_or_key);
const double* ScalarParameter(const PhysicalParameters& p, std::string_view name_or_key);

// One parameter's value in its public JSON form (a number, [x, y, z], the plane or null, the
// stiffness field), as ToJson(PhysicalParameters) writes it under parameter.json_key.
nlohmann::json ToJson(const PhysicalParameters& p, const ParameterInfo& parameter);
// Sets one parameter of *p from its public JSON form; errors name `field`. Does not validate
// the range (PhysicalParameters::Validate does).
Status ParameterFromJson(const nlohmann::json& value, const ParameterInfo& parameter,
                         const std::string& field, PhysicalParameters* p);
// Copies one parameter's value from `from` to *to.
void CopyParameter(const ParameterInfo& parameter, const PhysicalParameters& from,
                   PhysicalParameters* to);

}  // namespace softid::fem
