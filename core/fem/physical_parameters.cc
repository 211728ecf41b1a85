#include "core/fem/physical_parameters.h"

#include <cmath>

#include "core/common/json_fields.h"
#include "core/fem/parameter_registry.h"

namespace softid::fem {

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

Eigen::Isometry3d InitialPose::WorldFromRest(const Eigen::Vector3d& centre_m) const {
  const double angle = rotation.norm();
  const Eigen::Matrix3d turn = angle > 0.0
                                   ? Eigen::AngleAxisd(angle, rotation / angle).toRotationMatrix()
                                   : Eigen::Matrix3d::Identity();
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = turn;
  pose.translation() = centre_m + translation - turn * centre_m;
  return pose;
}

Status PhysicalParameters::Validate() const {
  for (const ParameterInfo& parameter : ParameterRegistry()) {
    const std::string field(parameter.json_key);
    switch (parameter.shape) {
      case ParameterShape::kScalar: {
        const double value = this->*parameter.scalar;
        if (!parameter.range.Contains(value)) {
          return json::Invalid(field, value, parameter.range.Requirement());
        }
        break;
      }
      case ParameterShape::kVector3: {
        const Eigen::Vector3d& value = this->*parameter.vector;
        if (!value.allFinite())
          return json::Invalid(field, json::FromVector3(value), "must be finite");
        break;
      }
      case ParameterShape::kPlane: {
        if (!ground) break;
        if (!ground->normal.allFinite() || std::abs(ground->normal.norm() - 1.0) > 1e-6) {
          return json::Invalid(field + ".normal", json::FromVector3(ground->normal),
                               "must be a unit vector");
        }
        if (!std::isfinite(ground->offset)) {
          return json::Invalid(field + ".offset", ground->offset, "must be finite");
        }
        break;
      }
      case ParameterShape::kPose: {
        if (!initial_pose.translation.allFinite()) {
          return json::Invalid(field + ".translation", json::FromVector3(initial_pose.translation),
                               "must be finite");
        }
        if (!initial_pose.rotation.allFinite()) {
          return json::Invalid(field + ".rotation", json::FromVector3(initial_pose.rotation),
                               "must be finite");
        }
        break;
      }
      case ParameterShape::kStiffnessField: {
        for (size_t i = 0; i < stiffness_field.regions.size(); ++i) {
          const auto& region = stiffness_field.regions[i];
          const std::string prefix = field + ".regions[" + std::to_string(i) + "]";
          if (!(region.scale > 0.0) || !std::isfinite(region.scale)) {
            return json::Invalid(prefix + ".scale", region.scale, "must be positive and finite");
          }
          if (!(region.box.min().array() <= region.box.max().array()).all()) {
            return json::Invalid(prefix + ".min", json::FromVector3(region.box.min()),
                                 "must not exceed max");
          }
        }
        if (!stiffness_field.log_gradient.allFinite()) {
          return json::Invalid(field + ".log_gradient",
                               json::FromVector3(stiffness_field.log_gradient), "must be finite");
        }
        break;
      }
    }
  }
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

nlohmann::json ToJson(const InitialPose& pose) {
  return {{"rotation", json::FromVector3(pose.rotation)},
          {"translation", json::FromVector3(pose.translation)}};
}

nlohmann::json ToJson(const PhysicalParameters& p) {
  nlohmann::json j = nlohmann::json::object();
  for (const ParameterInfo& parameter : ParameterRegistry()) {
    j[std::string(parameter.json_key)] = ToJson(p, parameter);
  }
  return j;
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

Result<InitialPose> InitialPoseFromJson(const nlohmann::json& j, const std::string& field) {
  if (!j.is_object() || !j.contains("rotation") || !j.contains("translation")) {
    return json::Invalid(field, j,
                         "must be {\"rotation\": [rx, ry, rz], \"translation\": [tx, ty, tz]}");
  }
  InitialPose pose;
  SOFTID_ASSIGN_OR_RETURN(pose.rotation, json::ToVector3(j["rotation"], field + ".rotation"));
  SOFTID_ASSIGN_OR_RETURN(pose.translation,
                          json::ToVector3(j["translation"], field + ".translation"));
  return pose;
}

Result<PhysicalParameters> PhysicalParametersFromJson(const nlohmann::json& j,
                                                      const PhysicalParameters& defaults) {
  if (!j.is_object()) return json::Invalid("parameters", j, "must be a JSON object");
  PhysicalParameters p = defaults;
  for (const auto& [key, value] : j.items()) {
    const ParameterInfo* parameter = FindParameter(key);
    // Only the JSON key: "ground_plane" is the job config's name of "ground".
    if (parameter == nullptr || parameter->json_key != key) {
      return json::Invalid(key, value, "is not a known parameter name");
    }
    SOFTID_RETURN_IF_ERROR(ParameterFromJson(value, *parameter, key, &p));
  }
  SOFTID_RETURN_IF_ERROR(p.Validate());
  return p;
}

}  // namespace softid::fem
