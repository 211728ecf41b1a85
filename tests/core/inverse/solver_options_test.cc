#include "core/inverse/solver_options.h"

#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <limits>
#include <string>
#include <vector>

namespace softid::inverse {
namespace {

using nlohmann::json;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

// One field set out of range in code, and the start of the message Validate must give.
struct BadField {
  std::function<void(SolverOptions&)> set;
  std::string prefix;
  std::string reason;
};

TEST(SolverOptions, DefaultsAreValidAndAreWhatAnEmptyConfigGives) {
  EXPECT_TRUE(SolverOptions{}.Validate().ok());
  const Result<SolverOptions> parsed = SolverOptionsFromJson(json::object());
  ASSERT_TRUE(parsed.ok()) << parsed.status().ToString();
  EXPECT_EQ(*parsed, SolverOptions{});
}

// Validate checks the typed fields themselves, with the parser's words, including values JSON
// cannot carry (NaN, infinity, enum values out of range).
TEST(SolverOptions, ValidateNamesEveryFieldOutOfRange) {
  const std::vector<BadField> cases = {
      {[](SolverOptions& o) { o.cells = 1; }, "cells = 1: ", "\"auto\" or an integer >= 2"},
      {[](SolverOptions& o) { o.cell_size_m = -0.01; }, "cell_size = -0.01: ", "> 0"},
      {[](SolverOptions& o) { o.cell_size_m = kInf; }, "cell_size = ", "finite number > 0"},
      {[](SolverOptions& o) { o.substeps = -2; }, "substeps = -2: ", "integer >= 1"},
      {[](SolverOptions& o) { o.rho_infinity = 1.5; }, "rho_infinity = 1.5: ", "in [0, 1]"},
      {[](SolverOptions& o) { o.rho_infinity = kNaN; }, "rho_infinity = ", "in [0, 1]"},
      {[](SolverOptions& o) { o.element = static_cast<fem::ElementFormulation>(5); },
       "element = 5: ", "\"trilinear\" or \"incompatible_modes\""},
      {[](SolverOptions& o) { o.grid_orientation = static_cast<fem::GridOrientation>(4); },
       "grid_orientation = 4: ", "\"world\" or \"body\""},
      {[](SolverOptions& o) { o.cut_cell_samples = 3; }, "cut_cell_samples = 3: ",
       "1, 2, 4 or 8"},
      {[](SolverOptions& o) { o.starts = 0; }, "starts = 0: ", "integer >= 1"},
      {[](SolverOptions& o) { o.threads = -1; }, "threads = -1: ", "integer >= 0"},
      {[](SolverOptions& o) { o.max_iterations = 0; }, "max_iterations = 0: ", "integer >= 1"},
      {[](SolverOptions& o) { o.function_tolerance = 0; }, "function_tolerance = 0.0: ", "> 0"},
      {[](SolverOptions& o) { o.gradient_tolerance = kNaN; }, "gradient_tolerance = ", "> 0"},
      {[](SolverOptions& o) { o.parameter_tolerance = -1; }, "parameter_tolerance = -1.0: ", "> 0"},
      {[](SolverOptions& o) { o.max_seconds = kInf; }, "max_seconds = ", "finite number >= 0"},
      {[](SolverOptions& o) { o.finite_difference_step = kInf; },
       "finite_difference_step = ", "finite number > 0"},
      {[](SolverOptions& o) { o.refine_iterations = -1; }, "refine_iterations = -1: ", ">= 0"},
      {[](SolverOptions& o) { o.gradient = static_cast<GradientMethod>(7); },
       "gradient = 7: ", "\"adjoint\" or \"finite_difference\""},
      {[](SolverOptions& o) { o.cost.band_cells = 0; }, "cost.band_cells = 0: ", "integer >= 1"},
      {[](SolverOptions& o) { o.cost.truncation_cells = kNaN; }, "cost.truncation_cells = ", "> 0"},
      {[](SolverOptions& o) { o.cost.rest_sdf = static_cast<cost::RestSdf>(9); },
       "cost.rest_sdf = 9: ", "\"surface_fitted\", \"exact\" or \"sampled\""},
      {[](SolverOptions& o) { o.cost.frame_loss = static_cast<FrameLossKind>(7); },
       "cost.frame_loss = 7: ", "\"squared\" or \"cauchy\""},
      {[](SolverOptions& o) { o.cost.frame_loss_noise_multiple = 0.0; },
       "cost.frame_loss_noise_multiple = 0.0: ", "> 0"},
  };
  for (const BadField& bad : cases) {
    SolverOptions options;
    bad.set(options);
    const Status status = options.Validate();
    ASSERT_FALSE(status.ok()) << "accepted; expected " << bad.prefix;
    EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
    EXPECT_EQ(status.message().rfind(bad.prefix, 0), 0u) << status.message();
    EXPECT_NE(status.message().find(bad.reason), std::string::npos) << status.message();
  }
}

// The sentinels "auto" and "absent" are valid, and every field survives the JSON round trip.
TEST(SolverOptions, JsonRoundTripKeepsEveryField) {
  SolverOptions options;
  options.cells = 24;
  options.cell_size_m = 0.004;
  options.substeps = 6;
  options.rho_infinity = 0.8;
  options.element = fem::ElementFormulation::kIncompatibleModes;
  options.grid_orientation = fem::GridOrientation::kWorld;
  options.cut_cell_samples = 8;
  options.starts = 3;
  options.threads = 2;
  options.seed = 12345678901234ULL;
  options.max_iterations = 17;
  options.function_tolerance = 1e-7;
  options.gradient_tolerance = 1e-9;
  options.parameter_tolerance = 1e-6;
  options.max_seconds = 120.0;
  options.gradient = GradientMethod::kFiniteDifference;
  options.finite_difference_step = 1e-3;
  options.continuation = false;
  options.launch_from_flight = false;
  options.predictable_frames_only = false;
  options.refine_iterations = 4;
  options.cost = {5, 1.5, cost::RestSdf::kExact};
  ASSERT_TRUE(options.Validate().ok()) << options.Validate().ToString();
  json written = json::object();
  WriteJson(options, &written);
  const Result<SolverOptions> read = SolverOptionsFromJson(written);
  ASSERT_TRUE(read.ok()) << read.status().ToString();
  EXPECT_EQ(*read, options);

  json defaults = json::object();
  WriteJson(SolverOptions{}, &defaults);
  EXPECT_EQ(defaults.at("cells"), "auto");
  EXPECT_EQ(defaults.at("substeps"), "auto");
  EXPECT_FALSE(defaults.contains("cell_size"));     // 0 = absent
  EXPECT_FALSE(defaults.contains("rho_infinity"));  // Newmark
  EXPECT_EQ(defaults.at("cost").at("frame_loss"), "squared");

  SolverOptions robust;
  robust.cost.frame_loss = FrameLossKind::kCauchy;
  robust.cost.frame_loss_noise_multiple = 3.0;
  json robust_json = json::object();
  WriteJson(robust, &robust_json);
  const Result<SolverOptions> robust_read = SolverOptionsFromJson(robust_json);
  ASSERT_TRUE(robust_read.ok()) << robust_read.status().ToString();
  EXPECT_EQ(*robust_read, robust);
}

TEST(SolverOptions, AnUnknownGridOrientationIsRejectedByName) {
  const Result<SolverOptions> read = SolverOptionsFromJson(json{{"grid_orientation", "diagonal"}});
  ASSERT_FALSE(read.ok());
  EXPECT_EQ(read.status().message().rfind("grid_orientation = \"diagonal\": ", 0), 0u)
      << read.status().message();
}

TEST(SolverOptions, ACutCellSamplingOtherThanAPowerOfTwoUpToEightIsRejectedByName) {
  for (const json& value : {json(3), json(16), json(0), json(2.5), json("4")}) {
    const Result<SolverOptions> read = SolverOptionsFromJson(json{{"cut_cell_samples", value}});
    ASSERT_FALSE(read.ok()) << value;
    EXPECT_EQ(read.status().message().rfind("cut_cell_samples = " + value.dump() + ": ", 0), 0u)
        << read.status().message();
  }
  const Result<SolverOptions> four = SolverOptionsFromJson(json{{"cut_cell_samples", 4}});
  ASSERT_TRUE(four.ok()) << four.status().ToString();
  EXPECT_EQ(four->cut_cell_samples, 4);
}

TEST(SolverOptions, AnUnknownFrameLossIsRejectedByName) {
  const Result<SolverOptions> read =
      SolverOptionsFromJson(json{{"cost", {{"frame_loss", "huber"}}}});
  ASSERT_FALSE(read.ok());
  EXPECT_EQ(read.status().message().rfind("cost.frame_loss = \"huber\": ", 0), 0u)
      << read.status().message();
}

// The solver reads only its own keys of a job config: the specification's are the caller's.
TEST(SolverOptions, FromJsonReadsOnlyTheSolverKeys) {
  const json config = json::parse(
      R"({"fit": ["youngs_modulus"], "frames": {"first": 2}, "starts": 2, "anything": 1})");
  const Result<SolverOptions> read = SolverOptionsFromJson(config);
  ASSERT_TRUE(read.ok()) << read.status().ToString();
  EXPECT_EQ(read->starts, 2);
  for (std::string_view key : kSolverOptionKeys) {
    EXPECT_NE(key, "fit");
    EXPECT_NE(key, "frames");
  }
  EXPECT_FALSE(SolverOptionsFromJson(json::array()).ok());
}

}  // namespace
}  // namespace softid::inverse
