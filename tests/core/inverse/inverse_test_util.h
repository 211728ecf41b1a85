// A small synthetic capture written to a temporary folder, loaded back as the fit sees it, and a
// config that fits its Young's modulus.
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>

#include "core/capture/capture.h"
#include "core/inverse/job_config.h"
#include "core/inverse/observed_frames.h"
#include "core/scenes/scene.h"
#include "core/scenes/synthesize.h"

namespace softid::inverse::testing {

struct SmallCapture {
  bool ok = false;
  std::string error;
  std::filesystem::path directory;
  capture::Capture capture;
  geometry::TriangleMesh mesh;
  fem::PhysicalParameters truth;
  std::shared_ptr<const std::vector<ObservedFrame>> frames;

  ~SmallCapture() {
    std::error_code ignored;
    if (!directory.empty()) std::filesystem::remove_all(directory, ignored);
  }
};

// Scene `name` simulated for `duration` seconds at 60 fps with 2 substeps on an 8-cell grid, seen
// by 2 40x40 cameras, noise-free unless `depth_noise_m` (sigma, depth-independent) is given.
inline SmallCapture MakeSmallCapture(const std::string& name, double duration, int cameras = 2,
                                     int cells = 8, double depth_noise_m = 0.0) {
  SmallCapture out;
  Result<scenes::Scene> scene = scenes::MakeBuiltinScene(name);
  if (!scene.ok()) {
    out.error = scene.status().ToString();
    return out;
  }
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  out.directory = std::filesystem::temp_directory_path() /
                  ("softid_inverse_" + std::string(info ? info->name() : "none") + "_" +
                   std::to_string(::getpid()) + "_" +
                   std::to_string(static_cast<long long>(depth_noise_m * 1e9)));
  std::filesystem::remove_all(out.directory);
  scenes::SynthesisOptions options;
  options.run.duration = duration;
  options.run.substeps_per_frame = 2;
  options.run.simulation.cells_along_longest_side = cells;
  options.cameras.count = cameras;
  options.cameras.width = 40;
  options.cameras.height = 40;
  options.noise.sigma_constant = depth_noise_m;
  options.noise.seed = 7;
  Result<scenes::SynthesisSummary> summary = scenes::Synthesize(*scene, options, out.directory);
  if (!summary.ok()) {
    out.error = summary.status().ToString();
    return out;
  }
  Result<capture::Capture> capture = capture::ReadCapture(out.directory);
  if (!capture.ok()) {
    out.error = capture.status().ToString();
    return out;
  }
  out.capture = *capture;
  out.mesh = *capture::LoadCaptureMesh(out.capture);
  out.truth = scene->parameters;
  Result<std::vector<ObservedFrame>> frames = LoadObservedFrames(out.capture, 0, -1);
  if (!frames.ok()) {
    out.error = frames.status().ToString();
    return out;
  }
  out.frames = std::make_shared<const std::vector<ObservedFrame>>(std::move(*frames));
  out.ok = true;
  return out;
}

// Young's modulus from `starts` random starts between 0.3 and 3 times the truth, everything
// else fixed at the truth (density from the capture's mass), on an 8-cell grid with 2 substeps.
inline JobConfig YoungsModulusConfig(const fem::PhysicalParameters& truth, int starts,
                                     int max_iterations) {
  JobConfig config;
  config.fit = {"youngs_modulus"};
  config.initial["youngs_modulus"].range =
      ScalarRange{0.3 * truth.youngs_modulus, 3.0 * truth.youngs_modulus};
  config.fixed = fem::ToJson(truth);
  config.fixed.erase("youngs_modulus");
  config.fixed.erase("density");  // from the capture's mass
  config.solver.cells = 8;
  config.solver.substeps = 2;
  config.solver.starts = starts;
  config.solver.max_iterations = max_iterations;
  return config;
}

// Young's modulus from one start at the truth, the rest of the truth fixed, on `cells` and
// `substeps`, to a tight tolerance: the optimum of that discretisation.
inline JobConfig ModulusAtDiscretisation(const fem::PhysicalParameters& truth, int cells,
                                         int substeps) {
  JobConfig config = YoungsModulusConfig(truth, /*starts=*/1, /*max_iterations=*/30);
  config.initial["youngs_modulus"] = InitialValue{.value = truth.youngs_modulus, .range = {}};
  config.solver.cells = cells;
  config.solver.substeps = substeps;
  config.solver.threads = 2;
  config.solver.function_tolerance = 1e-10;
  return config;
}

// A result's or report's JSON without its timing ("timing", "seconds", "*_seconds"): what two
// runs of the same computation must agree on.
inline nlohmann::json WithoutTiming(nlohmann::json json) {
  if (json.is_object()) {
    for (auto it = json.begin(); it != json.end();) {
      const std::string& key = it.key();
      if (key == "timing" || key == "seconds" || key.ends_with("_seconds")) {
        it = json.erase(it);
      } else {
        *it = WithoutTiming(*it);
        ++it;
      }
    }
  } else if (json.is_array()) {
    for (nlohmann::json& item : json) item = WithoutTiming(item);
  }
  return json;
}

}  // namespace softid::inverse::testing
