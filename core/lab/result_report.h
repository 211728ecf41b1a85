// Human-readable output of fit results for softid-lab: parameter lists, a table of recovered
// values (next to the truth when a synthetic capture carries truth.json), and atomic JSON writes.
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/fem/physical_parameters.h"

namespace softid::lab {

// "youngs_modulus=2.1e+04 Pa gravity=[0, 0, -9.8] m/s^2".
std::string FormatParameters(const fem::PhysicalParameters& p,
                             const std::vector<std::string>& names);

// Writes through a temporary file renamed into place, so a reader never sees half a file.
Status WriteJsonFile(const std::filesystem::path& path, const nlohmann::json& json);

// Prints one line per fitted parameter: value, unit, start, and (if `truth_file` exists) the
// true value and the relative error.
void PrintResultTable(const nlohmann::json& result, const std::filesystem::path& truth_file);

}  // namespace softid::lab
