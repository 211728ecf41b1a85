// The physical parameters of a simulated object and its surroundings, under the names used
// everywhere in softid (truth.json, job configs, result.json, the service). These names are a
// public contract: keep them stable. Each parameter's name, unit and range are listed once, in
// parameter_registry.h.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/common/status.h"

namespace softid::fem {

// A plane n . x = offset; the object lives on the side n . x > offset. `normal` is a unit vector.
struct GroundPlane {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // [-], unit length
  double offset = 0.0;                                // [m]
  double SignedDistance(const Eigen::Vector3d& p_W) const { return normal.dot(p_W) - offset; }
};

// Spatially varying Young's modulus: E(x) = youngs_modulus * Scale(x), evaluated per element at the
// cell centre of the rest pose.
struct StiffnessField {
  enum class Kind { kUniform, kRegions, kLinear };
  struct Region {
    Eigen::AlignedBox3d box;  // rest-pose box [m]
    double scale = 1.0;       // E multiplier inside the box [-], > 0
  };
  Kind kind = Kind::kUniform;
  // kRegions: elements whose centre lies in a box get that box's scale (the last match wins).
  std::vector<Region> regions;
  // kLinear: log E varies linearly: Scale(x) = exp(log_gradient . (x - origin)).
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();        // [m]
  Eigen::Vector3d log_gradient = Eigen::Vector3d::Zero();  // [1/m]

  double Scale(const Eigen::Vector3d& p_W) const;
};

const char* ToString(StiffnessField::Kind kind);

// A rigid correction of the rest pose at the first frame: the rest mesh turned by `rotation`
// about the centre of its bounding box, then moved by `translation`. It lets a fit correct a
// registration error of the scanned mesh (millimetres, degrees) instead of biasing the material.
// Zero: the rest mesh stands where the capture put it.
struct InitialPose {
  Eigen::Vector3d rotation = Eigen::Vector3d::Zero();     // rotation vector [rad]
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();  // [m]

  bool IsIdentity() const { return rotation.isZero(0.0) && translation.isZero(0.0); }
  // X_W = R (X - centre) + centre + translation, for the rest mesh's box centre `centre`.
  Eigen::Isometry3d WorldFromRest(const Eigen::Vector3d& centre_m) const;
};

struct PhysicalParameters {
  double youngs_modulus = 1.0e5;   // E [Pa], > 0
  double poisson_ratio = 0.3;      // nu [-], in (0, 0.5)
  double density = 1000.0;         // rho [kg/m^3], > 0
  double mass_damping = 0.0;       // Rayleigh alpha [1/s], >= 0: D = alpha M + beta K
  double stiffness_damping = 0.0;  // Rayleigh beta [s], >= 0
  Eigen::Vector3d gravity = Eigen::Vector3d(0.0, 0.0, -9.81);  // true acceleration [m/s^2]
  Eigen::Vector3d initial_velocity = Eigen::Vector3d::Zero();  // of the centre of mass [m/s]
  Eigen::Vector3d initial_angular_velocity = Eigen::Vector3d::Zero();  // about it [rad/s]
  InitialPose initial_pose;                                            // none by default
  std::optional<GroundPlane> ground;                                   // none: free flight
  // Penalty contact with the ground: pressure per metre of penetration [Pa/m]. 0 selects
  // DefaultContactStiffness (below).
  double contact_stiffness = 0.0;
  double contact_damping = 0.0;  // [s]: damping force = contact_damping * contact stiffness * v
  double friction_coefficient = 0.0;  // Coulomb mu [-], >= 0 (regularised; 0: frictionless)
  StiffnessField stiffness_field;     // uniform by default
  // Air drag per unit projected area (taken as a quarter of the surface, Cauchy's formula for
  // convex bodies): f = -(drag_linear + drag_quadratic |v|) v per m^2.
  double drag_linear = 0.0;     // [kg/(m^2 s)] = [Pa s/m], >= 0
  double drag_quadratic = 0.0;  // [kg/m^3] (rho_air C_d / 2), >= 0

  // Names the first field that is out of range (parameter_registry.h) and its value.
  Status Validate() const;
  // Lame parameters of the base modulus.
  double LameMu() const { return youngs_modulus / (2.0 * (1.0 + poisson_ratio)); }
  double LameLambda() const {
    return youngs_modulus * poisson_ratio / ((1.0 + poisson_ratio) * (1.0 - 2.0 * poisson_ratio));
  }
};

// The contact stiffness that contact_stiffness = 0 selects, 100 E / L [Pa/m] (L = longest side of
// the rest mesh): a contact pressure p = E eps then sinks in by eps L / 100, 1 % of the shortening
// the same stress causes over the body's length, independent of grid and time step.
inline constexpr double kDefaultContactStiffnessFactor = 100.0;  // k L / E [-]
inline double DefaultContactStiffness(double youngs_modulus_pa, double length_m) {
  return kDefaultContactStiffnessFactor * youngs_modulus_pa / length_m;
}

// JSON under the public names (truth.json, result values). Vectors are arrays; the ground plane is
// {"normal": [..], "offset": d} or null; the stiffness field is {"kind": "uniform"} |
// {"kind": "regions", "regions": [{"min": [..], "max": [..], "scale": s}]} |
// {"kind": "linear", "origin": [..], "log_gradient": [..]}; the initial pose is
// {"rotation": [..], "translation": [..]}.
nlohmann::json ToJson(const PhysicalParameters& parameters);
nlohmann::json ToJson(const GroundPlane& plane);
nlohmann::json ToJson(const StiffnessField& field);
// {"rotation": [rx, ry, rz], "translation": [tx, ty, tz]}
nlohmann::json ToJson(const InitialPose& pose);
// Reads the fields present in `json` over `defaults`; unknown keys are rejected by name.
Result<PhysicalParameters> PhysicalParametersFromJson(const nlohmann::json& json,
                                                      const PhysicalParameters& defaults = {});
Result<GroundPlane> GroundPlaneFromJson(const nlohmann::json& json, const std::string& field);
Result<StiffnessField> StiffnessFieldFromJson(const nlohmann::json& json, const std::string& field);
Result<InitialPose> InitialPoseFromJson(const nlohmann::json& json, const std::string& field);

}  // namespace softid::fem
