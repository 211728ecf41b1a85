#include "core/fem/physical_parameters.h"

#include <cmath>
#include <map>

#include "core/common/json_fields.h"

namespace softid::fem {
namespace {

Status RequirePositive(const char* name, double value) {
  if (!(value > 0.0) || !std::isfinite(value)) {
    return json::Invalid(name, value, "must be positive and finite");
  }
  return Status::Ok();
}

Status RequireNonNegative(const char* name, double value) {
  if (!(value >= 0.0) || !std::isfinite(value)) {
    return json::Invalid(name, value, "must be non-negative and finite");
  }
  return Status::Ok();
}

Status RequireFinite(const char* name, const Eigen::Vector3d& v) {
  if (!v.allFinite()) return json::Invalid(name, json::FromVector3(v), "must be finite");
  return Status::Ok();
}

}  // namespace

double StiffnessField::Scale(const Eigen::Vector3d& p_W) const {
  switch (kind) {
    case Kind::kUniform: return 1.0;
    case Kind::kRegions: {
      double scale = 1.0;
      for (const Region& region : regions) {
        if (region.box.contains(p_W)) scale = region.scale;
      }
      return scale;
    }
    case Kind::kLinear: return std::exp(log_gradient.dot(p_W - origin));
  }
  return 1.0;
}

const char* ToString(StiffnessField::Kind kind) {
  switch (kind) {
    case StiffnessField::Kind::kUniform: return "uniform";
    case StiffnessField::Kind::kRegions: return "regions";
    case StiffnessField::Kind::kLinear: return "linear";
  }
  return "uniform";
}

Status PhysicalParameters::Validate() const {
  SOFTID_RETURN_IF_ERROR(RequirePositive("youngs_modulus", youngs_modulus));
  if (!(poisson_ratio > 0.0 && poisson_ratio < 0.5)) {
    return json::Invalid("poisson_ratio", poisson_ratio, "must lie in (0, 0.5)");
  }
  SOFTID_RETURN_IF_ERROR(RequirePositive("density", density));
  SOFTID_RETURN_IF_ERROR(RequireNonNegative("mass_damping", mass_damping));
  SOFTID_RETURN_IF_ERROR(RequireNonNegative("stiffness_damping", stiffness_damping));
  SOFTID_RETURN_IF_ERROR(RequireFinite("gravity", gravity));
  SOFTID_RETURN_IF_ERROR(RequireFinite("initial_velocity", initial_velocity));
  SOFTID_RETURN_IF_ERROR(RequireFinite("initial_angular_velocity", initial_angular_velocity));
  if (ground) {
    if (!ground->normal.allFinite() || std::abs(ground->normal.norm() - 1.0) > 1e-6) {
      return json::Invalid("ground.normal", json::FromVector3(ground->normal),
                           "must be a unit vector");
    }
    if (!std::isfinite(ground->offset)) {
      return json::Invalid("ground.offset", ground->offset, "must be finite");
    }
  }
  SOFTID_RETURN_IF_ERROR(RequireNonNegative("contact_stiffness", contact_stiffness));
  SOFTID_RETURN_IF_ERROR(RequireNonNegative("contact_damping", contact_damping));
  SOFTID_RETURN_IF_ERROR(RequireNonNegative("friction_coefficient", friction_coefficient));
  SOFTID_RETURN_IF_ERROR(RequireNonNegative("drag_linear", drag_linear));
  SOFTID_RETURN_IF_ERROR(RequireNonNegative("drag_quadratic", drag_quadratic));
  for (size_t i = 0; i < stiffness_field.regions.size(); ++i) {
    const auto& region = stiffness_field.regions[i];
    const std::string prefix = "stiffness_field.regions[" + std::to_string(i) + "]";
    if (!(region.scale > 0.0) || !std::isfinite(region.scale)) {
      return json::Invalid(prefix + ".scale", region.scale, "must be positive and finite");
    }
    if (!(region.box.min().array() <= region.box.max().array()).all()) {
      return json::Invalid(prefix + ".min", json::FromVector3(region.box.min()),
                           "must not exceed max");
    }
  }
  SOFTID_RETURN_IF_ERROR(
      RequireFinite("stiffness_field.log_gradient", stiffness_field.log_gradient));
  return Status::Ok();
}

nlohmann::json ToJson(const GroundPlane& plane) {
  return {{"normal", json::FromVector3(plane.normal)}, {"offset", plane.offset}};
}

nlohmann::json ToJson(const StiffnessField& field) {
  nlohmann::json j = {{"kind", ToString(field.kind)}};
  if (field.kind == StiffnessField::Kind::kRegions) {
    j["regions"] = nlohmann::json::array();
    for (const auto& region : field.regions) {
      j["regions"].push_back({{"min", json::FromVector3(region.box.min())},
                              {"max", json::FromVector3(region.box.max())},
                              {"scale", region.scale}});
    }
  } else if (field.kind == StiffnessField::Kind::kLinear) {
    j["origin"] = json::FromVector3(field.origin);
    j["log_gradient"] = json::FromVector3(field.log_gradient);
  }
  return j;
}

nlohmann::json ToJson(const PhysicalParameters& p) {
  return {
      {"youngs_modulus", p.youngs_modulus},
      {"poisson_ratio", p.poisson_ratio},
      {"density", p.density},
      {"mass_damping", p.mass_damping},
      {"stiffness_damping", p.stiffness_damping},
      {"gravity", json::FromVector3(p.gravity)},
      {"initial_velocity", json::FromVector3(p.initial_velocity)},
      {"initial_angular_velocity", json::FromVector3(p.initial_angular_velocity)},
      {"ground", p.ground ? ToJson(*p.ground) : nlohmann::json(nullptr)},
      {"contact_stiffness", p.contact_stiffness},
      {"contact_damping", p.contact_damping},
      {"friction_coefficient", p.friction_coefficient},
      {"stiffness_field", ToJson(p.stiffness_field)},
      {"drag_linear", p.drag_linear},
      {"drag_quadratic", p.drag_quadratic},
  };
}

Result<GroundPlane> GroundPlaneFromJson(const nlohmann::json& j, const std::string& field) {
  if (!j.is_object() || !j.contains("normal") || !j.contains("offset")) {
    return json::Invalid(field, j, "must be {\"normal\": [x, y, z], \"offset\": d}");
  }
  GroundPlane plane;
  SOFTID_ASSIGN_OR_RETURN(Eigen::Vector3d normal, json::ToVector3(j["normal"], field + ".normal"));
  if (!(normal.norm() > 1e-12))
    return json::Invalid(field + ".normal", j["normal"], "must be non-zero");
  plane.normal = normal.normalized();  // stations may send an unnormalised normal
  SOFTID_ASSIGN_OR_RETURN(plane.offset, json::ToFiniteNumber(j["offset"], field + ".offset"));
  return plane;
}

Result<StiffnessField> StiffnessFieldFromJson(const nlohmann::json& j, const std::string& field) {
  if (!j.is_object() || !j.contains("kind")) {
    return json::Invalid(field, j, "must be an object with \"kind\": uniform | regions | linear");
  }
  StiffnessField out;
  SOFTID_ASSIGN_OR_RETURN(std::string kind, json::ToString(j["kind"], field + ".kind"));
  if (kind == "uniform") {
    out.kind = StiffnessField::Kind::kUniform;
  } else if (kind == "regions") {
    out.kind = StiffnessField::Kind::kRegions;
    if (!j.contains("regions") || !j["regions"].is_array()) {
      return json::Invalid(field + ".regions", j.value("regions", nlohmann::json()),
                           "must be an array");
    }
    for (size_t i = 0; i < j["regions"].size(); ++i) {
      const auto& r = j["regions"][i];
      const std::string prefix = field + ".regions[" + std::to_string(i) + "]";
      if (!r.is_object()) return json::Invalid(prefix, r, "must be an object");
      StiffnessField::Region region;
      SOFTID_ASSIGN_OR_RETURN(Eigen::Vector3d lo,
                              json::ToVector3(r.value("min", nlohmann::json()), prefix + ".min"));
      SOFTID_ASSIGN_OR_RETURN(Eigen::Vector3d hi,
                              json::ToVector3(r.value("max", nlohmann::json()), prefix + ".max"));
      SOFTID_ASSIGN_OR_RETURN(region.scale, json::ToFiniteNumber(r.value("scale", nlohmann::json()),
                                                                 prefix + ".scale"));
      region.box = Eigen::AlignedBox3d(lo, hi);
      out.regions.push_back(region);
    }
  } else if (kind == "linear") {
    out.kind = StiffnessField::Kind::kLinear;
    SOFTID_ASSIGN_OR_RETURN(
        out.origin, json::ToVector3(j.value("origin", nlohmann::json()), field + ".origin"));
    SOFTID_ASSIGN_OR_RETURN(
        out.log_gradient,
        json::ToVector3(j.value("log_gradient", nlohmann::json()), field + ".log_gradient"));
  } else {
    return json::Invalid(field + ".kind", j["kind"], "must be uniform, regions or linear");
  }
  return out;
}

Result<PhysicalParameters> PhysicalParametersFromJson(const nlohmann::json& j,
                                                      const PhysicalParameters& defaults) {
  if (!j.is_object()) return json::Invalid("parameters", j, "must be a JSON object");
  PhysicalParameters p = defaults;
  const std::map<std::string, double*> scalars = {
      {"youngs_modulus", &p.youngs_modulus},
      {"poisson_ratio", &p.poisson_ratio},
      {"density", &p.density},
      {"mass_damping", &p.mass_damping},
      {"stiffness_damping", &p.stiffness_damping},
      {"contact_stiffness", &p.contact_stiffness},
      {"contact_damping", &p.contact_damping},
      {"friction_coefficient", &p.friction_coefficient},
      {"drag_linear", &p.drag_linear},
      {"drag_quadratic", &p.drag_quadratic},
  };
  const std::map<std::string, Eigen::Vector3d*> vectors = {
      {"gravity", &p.gravity},
      {"initial_velocity", &p.initial_velocity},
      {"initial_angular_velocity", &p.initial_angular_velocity},
  };
  for (const auto& [key, value] : j.items()) {
    if (auto it = scalars.find(key); it != scalars.end()) {
      SOFTID_ASSIGN_OR_RETURN(*it->second, json::ToFiniteNumber(value, key));
    } else if (auto vit = vectors.find(key); vit != vectors.end()) {
      SOFTID_ASSIGN_OR_RETURN(*vit->second, json::ToVector3(value, key));
    } else if (key == "ground") {
      if (value.is_null()) {
        p.ground.reset();
      } else {
        SOFTID_ASSIGN_OR_RETURN(p.ground, GroundPlaneFromJson(value, key));
      }
    } else if (key == "stiffness_field") {
      SOFTID_ASSIGN_OR_RETURN(p.stiffness_field, StiffnessFieldFromJson(value, key));
    } else {
      return json::Invalid(key, value, "is not a known parameter name");
    }
  }
  SOFTID_RETURN_IF_ERROR(p.Validate());
  return p;
}

const char* ParameterUnit(const std::string& name) {
  static const std::map<std::string, const char*> kUnits = {
      {"youngs_modulus", "Pa"},
      {"poisson_ratio", "1"},
      {"density", "kg/m^3"},
      {"mass_damping", "1/s"},
      {"stiffness_damping", "s"},
      {"gravity", "m/s^2"},
      {"initial_velocity", "m/s"},
      {"initial_angular_velocity", "rad/s"},
      {"ground", "m"},
      {"ground_plane", "m"},
      {"contact_stiffness", "Pa/m"},
      {"contact_damping", "s"},
      {"friction_coefficient", "1"},
      {"stiffness_field", "1"},
      {"drag_linear", "kg/(m^2 s)"},
      {"drag_quadratic", "kg/m^3"},
  };
  auto it = kUnits.find(name);
  return it == kUnits.end() ? "" : it->second;
}

}  // namespace softid::fem
