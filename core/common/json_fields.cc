#include "core/common/json_fields.h"

#include <cmath>
#include <cstdint>
#include <limits>

namespace softid::json {

std::string Brief(const nlohmann::json& value) {
  // Invalid UTF-8 in a string (a value built from bytes a client sent) is shown as U+FFFD rather
  // than throwing.
  std::string text = value.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  constexpr size_t kMaxLength = 80;
  if (text.size() > kMaxLength) {
    size_t cut = kMaxLength - 3;
    // Never inside a multi-byte character: the message must stay valid UTF-8 (gRPC status
    // messages and proto string fields carry it).
    while (cut > 0 && (static_cast<unsigned char>(text[cut]) & 0xC0) == 0x80) --cut;
    text = text.substr(0, cut) + "...";
  }
  return text;
}

Status Invalid(const std::string& field, const nlohmann::json& value,
               const std::string& requirement) {
  return Status::InvalidArgument(field + " = " + Brief(value) + ": " + requirement);
}

Result<double> ToFiniteNumber(const nlohmann::json& value, const std::string& field) {
  if (!value.is_number()) return Invalid(field, value, "must be a finite number");
  const double x = value.get<double>();
  if (!std::isfinite(x)) return Invalid(field, value, "must be a finite number");
  return x;
}

Result<Eigen::Vector3d> ToVector3(const nlohmann::json& value, const std::string& field) {
  const char* requirement = "must be an array of 3 finite numbers";
  if (!value.is_array() || value.size() != 3) return Invalid(field, value, requirement);
  Eigen::Vector3d v;
  for (int i = 0; i < 3; ++i) {
    if (!value[i].is_number() || !std::isfinite(value[i].get<double>())) {
      return Invalid(field, value, requirement);
    }
    v[i] = value[i].get<double>();
  }
  return v;
}

Result<std::string> ToString(const nlohmann::json& value, const std::string& field) {
  if (!value.is_string()) return Invalid(field, value, "must be a string");
  return value.get<std::string>();
}

Result<int> ToInteger(const nlohmann::json& value, const std::string& field) {
  if (!value.is_number_integer()) return Invalid(field, value, "must be an integer");
  const auto x = value.get<long long>();
  if (x < -2147483647LL || x > 2147483647LL) return Invalid(field, value, "is out of range");
  return static_cast<int>(x);
}

Result<int> ToIntegerAtLeast(const nlohmann::json& value, const std::string& field, int min,
                             const std::string& requirement) {
  if (!value.is_number_integer()) return Invalid(field, value, requirement);
  constexpr std::int64_t kMax = std::numeric_limits<int>::max();
  if (value.is_number_unsigned() && value.get<std::uint64_t>() > static_cast<std::uint64_t>(kMax)) {
    return Invalid(field, value, requirement);
  }
  const auto x = value.get<std::int64_t>();
  if (x < min || x > kMax) return Invalid(field, value, requirement);
  return static_cast<int>(x);
}

Result<int> ToIntegerAtLeast(const nlohmann::json& value, const std::string& field, int min) {
  return ToIntegerAtLeast(value, field, min, "must be an integer >= " + std::to_string(min));
}

Result<double> ToPositiveNumber(const nlohmann::json& value, const std::string& field) {
  if (!value.is_number() || !std::isfinite(value.get<double>()) || !(value.get<double>() > 0.0)) {
    return Invalid(field, value, "must be a finite number > 0");
  }
  return value.get<double>();
}

nlohmann::json FromVector3(const Eigen::Vector3d& v) {
  return {v.x(), v.y(), v.z()};
}

}  // namespace softid::json
