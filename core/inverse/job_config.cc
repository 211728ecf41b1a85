#include "core/inverse/job_config.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <fstream>
#include <sstream>
#include <system_error>

#include "core/common/check.h"
#include "core/common/json_fields.h"

namespace softid::inverse {
namespace {

using Json = nlohmann::json;

constexpr std::string_view kGroundAlias = "ground";
constexpr std::string_view kGroundPlane = "ground_plane";

// The top-level keys of the job's specification (kSolverOptionKeys are the others).
constexpr auto kSpecificationKeys =
    std::to_array<std::string_view>({"fit", "initial", "fixed", "frames", "heldout_every",
                                     "diagnose", "uncertainty", "refine_grid"});

bool IsJobConfigKey(std::string_view key) {
  return std::find(kSpecificationKeys.begin(), kSpecificationKeys.end(), key) !=
             kSpecificationKeys.end() ||
         std::find(kSolverOptionKeys.begin(), kSolverOptionKeys.end(), key) !=
             kSolverOptionKeys.end();
}

std::string Join(const std::vector<std::string>& names) {
  std::string out;
  for (const std::string& name : names) out += (out.empty() ? "" : ", ") + name;
  return out;
}

std::string KnownFittable() {
  std::vector<std::string> names;
  for (const fem::ParameterInfo& parameter : fem::ParameterRegistry())
    names.emplace_back(parameter.name);
  return "unknown parameter (known: " + Join(names) + "; \"ground\" is an alias of ground_plane)";
}

// The public PhysicalParameters keys.
std::vector<std::string> PhysicalKeys() {
  std::vector<std::string> keys;
  for (const fem::ParameterInfo& parameter : fem::ParameterRegistry())
    keys.emplace_back(parameter.json_key);
  return keys;
}

Status UnknownKey(const std::string& object, const std::string& key) {
  return Status::InvalidArgument(object + ": unknown key \"" + key + "\"");
}

// Rejects keys of `object` that are not in `known`, naming `object_name`.
template <typename Names>
Status CheckKeys(const Json& object, const std::string& object_name, const Names& known) {
  for (const auto& item : object.items()) {
    if (std::find(std::begin(known), std::end(known), item.key()) == std::end(known)) {
      return UnknownKey(object_name, item.key());
    }
  }
  return Status::Ok();
}

// Replaces the leading field path `key` of a fem error ("ground.normal = ...") by `field`
// ("initial.ground_plane.normal = ..."), so errors name the path the user wrote.
Status Reroot(const Status& status, const std::string& key, const std::string& field) {
  const std::string& message = status.message();
  if (message.compare(0, key.size(), key) == 0 && message.size() > key.size() &&
      (message[key.size()] == ' ' || message[key.size()] == '.' || message[key.size()] == '[')) {
    return Status(status.code(), field + message.substr(key.size()));
  }
  return status.WithContext(field);
}

// Parses one parameter value in its public JSON form under the PhysicalParameters key `key`, with
// the rules of fem::PhysicalParametersFromJson; returns the normalised form fem::ToJson writes.
Result<Json> NormalisedParameterValue(const std::string& key, const Json& value,
                                      const std::string& field) {
  const Result<fem::PhysicalParameters> parsed =
      fem::PhysicalParametersFromJson(Json::object({{key, value}}));
  if (!parsed.ok()) return Reroot(parsed.status(), key, field);
  Json normalised = fem::ToJson(*parsed)[key];
  if (key == kGroundAlias && !normalised.is_null()) {
    // Dividing a unit normal by its norm again can change its last bits, which would break the
    // exact ToJson round trip; a normal that is unit to rounding is kept as written.
    const Result<Eigen::Vector3d> written = json::ToVector3(value["normal"], field + ".normal");
    if (written.ok() && std::abs(written->norm() - 1.0) <= 1e-12) {
      normalised["normal"] = json::FromVector3(*written);
    }
  }
  return normalised;
}

Result<std::vector<std::string>> ParseFit(const Json& value) {
  if (!value.is_array()) return json::Invalid("fit", value, "must be an array of parameter names");
  if (value.empty()) return json::Invalid("fit", value, "must name at least one parameter");
  std::vector<std::string> fit;
  for (size_t i = 0; i < value.size(); ++i) {
    const std::string field = "fit[" + std::to_string(i) + "]";
    if (!value[i].is_string()) return json::Invalid(field, value[i], "must be a parameter name");
    const std::optional<std::string_view> name = CanonicalFittableName(value[i].get<std::string>());
    if (!name) return json::Invalid(field, value[i], KnownFittable());
    const auto previous = std::find(fit.begin(), fit.end(), *name);
    if (previous != fit.end()) {
      return json::Invalid(
          field, value[i],
          "is listed twice (also fit[" + std::to_string(previous - fit.begin()) + "])");
    }
    fit.emplace_back(*name);
  }
  return fit;
}

// One entry of "initial": `key` as written, `fit` already parsed.
Result<InitialValue> ParseInitialValue(const std::string& key, const Json& value,
                                       const std::vector<std::string>& fit) {
  const std::string field = "initial." + key;
  const std::optional<std::string_view> name = CanonicalFittableName(key);
  if (!name) return json::Invalid(field, value, KnownFittable());
  if (std::find(fit.begin(), fit.end(), *name) == fit.end()) {
    return json::Invalid(field, value,
                         std::string(*name) +
                             " is not in \"fit\"; put the value of a parameter that is not "
                             "fitted in \"fixed\"");
  }
  const std::string physical_key(PhysicalParameterKey(*name));
  const ParameterShape shape = ShapeOf(*name);
  InitialValue initial;
  if (value.is_object() &&
      (shape == ParameterShape::kScalar || value.contains("min") || value.contains("max"))) {
    if (shape != ParameterShape::kScalar) {
      return json::Invalid(field, value,
                           "a {\"min\": a, \"max\": b} range is only allowed for scalar "
                           "parameters; give one start value");
    }
    SOFTID_RETURN_IF_ERROR(CheckKeys(value, field, std::array<std::string_view, 2>{"min", "max"}));
    if (!value.contains("min") || !value.contains("max")) {
      return json::Invalid(field, value, "a range needs both \"min\" and \"max\"");
    }
    SOFTID_ASSIGN_OR_RETURN(const Json min,
                            NormalisedParameterValue(physical_key, value["min"], field + ".min"));
    SOFTID_ASSIGN_OR_RETURN(const Json max,
                            NormalisedParameterValue(physical_key, value["max"], field + ".max"));
    ScalarRange range{min.get<double>(), max.get<double>()};
    if (!(range.min < range.max)) {
      return json::Invalid(field + ".min", value["min"],
                           "must be below max (" + json::Brief(value["max"]) + ")");
    }
    initial.range = range;
    return initial;
  }
  if (shape == ParameterShape::kScalar && !value.is_number()) {
    return json::Invalid(field, value, "must be a number or a range {\"min\": a, \"max\": b}");
  }
  if (shape == ParameterShape::kPlane && value.is_null()) {
    // PhysicalParameters reads null as "no ground"; a fitted plane needs a start plane.
    return json::Invalid(field, value, "must be {\"normal\": [x, y, z], \"offset\": d}");
  }
  SOFTID_ASSIGN_OR_RETURN(initial.value, NormalisedParameterValue(physical_key, value, field));
  return initial;
}

Result<std::map<std::string, InitialValue>> ParseInitial(const Json& value,
                                                         const std::vector<std::string>& fit) {
  if (!value.is_object()) {
    return json::Invalid("initial", value, "must be an object {\"<parameter>\": <start>}");
  }
  std::map<std::string, InitialValue> initial;
  std::map<std::string, std::string> written_as;  // canonical name -> key as written
  for (const auto& item : value.items()) {
    SOFTID_ASSIGN_OR_RETURN(InitialValue start, ParseInitialValue(item.key(), item.value(), fit));
    const std::string name(*CanonicalFittableName(item.key()));
    if (auto it = written_as.find(name); it != written_as.end()) {
      return json::Invalid("initial." + item.key(), item.value(),
                           "duplicate of initial." + it->second);
    }
    written_as[name] = item.key();
    initial[name] = std::move(start);
  }
  return initial;
}

Result<Json> ParseFixed(const Json& value, const std::vector<std::string>& fit) {
  if (!value.is_object()) {
    return json::Invalid("fixed", value, "must be an object {\"<parameter>\": <value>}");
  }
  Json fixed = Json::object();
  std::map<std::string, std::string> written_as;  // PhysicalParameters key -> key as written
  for (const auto& item : value.items()) {
    const std::string field = "fixed." + item.key();
    const fem::ParameterInfo* parameter = fem::FindParameter(item.key());
    if (parameter == nullptr) {
      return json::Invalid(field, item.value(),
                           "unknown parameter (known: " + Join(PhysicalKeys()) +
                               "; \"ground_plane\" is an alias of ground)");
    }
    const std::string key(parameter->json_key);  // "ground" also when written "ground_plane"
    if (auto it = written_as.find(key); it != written_as.end()) {
      return json::Invalid(field, item.value(), "duplicate of fixed." + it->second);
    }
    written_as[key] = item.key();
    if (std::find(fit.begin(), fit.end(), parameter->name) != fit.end()) {
      return json::Invalid(field, item.value(),
                           std::string(parameter->name) +
                               " is also in \"fit\"; a parameter is either fitted or fixed");
    }
    SOFTID_ASSIGN_OR_RETURN(fixed[key], NormalisedParameterValue(key, item.value(), field));
  }
  return fixed;
}

Result<FrameRange> ParseFrames(const Json& value) {
  if (!value.is_object()) {
    return json::Invalid("frames", value, "must be an object {\"first\": f, \"last\": l}");
  }
  SOFTID_RETURN_IF_ERROR(
      CheckKeys(value, "frames", std::array<std::string_view, 2>{"first", "last"}));
  FrameRange frames;
  if (value.contains("first")) {
    SOFTID_ASSIGN_OR_RETURN(frames.first,
                            json::ToIntegerAtLeast(value["first"], "frames.first", 0));
  }
  if (value.contains("last")) {
    const std::string requirement =
        "must be -1 (the capture's last frame) or an integer >= " + std::string("frames.first (") +
        std::to_string(frames.first) + ")";
    SOFTID_ASSIGN_OR_RETURN(frames.last,
                            json::ToIntegerAtLeast(value["last"], "frames.last", -1, requirement));
    if (frames.last != -1 && frames.last < frames.first) {
      return json::Invalid("frames.last", value["last"], requirement);
    }
  }
  return frames;
}

Result<bool> ParseBool(const Json& value, const std::string& field) {
  if (!value.is_boolean()) return json::Invalid(field, value, "must be true or false");
  return value.get<bool>();
}

// Reads the specification keys of `j` into `config` (the solver keys are SolverOptionsFromJson's).
Status ParseSpecification(const Json& j, JobConfig* config) {
  // "initial" and "fixed" refer to "fit", so it is read first whatever the key order.
  if (j.contains("fit")) {
    SOFTID_ASSIGN_OR_RETURN(config->fit, ParseFit(j["fit"]));
  }
  if (j.contains("initial")) {
    SOFTID_ASSIGN_OR_RETURN(config->initial, ParseInitial(j["initial"], config->fit));
  }
  if (j.contains("fixed")) {
    SOFTID_ASSIGN_OR_RETURN(config->fixed, ParseFixed(j["fixed"], config->fit));
  }
  if (j.contains("frames")) {
    SOFTID_ASSIGN_OR_RETURN(config->frames, ParseFrames(j["frames"]));
  }
  if (j.contains("heldout_every")) {
    constexpr const char* kRequirement =
        "must be 0 (none) or an integer >= 2 (1 would hold out every frame)";
    SOFTID_ASSIGN_OR_RETURN(
        config->heldout_every,
        json::ToIntegerAtLeast(j["heldout_every"], "heldout_every", 0, kRequirement));
    if (config->heldout_every == 1)
      return json::Invalid("heldout_every", j["heldout_every"], kRequirement);
  }
  if (j.contains("diagnose")) {
    SOFTID_ASSIGN_OR_RETURN(config->diagnose, ParseBool(j["diagnose"], "diagnose"));
  }
  if (j.contains("uncertainty")) {
    SOFTID_ASSIGN_OR_RETURN(config->uncertainty, ParseBool(j["uncertainty"], "uncertainty"));
  }
  if (j.contains("refine_grid")) {
    SOFTID_ASSIGN_OR_RETURN(config->refine_grid, ParseBool(j["refine_grid"], "refine_grid"));
  }
  if (config->refine_grid && !config->uncertainty) {
    return json::Invalid("refine_grid", true,
                         "needs \"uncertainty\": true (the fitted values' discretisation error "
                         "decides the refinement)");
  }
  return Status::Ok();
}

// The specification keys of ToJson.
Json SpecificationJson(const JobConfig& config) {
  Json initial = Json::object();
  for (const auto& [name, start] : config.initial) {
    if (start.value) {
      initial[name] = *start.value;
    } else if (start.range) {
      initial[name] = {{"min", start.range->min}, {"max", start.range->max}};
    }
  }
  return {
      {"fit", config.fit},
      {"initial", initial},
      {"fixed", config.fixed},
      {"frames", {{"first", config.frames.first}, {"last", config.frames.last}}},
      {"heldout_every", config.heldout_every},
      {"diagnose", config.diagnose},
      {"uncertainty", config.uncertainty},
      {"refine_grid", config.refine_grid},
  };
}

}  // namespace

bool IsFittable(std::string_view name) {
  const fem::ParameterInfo* parameter = fem::FindParameter(name);
  return parameter != nullptr && parameter->name == name;
}

std::optional<std::string_view> CanonicalFittableName(std::string_view name) {
  // FindParameter also finds a parameter by its PhysicalParameters key: the alias "ground".
  const fem::ParameterInfo* parameter = fem::FindParameter(name);
  if (parameter == nullptr) return std::nullopt;
  return parameter->name;
}

std::string_view PhysicalParameterKey(std::string_view fittable_name) {
  SOFTID_THROW_UNLESS(IsFittable(fittable_name),
                      "not a fittable parameter: " + std::string(fittable_name));
  return fem::FindParameter(fittable_name)->json_key;
}

ParameterShape ShapeOf(std::string_view fittable_name) {
  const fem::ParameterInfo* parameter = fem::FindParameter(fittable_name);
  SOFTID_THROW_UNLESS(parameter != nullptr,
                      "not a fittable parameter: " + std::string(fittable_name));
  return parameter->shape;
}

bool JobConfig::IsFitted(std::string_view fittable_name) const {
  return std::find(fit.begin(), fit.end(), fittable_name) != fit.end();
}

bool JobConfig::IsHeldOut(int frame) const {
  return heldout_every > 0 && frame >= frames.first &&
         (frame - frames.first) % heldout_every == heldout_every - 1;
}

Status JobConfig::Validate() const {
  // Checks JSON cannot express (canonical names, one of value/range) come first; the parameter
  // values (JSON by nature) then go through the parser's own rules, and the solver options are
  // checked on their typed fields.
  for (size_t i = 0; i < fit.size(); ++i) {
    if (fit[i] == kGroundAlias) {
      return json::Invalid("fit[" + std::to_string(i) + "]", fit[i],
                           "must be \"ground_plane\" (the alias is resolved only in JSON)");
    }
  }
  for (const auto& [name, start] : initial) {
    if (name == kGroundAlias) {
      return Status::InvalidArgument(
          "initial.ground: must be keyed \"ground_plane\" (the alias is resolved only in JSON)");
    }
    if (start.value.has_value() == start.range.has_value()) {
      return Status::InvalidArgument("initial." + name +
                                     ": exactly one of value and range must be set");
    }
  }
  if (fixed.is_object() && fixed.contains(kGroundPlane)) {
    return Status::InvalidArgument(
        "fixed.ground_plane: must be keyed \"ground\" (the alias is resolved only in JSON)");
  }
  JobConfig parsed;
  SOFTID_RETURN_IF_ERROR(ParseSpecification(SpecificationJson(*this), &parsed));
  return solver.Validate();
}

Result<JobConfig> JobConfigFromJson(const Json& j) {
  if (!j.is_object()) return json::Invalid("job config", j, "must be a JSON object");
  for (const auto& item : j.items()) {
    if (!IsJobConfigKey(item.key())) return UnknownKey("job config", item.key());
  }
  JobConfig config;
  SOFTID_RETURN_IF_ERROR(ParseSpecification(j, &config));
  SOFTID_ASSIGN_OR_RETURN(config.solver, SolverOptionsFromJson(j));
  return config;
}

Result<JobConfig> JobConfigFromString(std::string_view text, std::string_view source) {
  Json j;
  try {
    j = Json::parse(text);
  } catch (const Json::exception& e) {
    // parse_error, or out_of_range for numbers like 1e400. what() is "[json.exception.parse_
    // error.101] parse error at line 3, column 7: ..."; the bracketed id means nothing to users.
    std::string what = e.what();
    if (const size_t end = what.find("] ");
        what.rfind("[json.exception", 0) == 0 && end != std::string::npos) {
      what = what.substr(end + 2);
    }
    return Status::InvalidArgument(std::string(source) + ": invalid JSON: " + what);
  }
  Result<JobConfig> config = JobConfigFromJson(j);
  if (!config.ok()) return config.status().WithContext(std::string(source));
  return config;
}

Result<JobConfig> ReadJobConfig(const std::filesystem::path& file) {
  std::error_code error;
  if (!std::filesystem::exists(file, error)) {
    return Status::NotFound(file.string() + ": job config not found");
  }
  if (std::filesystem::is_directory(file, error)) {
    return Status::InvalidArgument(file.string() + ": is a folder, not a job config file");
  }
  std::ifstream stream(file, std::ios::binary);
  if (!stream) return Status::IoError(file.string() + ": cannot open file");
  std::ostringstream text;
  text << stream.rdbuf();
  if (stream.bad()) return Status::IoError(file.string() + ": read error");
  return JobConfigFromString(text.str(), file.string());
}

Json ToJson(const JobConfig& config) {
  Json j = SpecificationJson(config);
  WriteJson(config.solver, &j);
  return j;
}

Result<fem::PhysicalParameters> ApplyToParameters(const JobConfig& config,
                                                  const fem::PhysicalParameters& base) {
  SOFTID_RETURN_IF_ERROR(config.Validate());
  SOFTID_RETURN_IF_ERROR(base.Validate().WithContext("base parameters"));
  Json overrides = config.fixed;
  for (const auto& [name, start] : config.initial) {
    if (start.value) overrides[std::string(PhysicalParameterKey(name))] = *start.value;
  }
  // Kept in the Result (no SOFTID_ASSIGN_OR_RETURN): moving the optional ground out of it trips a
  // GCC -Wmaybe-uninitialized false positive.
  Result<fem::PhysicalParameters> parameters = fem::PhysicalParametersFromJson(overrides, base);
  if (!parameters.ok()) return parameters;
  if (config.IsFitted(kGroundPlane) && !parameters->ground.has_value()) {
    return Status::InvalidArgument(
        "initial.ground_plane: ground_plane is fitted but neither \"initial\" nor the base "
        "parameters give a start plane");
  }
  return parameters;
}

}  // namespace softid::inverse
