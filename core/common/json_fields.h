// Typed reads of JSON fields with errors that name the field path and the offending value, e.g.
// `gravity = "down": must be an array of 3 finite numbers`. Shared by every JSON edge of core.
#pragma once

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <string>

#include "core/common/status.h"

namespace softid::json {

// A short rendering of a JSON value for error messages (long values are elided).
std::string Brief(const nlohmann::json& value);

// `field` is the path used in the message ("ground.offset").
Result<double> ToFiniteNumber(const nlohmann::json& value, const std::string& field);
Result<Eigen::Vector3d> ToVector3(const nlohmann::json& value, const std::string& field);
Result<std::string> ToString(const nlohmann::json& value, const std::string& field);
Result<int> ToInteger(const nlohmann::json& value, const std::string& field);
// An integer in [min, INT_MAX]; anything else (other types too) fails with `requirement`, so the
// message always states what is expected.
Result<int> ToIntegerAtLeast(const nlohmann::json& value, const std::string& field, int min,
                             const std::string& requirement);
// The same with the requirement "must be an integer >= <min>".
Result<int> ToIntegerAtLeast(const nlohmann::json& value, const std::string& field, int min);
// A finite number > 0, or "must be a finite number > 0".
Result<double> ToPositiveNumber(const nlohmann::json& value, const std::string& field);

// An InvalidArgument "<field> = <value>: <requirement>".
Status Invalid(const std::string& field, const nlohmann::json& value,
               const std::string& requirement);

nlohmann::json FromVector3(const Eigen::Vector3d& v);

}  // namespace softid::json
