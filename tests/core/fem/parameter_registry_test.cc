#include "core/fem/parameter_registry.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <set>
#include <sstream>
#include <string>
#include <vector>

namespace softid::fem {
namespace {

// A value of the parameter's JSON form away from its default, valid for the parameter.
nlohmann::json SampleJson(const ParameterInfo& parameter) {
  switch (parameter.shape) {
    case ParameterShape::kScalar: {
      const ValidRange& range = parameter.range;
      // Inside the range: the middle of a bounded one, or above its lower bound.
      return std::isinf(range.upper) ? range.lower + 0.37
                                     : 0.5 * (range.lower + range.upper) + 0.01;
    }
    case ParameterShape::kVector3: return {0.25, -1.5, 3.0};
    case ParameterShape::kPlane: return {{"normal", {0.0, 0.6, 0.8}}, {"offset", 0.125}};
    case ParameterShape::kStiffnessField:
      return {{"kind", "regions"},
              {"regions", {{{"min", {0.0, 0.0, 0.0}}, {"max", {1.0, 1.0, 1.0}}, {"scale", 2.5}}}}};
    case ParameterShape::kPose:
      return {{"rotation", {0.01, -0.02, 0.03}}, {"translation", {0.001, 0.002, -0.003}}};
  }
  return nullptr;
}

std::string FormatNumber(double value) {
  std::ostringstream out;
  out << value;
  return out.str();
}

std::string DefaultText(const ParameterInfo& parameter) {
  const nlohmann::json value = ToJson(PhysicalParameters{}, parameter);
  switch (parameter.shape) {
    case ParameterShape::kScalar: return FormatNumber(value.get<double>());
    case ParameterShape::kVector3: {
      std::string text = "(";
      for (int k = 0; k < 3; ++k) {
        if (k > 0) text += ", ";
        text += FormatNumber(value[k].get<double>());
      }
      return text + ")";
    }
    case ParameterShape::kPlane: return value.is_null() ? "none" : value.dump();
    case ParameterShape::kStiffnessField: return value["kind"].get<std::string>();
    case ParameterShape::kPose: return "identity";
  }
  return "?";
}

std::string ValidValuesText(const ParameterInfo& parameter) {
  switch (parameter.shape) {
    case ParameterShape::kScalar: return parameter.range.ToString();
    case ParameterShape::kVector3: return "finite";
    case ParameterShape::kPlane: return "any non-zero normal, finite offset";
    case ParameterShape::kStiffnessField: return "region scales > 0";
    case ParameterShape::kPose: return "finite";
  }
  return "?";
}

std::string Row(const std::vector<std::string>& cells) {
  std::string row = "|";
  for (const std::string& cell : cells) {
    row += " ";
    row += cell;
    row += " |";
  }
  return row;
}

// The table of docs/job-config.md as the registry says it must read.
std::vector<std::string> ExpectedTable() {
  std::vector<std::string> lines = {
      Row({"name", "meaning", "unit", "valid values", "default", "optimiser variable"}),
      Row({"---", "---", "---", "---", "---", "---"})};
  for (const ParameterInfo& p : ParameterRegistry()) {
    std::string name = "`";
    name += p.name;
    name += "`";
    if (p.json_key != p.name) {
      name += " (alias `";
      name += p.json_key;
      name += "`)";
    }
    lines.push_back(Row({name, std::string(p.description), std::string(p.unit), ValidValuesText(p),
                         DefaultText(p), std::string(Describe(p.transform))}));
  }
  return lines;
}

// The table under "## Fittable parameters" in docs/job-config.md.
std::vector<std::string> DocumentedTable() {
  std::ifstream file(std::string(SOFTID_SOURCE_DIR) + "/docs/job-config.md");
  std::vector<std::string> lines;
  bool in_section = false;
  for (std::string line; std::getline(file, line);) {
    if (line.rfind("## ", 0) == 0) in_section = line == "## Fittable parameters";
    if (!in_section) continue;
    if (line.rfind("|", 0) == 0) {
      lines.push_back(line);
    } else if (!lines.empty()) {
      break;
    }
  }
  return lines;
}

// The reference in the docs is the registry: names, units, ranges, defaults and transforms.
TEST(ParameterRegistry, DocumentedTableMatches) {
  const std::vector<std::string> documented = DocumentedTable();
  const std::vector<std::string> expected = ExpectedTable();
  for (size_t i = 0; i < std::max(documented.size(), expected.size()); ++i) {
    EXPECT_EQ(i < documented.size() ? documented[i] : "(missing)",
              i < expected.size() ? expected[i] : "(none)")
        << "line " << i + 1 << " of the table";
  }
  if (::testing::Test::HasFailure()) {
    std::string table;
    for (const std::string& line : expected) table += line + "\n";
    ADD_FAILURE() << SOFTID_SOURCE_DIR "/docs/job-config.md, \"## Fittable parameters\", should "
                  << "list the registry (core/fem/parameter_registry.cc):\n"
                  << table;
  }
}

TEST(ParameterRegistry, LookupByNameAndKey) {
  ASSERT_NE(FindParameter("ground_plane"), nullptr);
  EXPECT_EQ(FindParameter("ground"), FindParameter("ground_plane"));
  EXPECT_EQ(FindParameter("ground")->json_key, "ground");
  EXPECT_EQ(FindParameter("youngs_modulo"), nullptr);
  EXPECT_EQ(ParameterUnit("ground"), "m");
  EXPECT_EQ(ParameterUnit("mass_damping"), "1/s");
  EXPECT_EQ(ParameterUnit("youngs_modulo"), "");
  PhysicalParameters p;
  ASSERT_NE(ScalarParameter(p, "density"), nullptr);
  *ScalarParameter(p, "density") = 12.0;
  EXPECT_EQ(p.density, 12.0);
  EXPECT_EQ(ScalarParameter(p, "gravity"), nullptr);
  std::set<std::string_view> names;
  for (const ParameterInfo& parameter : ParameterRegistry()) {
    EXPECT_TRUE(names.insert(parameter.name).second) << parameter.name;
    EXPECT_FALSE(parameter.unit.empty()) << parameter.name;
    EXPECT_EQ(FindParameter(parameter.name), &parameter);
    EXPECT_EQ(FindParameter(parameter.json_key), &parameter);
  }
}

// The full JSON has exactly the registry's keys, and each parameter's value round-trips alone.
TEST(ParameterRegistry, EveryParameterRoundTripsThroughJson) {
  const nlohmann::json defaults = ToJson(PhysicalParameters{});
  EXPECT_EQ(defaults.size(), ParameterRegistry().size());
  for (const ParameterInfo& parameter : ParameterRegistry()) {
    SCOPED_TRACE(std::string(parameter.name));
    const std::string key(parameter.json_key);
    EXPECT_TRUE(defaults.contains(key));
    const nlohmann::json sample = SampleJson(parameter);
    const Result<PhysicalParameters> read = PhysicalParametersFromJson({{key, sample}});
    ASSERT_TRUE(read.ok()) << read.status().ToString();
    EXPECT_NE(ToJson(*read, parameter), ToJson(PhysicalParameters{}, parameter));
    EXPECT_EQ(ToJson(*read)[key], ToJson(*read, parameter));
    const Result<PhysicalParameters> back = PhysicalParametersFromJson(ToJson(*read));
    ASSERT_TRUE(back.ok()) << back.status().ToString();
    EXPECT_EQ(ToJson(*back), ToJson(*read));
    PhysicalParameters copy;
    CopyParameter(parameter, *read, &copy);
    EXPECT_EQ(ToJson(copy), ToJson(*read));
  }
  // The job config's name of the plane is not a PhysicalParameters key.
  EXPECT_FALSE(PhysicalParametersFromJson({{"ground_plane", nullptr}}).ok());
}

// Validate applies each scalar's range and names the JSON key.
TEST(ParameterRegistry, ValidateAppliesTheRanges) {
  for (const ParameterInfo& parameter : ParameterRegistry()) {
    if (parameter.shape != ParameterShape::kScalar) continue;
    SCOPED_TRACE(std::string(parameter.name));
    PhysicalParameters p;
    const double outside = parameter.range.lower - 1.0;
    p.*parameter.scalar = outside;
    const Status status = p.Validate();
    ASSERT_FALSE(status.ok());
    EXPECT_EQ(status.message(), std::string(parameter.json_key) + " = " +
                                    nlohmann::json(outside).dump() + ": " +
                                    parameter.range.Requirement());
    p.*parameter.scalar = std::numeric_limits<double>::quiet_NaN();
    EXPECT_FALSE(p.Validate().ok());
  }
  EXPECT_EQ(FindParameter("density")->range.Requirement(), "must be positive and finite");
  EXPECT_EQ(FindParameter("mass_damping")->range.Requirement(), "must be non-negative and finite");
  EXPECT_EQ(FindParameter("poisson_ratio")->range.Requirement(), "must lie in (0, 0.5)");
}

// The gradient's sum and JSON cover every parameter under its JSON key.
TEST(ParameterRegistry, GradientSumAndJsonCoverEveryParameter) {
  ParameterGradient g;
  double value = 1.0;
  for (const ParameterInfo& parameter : ParameterRegistry()) {
    switch (parameter.shape) {
      case ParameterShape::kScalar: g.*parameter.scalar_gradient = value; break;
      case ParameterShape::kVector3:
        g.*parameter.vector_gradient = Eigen::Vector3d(value, -value, 2 * value);
        break;
      case ParameterShape::kPlane:
        g.ground_normal = Eigen::Vector3d(value, 0, 0);
        g.ground_offset = value;
        break;
      case ParameterShape::kStiffnessField: g.stiffness_field = {value, value}; break;
      case ParameterShape::kPose:
        g.initial_pose_rotation = Eigen::Vector3d(value, 0, -value);
        g.initial_pose_translation = Eigen::Vector3d(0, value, 0);
        break;
    }
    value += 1.0;
  }
  ParameterGradient twice = g;
  twice += g;
  const nlohmann::json once_json = ToJson(g), twice_json = ToJson(twice);
  EXPECT_EQ(once_json.size(), ParameterRegistry().size());
  for (const ParameterInfo& parameter : ParameterRegistry()) {
    SCOPED_TRACE(std::string(parameter.name));
    const std::string key(parameter.json_key);
    ASSERT_TRUE(once_json.contains(key));
    const nlohmann::json& once = once_json[key];
    const nlohmann::json& sum = twice_json[key];
    switch (parameter.shape) {
      case ParameterShape::kScalar: EXPECT_EQ(sum.get<double>(), 2 * once.get<double>()); break;
      case ParameterShape::kVector3:
      case ParameterShape::kStiffnessField:
        for (size_t k = 0; k < once.size(); ++k)
          EXPECT_EQ(sum[k].get<double>(), 2 * once[k].get<double>());
        break;
      case ParameterShape::kPlane:
        EXPECT_EQ(sum["offset"].get<double>(), 2 * once["offset"].get<double>());
        EXPECT_EQ(sum["normal"][0].get<double>(), 2 * once["normal"][0].get<double>());
        break;
      case ParameterShape::kPose:
        EXPECT_EQ(sum["rotation"][0].get<double>(), 2 * once["rotation"][0].get<double>());
        EXPECT_EQ(sum["translation"][1].get<double>(), 2 * once["translation"][1].get<double>());
        break;
    }
  }
}

TEST(DefaultContactStiffness, IsHundredTimesEOverL) {
  EXPECT_EQ(DefaultContactStiffness(4e4, 0.2), 100.0 * 4e4 / 0.2);
}

}  // namespace
}  // namespace softid::fem
