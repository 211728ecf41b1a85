#include "core/lab/result_report.h"

#include <fmt/format.h>

#include <cmath>
#include <cstdio>
#include <fstream>

#include "core/fem/parameter_registry.h"
#include "core/inverse/fit.h"

namespace softid::lab {
namespace {

std::string Compact(const nlohmann::json& value) {
  if (value.is_number()) return fmt::format("{:.5g}", value.get<double>());
  if (value.is_array()) {
    std::string out = "[";
    for (size_t i = 0; i < value.size(); ++i) out += (i ? ", " : "") + Compact(value[i]);
    return out + "]";
  }
  if (value.is_object() && value.contains("normal") && value.contains("offset"))
    return "n=" + Compact(value["normal"]) + " d=" + Compact(value["offset"]);
  return value.dump();
}

// Relative error of a recovered value against the truth (vectors: |a - b| / |b|).
std::optional<double> RelativeError(const nlohmann::json& value, const nlohmann::json& truth) {
  if (value.is_number() && truth.is_number()) {
    const double t = truth.get<double>();
    if (t == 0.0) return std::nullopt;
    return std::abs(value.get<double>() - t) / std::abs(t);
  }
  if (value.is_array() && truth.is_array() && value.size() == truth.size()) {
    double diff = 0.0, norm = 0.0;
    for (size_t i = 0; i < value.size(); ++i) {
      diff += std::pow(value[i].get<double>() - truth[i].get<double>(), 2);
      norm += std::pow(truth[i].get<double>(), 2);
    }
    if (norm == 0.0) return std::nullopt;
    return std::sqrt(diff / norm);
  }
  return std::nullopt;
}

}  // namespace

std::string FormatParameters(const fem::PhysicalParameters& p,
                             const std::vector<std::string>& names) {
  std::string out;
  for (const std::string& name : names) {
    if (!out.empty()) out += " ";
    out += name + "=" + Compact(inverse::ParameterValueJson(p, name));
    const std::string unit(fem::ParameterUnit(name));
    if (!unit.empty() && unit != "1") out += " " + unit;
  }
  return out;
}

Status WriteJsonFile(const std::filesystem::path& path, const nlohmann::json& json) {
  std::error_code error;
  // `--out new/result.json` makes its folder, as the report beside it does.
  if (path.has_parent_path()) {
    std::filesystem::create_directories(path.parent_path(), error);
    if (error) {
      return Status::IoError(path.string() + ": cannot create its folder " +
                             path.parent_path().string() + " (" + error.message() + ")");
    }
  }
  const std::filesystem::path temporary = path.string() + ".tmp";
  {
    std::ofstream out(temporary);
    if (!out) return Status::IoError(path.string() + ": cannot be written");
    out << json.dump(2) << "\n";
    if (!out) return Status::IoError(path.string() + ": write failed");
  }
  std::filesystem::rename(temporary, path, error);
  if (error) return Status::IoError(path.string() + ": " + error.message());
  return Status::Ok();
}

void PrintResultTable(const nlohmann::json& result, const std::filesystem::path& truth_file) {
  nlohmann::json truth;
  if (std::ifstream in(truth_file); in) {
    try {
      truth = nlohmann::json::parse(in).value("parameters", nlohmann::json::object());
    } catch (const nlohmann::json::exception&) {
      truth = nullptr;
    }
  }
  std::printf("%-26s %-32s %-24s %-24s %-10s %-32s", "parameter", "recovered", "1-sigma",
              "discretisation", "unit", "start");
  if (!truth.is_null()) std::printf(" %-32s %s", "truth", "error");
  std::printf("\n");
  for (const auto& [name, entry] : result["parameters"].items()) {
    const std::string sigma = !entry.contains("standard_uncertainty") ? "-"
                              : entry["standard_uncertainty"].is_null()
                                  ? "undetermined"
                                  : Compact(entry["standard_uncertainty"]);
    // The estimated bias of the grid and time step (docs/results.md), beside the noise's sigma.
    const std::string bias = !entry.contains("discretisation_error") ? "-"
                             : entry["discretisation_error"]["total"].is_null()
                                 ? "undetermined"
                                 : Compact(entry["discretisation_error"]["total"]);
    std::printf("%-26s %-32s %-24s %-24s %-10s %-32s", name.c_str(),
                Compact(entry["value"]).c_str(), sigma.c_str(), bias.c_str(),
                entry["unit"].get<std::string>().c_str(), Compact(entry["initial"]).c_str());
    const std::string key = name == "ground_plane" ? "ground" : name;
    if (!truth.is_null() && truth.contains(key)) {
      std::printf(" %-32s", Compact(truth[key]).c_str());
      if (auto error = RelativeError(entry["value"], truth[key]))
        std::printf(" %.2f %%", 100.0 * *error);
    }
    std::printf("\n");
  }
  std::printf("cost %.4e -> %.4e m^2 after %d iterations (%s), %.1f s\n",
              result["cost"]["initial"].get<double>(), result["cost"]["final"].get<double>(),
              result["iterations"].get<int>(),
              result["converged"].get<bool>() ? "converged" : "not converged",
              result["timing"]["total_seconds"].get<double>());
}

}  // namespace softid::lab
