#include "core/inverse/job_config.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <stdexcept>
#include <string>

#include "core/inverse/objective_settings.h"

namespace softid::inverse {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

// A temporary file path for one test; the file is removed on destruction.
class TempFile {
 public:
  explicit TempFile(const std::string& name) {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    path_ = fs::temp_directory_path() / ("softid_job_config_" + std::string(info->name()) + "_" +
                                         std::to_string(::getpid()) + "_" + name);
  }
  ~TempFile() {
    std::error_code error;
    fs::remove(path_, error);
  }
  TempFile(const TempFile&) = delete;
  TempFile& operator=(const TempFile&) = delete;

  const fs::path& path() const { return path_; }
  void Write(const std::string& text) const { std::ofstream(path_, std::ios::binary) << text; }

 private:
  fs::path path_;
};

// Expects InvalidArgument whose message starts with `prefix` (the field path and the value, e.g.
// "cells = 1: ") and contains `reason`.
void ExpectInvalid(const Result<JobConfig>& result, const std::string& prefix,
                   const std::string& reason) {
  ASSERT_FALSE(result.ok()) << "accepted; expected an error starting with " << prefix;
  EXPECT_EQ(result.status().code(), StatusCode::kInvalidArgument);
  const std::string& message = result.status().message();
  EXPECT_EQ(message.rfind(prefix, 0), 0u) << message;
  EXPECT_NE(message.find(reason), std::string::npos) << message;
}

void ExpectInvalid(const json& config, const std::string& prefix, const std::string& reason) {
  SCOPED_TRACE(config.dump());
  ExpectInvalid(JobConfigFromJson(config), prefix, reason);
}

// A config with every key set away from its default.
json FullConfig() {
  return json::parse(R"({
    "fit": ["youngs_modulus", "poisson_ratio", "ground", "gravity", "stiffness_field"],
    "initial": {
      "youngs_modulus": {"min": 1e4, "max": 1e6},
      "poisson_ratio": 0.35,
      "ground": {"normal": [0, 0.2, 1], "offset": 0.01},
      "gravity": [0, 0, -9.7],
      "stiffness_field": {"kind": "linear", "origin": [0, 0, 0], "log_gradient": [1, 0, 0]}
    },
    "fixed": {"density": 950, "initial_velocity": [0.1, 0, 0], "friction_coefficient": 0.4},
    "cells": 24,
    "cell_size": 0.004,
    "substeps": 3,
    "rho_infinity": 0.8,
    "element": "incompatible_modes",
    "frames": {"first": 2, "last": 40},
    "heldout_every": 5,
    "starts": 8,
    "threads": 3,
    "seed": 12345678901,
    "max_iterations": 80,
    "function_tolerance": 1e-7,
    "gradient_tolerance": 1e-9,
    "parameter_tolerance": 1e-6,
    "gradient": "finite_difference",
    "finite_difference_step": 1e-3,
    "continuation": false,
    "refine_iterations": 12,
    "max_seconds": 90.5,
    "cost": {"band_cells": 4, "truncation_cells": 1.5, "rest_sdf": "sampled"},
    "diagnose": true,
    "refine_grid": true
  })");
}

TEST(Fittable, NamesAndShapes) {
  EXPECT_EQ(fem::ParameterRegistry().front().name, "youngs_modulus");
  EXPECT_EQ(fem::ParameterRegistry().back().name, "contact_damping");
  EXPECT_TRUE(IsFittable("ground_plane"));
  EXPECT_FALSE(IsFittable("ground"));  // the alias is resolved by CanonicalFittableName
  EXPECT_FALSE(IsFittable("youngs_modulo"));
  EXPECT_EQ(CanonicalFittableName("ground"), "ground_plane");
  EXPECT_EQ(CanonicalFittableName("density"), "density");
  EXPECT_EQ(CanonicalFittableName("fits"), std::nullopt);
  EXPECT_EQ(PhysicalParameterKey("ground_plane"), "ground");
  EXPECT_EQ(PhysicalParameterKey("drag_linear"), "drag_linear");
  EXPECT_EQ(ShapeOf("youngs_modulus"), ParameterShape::kScalar);
  EXPECT_EQ(ShapeOf("contact_damping"), ParameterShape::kScalar);
  EXPECT_EQ(ShapeOf("initial_angular_velocity"), ParameterShape::kVector3);
  EXPECT_EQ(ShapeOf("ground_plane"), ParameterShape::kPlane);
  EXPECT_EQ(ShapeOf("ground"), ParameterShape::kPlane);
  EXPECT_EQ(ShapeOf("stiffness_field"), ParameterShape::kStiffnessField);
  EXPECT_THROW(ShapeOf("youngs_modulo"), std::invalid_argument);
  // Every fittable parameter is a public PhysicalParameters key (so "fixed" can hold it).
  const json public_keys = fem::ToJson(fem::PhysicalParameters{});
  for (const fem::ParameterInfo& parameter : fem::ParameterRegistry()) {
    EXPECT_TRUE(IsFittable(parameter.name)) << parameter.name;
    EXPECT_TRUE(public_keys.contains(std::string(PhysicalParameterKey(parameter.name))))
        << parameter.name;
  }
}

TEST(JobConfig, DefaultsFromEmptyObject) {
  const Result<JobConfig> config = JobConfigFromJson(json::object());
  ASSERT_TRUE(config.ok()) << config.status().ToString();
  EXPECT_EQ(*config, JobConfig{});
  EXPECT_EQ(config->fit, std::vector<std::string>{"youngs_modulus"});
  EXPECT_TRUE(config->initial.empty());
  EXPECT_EQ(config->fixed, json::object());
  EXPECT_EQ(config->solver.cells, kAutoCells);
  EXPECT_EQ(config->solver.cell_size_m, 0.0);
  EXPECT_EQ(config->solver.substeps, kAutoSubsteps);
  EXPECT_EQ(config->solver.rho_infinity, SolverOptions::kNewmark);
  EXPECT_EQ(SimulationOptionsFor(config->solver).generalized_alpha_f, 0.0);
  EXPECT_EQ(SimulationOptionsFor(config->solver).element, fem::ElementFormulation::kTrilinear);
  EXPECT_EQ(config->frames.first, 0);
  EXPECT_EQ(config->frames.last, -1);
  EXPECT_EQ(config->heldout_every, 0);
  EXPECT_EQ(config->solver.starts, 4);
  EXPECT_EQ(config->solver.threads, 0);
  EXPECT_EQ(config->solver.seed, 1u);
  EXPECT_EQ(config->solver.max_iterations, 50);
  EXPECT_EQ(config->solver.function_tolerance, 1e-6);
  EXPECT_EQ(config->solver.gradient_tolerance, 1e-10);
  EXPECT_EQ(config->solver.parameter_tolerance, 1e-8);
  EXPECT_EQ(config->solver.gradient, GradientMethod::kAdjoint);
  EXPECT_EQ(config->solver.finite_difference_step, 1e-4);
  EXPECT_TRUE(config->solver.continuation);
  EXPECT_TRUE(config->solver.launch_from_flight);
  EXPECT_TRUE(config->solver.predictable_frames_only);
  EXPECT_EQ(config->solver.refine_iterations, 0);
  EXPECT_EQ(config->solver.cost.band_cells, 3);
  EXPECT_EQ(config->solver.cost.truncation_cells, 2.0);
  EXPECT_EQ(config->solver.cost.rest_sdf, cost::RestSdf::kSurfaceFitted);
  EXPECT_FALSE(config->diagnose);
  EXPECT_TRUE(config->uncertainty);  // every result says how sure it is unless told not to
  EXPECT_FALSE(config->refine_grid);
  EXPECT_TRUE(config->Validate().ok());

  // The defaults are written out in full, except the absent cell_size.
  const json j = ToJson(*config);
  EXPECT_FALSE(j.contains("cell_size"));
  EXPECT_EQ(j["gradient"], "adjoint");
  EXPECT_EQ(j["frames"], json::parse(R"({"first": 0, "last": -1})"));
  EXPECT_EQ(JobConfigFromJson(j).value(), *config);
}

TEST(JobConfig, FullConfigRoundTrips) {
  const Result<JobConfig> config = JobConfigFromJson(FullConfig());
  ASSERT_TRUE(config.ok()) << config.status().ToString();
  EXPECT_EQ(config->fit, (std::vector<std::string>{"youngs_modulus", "poisson_ratio",
                                                   "ground_plane", "gravity", "stiffness_field"}));
  ASSERT_EQ(config->initial.size(), 5u);
  const InitialValue& youngs = config->initial.at("youngs_modulus");
  ASSERT_TRUE(youngs.range.has_value());
  EXPECT_FALSE(youngs.value.has_value());
  EXPECT_EQ(youngs.range->min, 1e4);
  EXPECT_EQ(youngs.range->max, 1e6);
  EXPECT_EQ(config->initial.at("poisson_ratio").value, json(0.35));
  EXPECT_EQ(config->initial.at("gravity").value, json::parse("[0.0, 0.0, -9.7]"));
  EXPECT_EQ(config->initial.at("stiffness_field").value->at("kind"), "linear");
  EXPECT_EQ(config->fixed.at("density"), 950.0);
  EXPECT_EQ(config->solver.cells, 24);
  EXPECT_EQ(config->solver.cell_size_m, 0.004);
  EXPECT_EQ(config->solver.substeps, 3);
  EXPECT_EQ(config->solver.rho_infinity, 0.8);
  EXPECT_EQ(SimulationOptionsFor(config->solver).element,
            fem::ElementFormulation::kIncompatibleModes);
  // rho = 0.8: alpha_m = 1/3, alpha_f = 4/9 (Chung & Hulbert), gamma = 1/2 - alpha_m + alpha_f.
  const fem::SimulationOptions simulation = SimulationOptionsFor(config->solver);
  EXPECT_NEAR(simulation.generalized_alpha_m, 1.0 / 3.0, 1e-15);
  EXPECT_NEAR(simulation.generalized_alpha_f, 4.0 / 9.0, 1e-15);
  EXPECT_NEAR(simulation.newmark_gamma, 0.5 - 1.0 / 3.0 + 4.0 / 9.0, 1e-15);
  EXPECT_TRUE(simulation.Validate().ok());
  EXPECT_EQ(config->frames, (FrameRange{2, 40}));
  EXPECT_EQ(config->heldout_every, 5);
  EXPECT_EQ(config->solver.starts, 8);
  EXPECT_EQ(config->solver.threads, 3);
  EXPECT_EQ(config->solver.seed, 12345678901u);
  EXPECT_EQ(config->solver.max_iterations, 80);
  EXPECT_EQ(config->solver.function_tolerance, 1e-7);
  EXPECT_EQ(config->solver.gradient_tolerance, 1e-9);
  EXPECT_EQ(config->solver.parameter_tolerance, 1e-6);
  EXPECT_EQ(config->solver.gradient, GradientMethod::kFiniteDifference);
  EXPECT_EQ(config->solver.finite_difference_step, 1e-3);
  EXPECT_FALSE(config->solver.continuation);
  EXPECT_EQ(config->solver.refine_iterations, 12);
  EXPECT_EQ(config->solver.max_seconds, 90.5);
  EXPECT_EQ(config->solver.cost, (CostSettings{4, 1.5, cost::RestSdf::kSampled}));
  EXPECT_TRUE(config->diagnose);
  EXPECT_TRUE(config->refine_grid);
  EXPECT_TRUE(config->Validate().ok()) << config->Validate().ToString();

  // JSON object and text round trips reproduce every field.
  const json j = ToJson(*config);
  const Result<JobConfig> back = JobConfigFromJson(j);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(*back, *config);
  EXPECT_EQ(ToJson(*back), j);
  const Result<JobConfig> from_text = JobConfigFromString(j.dump(2), "roundtrip.json");
  ASSERT_TRUE(from_text.ok()) << from_text.status().ToString();
  EXPECT_EQ(*from_text, *config);
}

TEST(JobConfig, GroundAliasAndNormalNormalisation) {
  const Result<JobConfig> config = JobConfigFromJson(json::parse(R"({
    "fit": ["ground"],
    "initial": {"ground": {"normal": [0, 0.2, 1], "offset": 0.05}}
  })"));
  ASSERT_TRUE(config.ok()) << config.status().ToString();
  EXPECT_EQ(config->fit, std::vector<std::string>{"ground_plane"});
  ASSERT_EQ(config->initial.count("ground_plane"), 1u);
  EXPECT_EQ(config->initial.count("ground"), 0u);
  const json& plane = *config->initial.at("ground_plane").value;
  const Eigen::Vector3d normal(plane["normal"][0], plane["normal"][1], plane["normal"][2]);
  EXPECT_NEAR(normal.norm(), 1.0, 1e-15);
  EXPECT_NEAR(normal.y() / normal.z(), 0.2, 1e-15);  // same direction as typed
  EXPECT_EQ(normal.x(), 0.0);
  EXPECT_EQ(plane["offset"], 0.05);
  EXPECT_TRUE(config->IsFitted("ground_plane"));

  // "fixed" takes PhysicalParameters keys: "ground_plane" is stored as "ground", normalised too.
  const Result<JobConfig> fixed = JobConfigFromJson(
      json::parse(R"({"fixed": {"ground_plane": {"normal": [0, 0, 2], "offset": -0.1}}})"));
  ASSERT_TRUE(fixed.ok()) << fixed.status().ToString();
  EXPECT_FALSE(fixed->fixed.contains("ground_plane"));
  EXPECT_EQ(fixed->fixed["ground"], json::parse(R"({"normal": [0.0, 0.0, 1.0], "offset": -0.1})"));
  // "ground": null fixes free flight.
  const Result<JobConfig> free_flight =
      JobConfigFromJson(json::parse(R"({"fixed": {"ground": null}})"));
  ASSERT_TRUE(free_flight.ok()) << free_flight.status().ToString();
  EXPECT_TRUE(free_flight->fixed["ground"].is_null());
}

TEST(JobConfigRejects, UnknownKeys) {
  const Result<JobConfig> top = JobConfigFromJson(json::parse(R"({"fits": ["density"]})"));
  ASSERT_FALSE(top.ok());
  EXPECT_EQ(top.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(top.status().message(), "job config: unknown key \"fits\"");
  ExpectInvalid(json::parse(R"({"frames": {"first": 0, "lst": 3}})"), "frames: unknown key \"lst\"",
                "");
  ExpectInvalid(json::parse(R"({"cost": {"band": 3}})"), "cost: unknown key \"band\"", "");
  ExpectInvalid(
      json::parse(R"({"initial": {"youngs_modulus": {"min": 1, "max": 2, "mean": 1.5}}})"),
      "initial.youngs_modulus: unknown key \"mean\"", "");
  ExpectInvalid(json::parse("[1, 2]"), "job config = [1,2]: ", "must be a JSON object");
}

TEST(JobConfigRejects, FitNames) {
  const Result<JobConfig> unknown =
      JobConfigFromJson(json::parse(R"({"fit": ["youngs_modulus", "youngs_modulo"]})"));
  ExpectInvalid(unknown, "fit[1] = \"youngs_modulo\": ",
                "unknown parameter (known: youngs_modulus, poisson_ratio, density, ");
  ASSERT_FALSE(unknown.ok());
  EXPECT_NE(unknown.status().message().find("contact_damping"), std::string::npos);
  ExpectInvalid(json::parse(R"({"fit": ["poisson_ratio", "density", "poisson_ratio"]})"),
                "fit[2] = \"poisson_ratio\": ", "is listed twice (also fit[0])");
  ExpectInvalid(json::parse(R"({"fit": ["ground", "ground_plane"]})"),
                "fit[1] = \"ground_plane\": ", "is listed twice (also fit[0])");
  ExpectInvalid(json::parse(R"({"fit": "youngs_modulus"})"),
                "fit = \"youngs_modulus\": ", "must be an array of parameter names");
  ExpectInvalid(json::parse(R"({"fit": [3]})"), "fit[0] = 3: ", "must be a parameter name");
  ExpectInvalid(json::parse(R"({"fit": []})"), "fit = []: ", "must name at least one parameter");
}

TEST(JobConfigRejects, InitialValues) {
  // A start value for a parameter that is not fitted belongs in "fixed".
  ExpectInvalid(json::parse(R"({"initial": {"poisson_ratio": 0.3}})"),
                "initial.poisson_ratio = 0.3: ",
                "put the value of a parameter that is not fitted "
                "in \"fixed\"");
  ExpectInvalid(json::parse(R"({"initial": {"youngs_modulo": 1000}})"),
                "initial.youngs_modulo = 1000: ", "unknown parameter (known: ");
  // The same rules as PhysicalParameters::Validate.
  const Result<JobConfig> poisson = JobConfigFromJson(
      json::parse(R"({"fit": ["poisson_ratio"], "initial": {"poisson_ratio": 0.7}})"));
  ASSERT_FALSE(poisson.ok());
  EXPECT_EQ(poisson.status().message(), "initial.poisson_ratio = 0.7: must lie in (0, 0.5)");
  ExpectInvalid(json::parse(R"({"initial": {"youngs_modulus": -5}})"),
                "initial.youngs_modulus = -5.0: ", "must be positive and finite");
  ExpectInvalid(json::parse(R"({"initial": {"youngs_modulus": "stiff"}})"),
                "initial.youngs_modulus = \"stiff\": ", "must be a number or a range");
  ExpectInvalid(json::parse(R"({"fit": ["gravity"], "initial": {"gravity": [0, -9.81]}})"),
                "initial.gravity = [0,-9.81]: ", "must be an array of 3 finite numbers");
  ExpectInvalid(
      json::parse(
          R"({"fit": ["ground"], "initial": {"ground": {"normal": [0, 0, 0], "offset": 0}}})"),
      "initial.ground.normal = [0,0,0]: ", "must be non-zero");
  ExpectInvalid(json::parse(R"({"fit": ["ground"], "initial": {"ground": null}})"),
                "initial.ground = null: ", "must be {\"normal\"");
  ExpectInvalid(
      json::parse(R"({"fit": ["stiffness_field"],
                                "initial": {"stiffness_field": {"kind": "smooth"}}})"),
      "initial.stiffness_field.kind = \"smooth\": ", "must be uniform, regions or linear");
  // One entry per parameter, also through the alias.
  ExpectInvalid(json::parse(R"({"fit": ["ground_plane"], "initial": {
                  "ground": {"normal": [0, 0, 1], "offset": 0},
                  "ground_plane": {"normal": [0, 0, 1], "offset": 0}}})"),
                "initial.ground_plane = {", "duplicate of initial.ground");
}

TEST(JobConfigRejects, InitialRanges) {
  ExpectInvalid(json::parse(R"({"initial": {"youngs_modulus": {"min": 5000, "max": 1000}}})"),
                "initial.youngs_modulus.min = 5000: ", "must be below max (1000)");
  ExpectInvalid(json::parse(R"({"initial": {"youngs_modulus": {"min": 1000, "max": 1000}}})"),
                "initial.youngs_modulus.min = 1000: ", "must be below max (1000)");
  ExpectInvalid(json::parse(R"({"fit": ["poisson_ratio"],
                                "initial": {"poisson_ratio": {"min": 0.1, "max": 0.6}}})"),
                "initial.poisson_ratio.max = 0.6: ", "must lie in (0, 0.5)");
  ExpectInvalid(json::parse(R"({"initial": {"youngs_modulus": {"min": -1, "max": 1000}}})"),
                "initial.youngs_modulus.min = -1.0: ", "must be positive and finite");
  ExpectInvalid(json::parse(R"({"initial": {"youngs_modulus": {"min": 1000}}})"),
                "initial.youngs_modulus = {\"min\":1000}: ", "a range needs both");
  // Ranges are for scalars only.
  ExpectInvalid(json::parse(R"({"fit": ["gravity"],
                                "initial": {"gravity": {"min": [0, 0, -10], "max": [0, 0, -9]}}})"),
                "initial.gravity = {\"max\":[0,0,-9],\"min\":[0,0,-10]}: ",
                "range is only allowed for scalar parameters");
  ExpectInvalid(
      json::parse(R"({"fit": ["ground"], "initial": {"ground": {"min": 0, "max": 1}}})"),
      "initial.ground = {\"max\":1,\"min\":0}: ", "range is only allowed for scalar parameters");
}

TEST(JobConfigRejects, FixedValues) {
  const Result<JobConfig> poisson =
      JobConfigFromJson(json::parse(R"({"fixed": {"poisson_ratio": 0.7}})"));
  ASSERT_FALSE(poisson.ok());
  EXPECT_EQ(poisson.status().message(), "fixed.poisson_ratio = 0.7: must lie in (0, 0.5)");
  ExpectInvalid(json::parse(R"({"fixed": {"youngs_modulus": 5000}})"),
                "fixed.youngs_modulus = 5000: ",
                "youngs_modulus is also in \"fit\"; a parameter is either fitted or fixed");
  ExpectInvalid(json::parse(R"({"fit": ["ground_plane"],
                                "fixed": {"ground": {"normal": [0, 0, 1], "offset": 0}}})"),
                "fixed.ground = {", "ground_plane is also in \"fit\"");
  ExpectInvalid(json::parse(R"({"fixed": {"poisson": 0.3}})"),
                "fixed.poisson = 0.3: ", "unknown parameter (known: ");
  ExpectInvalid(json::parse(R"({"fixed": {"ground_plane": {"normal": [0, 0, 0], "offset": 0}}})"),
                "fixed.ground_plane.normal = [0,0,0]: ", "must be non-zero");
  ExpectInvalid(json::parse(R"({"fixed": {"density": "heavy"}})"),
                "fixed.density = \"heavy\": ", "must be a finite number");
  ExpectInvalid(json::parse(R"({"fixed": {"ground": {"normal": [0, 0, 1], "offset": 0},
                                          "ground_plane": null}})"),
                "fixed.ground_plane = null: ", "duplicate of fixed.ground");
  ExpectInvalid(json::parse(R"({"fixed": [1]})"), "fixed = [1]: ", "must be an object");
}

TEST(JobConfigRejects, NumericalSettings) {
  const Result<JobConfig> cells = JobConfigFromJson(json::parse(R"({"cells": 1})"));
  ASSERT_FALSE(cells.ok());
  EXPECT_EQ(cells.status().message(), "cells = 1: must be \"auto\" or an integer >= 2");
  ExpectInvalid(json::parse(R"({"cells": "ten"})"),
                "cells = \"ten\": ", "must be \"auto\" or an integer >= 2");
  ExpectInvalid(json::parse(R"({"cells": 2.5})"),
                "cells = 2.5: ", "must be \"auto\" or an integer >= 2");
  ExpectInvalid(json::parse(R"({"cells": 10000000000})"),
                "cells = 10000000000: ", "must be \"auto\" or an integer >= 2");
  ExpectInvalid(json::parse(R"({"cell_size": 0})"),
                "cell_size = 0: ", "must be a finite number > 0");
  ExpectInvalid(json::parse(R"({"substeps": 0})"),
                "substeps = 0: ", "must be \"auto\" or an integer >= 1");
  ExpectInvalid(json::parse(R"({"substeps": "fast"})"),
                "substeps = \"fast\": ", "must be \"auto\" or an integer >= 1");
  ExpectInvalid(json::parse(R"({"rho_infinity": 1.5})"),
                "rho_infinity = 1.5: ", "must be a number in [0, 1]");
  ExpectInvalid(json::parse(R"({"rho_infinity": "newmark"})"),
                "rho_infinity = \"newmark\": ", "must be a number in [0, 1]");
  ExpectInvalid(json::parse(R"({"element": "quadratic"})"),
                "element = \"quadratic\": ", "must be \"trilinear\" or \"incompatible_modes\"");
  ExpectInvalid(json::parse(R"({"starts": 0})"), "starts = 0: ", "must be an integer >= 1");
  ExpectInvalid(json::parse(R"({"threads": -1})"), "threads = -1: ", "must be an integer >= 0");
  ExpectInvalid(json::parse(R"({"seed": -3})"), "seed = -3: ", "must be an integer >= 0");
  ExpectInvalid(json::parse(R"({"seed": 1.5})"), "seed = 1.5: ", "must be an integer >= 0");
  ExpectInvalid(json::parse(R"({"max_iterations": 0})"),
                "max_iterations = 0: ", "must be an integer >= 1");
  ExpectInvalid(json::parse(R"({"function_tolerance": 0})"),
                "function_tolerance = 0: ", "must be a finite number > 0");
  ExpectInvalid(json::parse(R"({"gradient_tolerance": "tight"})"),
                "gradient_tolerance = \"tight\": ", "must be a finite number > 0");
  ExpectInvalid(json::parse(R"({"parameter_tolerance": -1e-8})"),
                "parameter_tolerance = -1e-08: ", "must be a finite number > 0");
  ExpectInvalid(json::parse(R"({"finite_difference_step": 0.0})"),
                "finite_difference_step = 0.0: ", "must be a finite number > 0");
  ExpectInvalid(json::parse(R"({"gradient": "magic"})"),
                "gradient = \"magic\": ", "must be \"adjoint\" or \"finite_difference\"");
  ExpectInvalid(json::parse(R"({"cost": {"band_cells": 0}})"),
                "cost.band_cells = 0: ", "must be an integer >= 1");
  ExpectInvalid(json::parse(R"({"cost": {"truncation_cells": -2}})"),
                "cost.truncation_cells = -2: ", "must be a finite number > 0");
  ExpectInvalid(json::parse(R"({"cost": 3})"), "cost = 3: ", "must be an object");
  ExpectInvalid(json::parse(R"({"cost": {"rest_sdf": "nodal"}})"), "cost.rest_sdf = \"nodal\": ",
                "must be \"surface_fitted\", \"exact\" or \"sampled\"");
  ExpectInvalid(json::parse(R"({"diagnose": "yes"})"),
                "diagnose = \"yes\": ", "must be true or false");
  ExpectInvalid(json::parse(R"({"uncertainty": 0})"), "uncertainty = 0: ", "must be true or false");
  ExpectInvalid(json::parse(R"({"refine_grid": "yes"})"),
                "refine_grid = \"yes\": ", "must be true or false");
  ExpectInvalid(json::parse(R"({"refine_grid": true, "uncertainty": false})"),
                "refine_grid = true: ", "needs \"uncertainty\": true");
  ExpectInvalid(json::parse(R"({"continuation": 1})"),
                "continuation = 1: ", "must be true or false");
  ExpectInvalid(json::parse(R"({"launch_from_flight": "no"})"),
                "launch_from_flight = \"no\": ", "must be true or false");
  ExpectInvalid(json::parse(R"({"predictable_frames_only": 1})"),
                "predictable_frames_only = 1: ", "must be true or false");
  ExpectInvalid(json::parse(R"({"refine_iterations": -1})"),
                "refine_iterations = -1: ", "must be an integer >= 0");
  ExpectInvalid(json::parse(R"({"refine_iterations": 2.5})"),
                "refine_iterations = 2.5: ", "must be an integer >= 0");
  ExpectInvalid(json::parse(R"({"max_seconds": -1})"),
                "max_seconds = -1: ", "must be a finite number >= 0");
  ExpectInvalid(json::parse(R"({"max_seconds": "1h"})"), "max_seconds = \"1h\": ", "");
}

TEST(JobConfigRejects, Frames) {
  ExpectInvalid(json::parse(R"({"frames": {"first": 5, "last": 3}})"), "frames.last = 3: ",
                "must be -1 (the capture's last frame) or an integer >= frames.first (5)");
  ExpectInvalid(json::parse(R"({"frames": {"last": -2}})"),
                "frames.last = -2: ", "must be -1 (the capture's last frame)");
  ExpectInvalid(json::parse(R"({"frames": {"first": -1}})"),
                "frames.first = -1: ", "must be an integer >= 0");
  ExpectInvalid(json::parse(R"({"frames": [0, 10]})"), "frames = [0,10]: ", "must be an object");
  ExpectInvalid(json::parse(R"({"heldout_every": 1})"),
                "heldout_every = 1: ", "1 would hold out every frame");
  ExpectInvalid(json::parse(R"({"heldout_every": -4})"),
                "heldout_every = -4: ", "must be 0 (none) or an integer >= 2");
  // last == first (one frame) and last = -1 after a late first are fine.
  EXPECT_TRUE(JobConfigFromJson(json::parse(R"({"frames": {"first": 7, "last": 7}})")).ok());
  EXPECT_TRUE(JobConfigFromJson(json::parse(R"({"frames": {"first": 7, "last": -1}})")).ok());
}

TEST(JobConfig, HeldOutFrames) {
  JobConfig config;
  EXPECT_FALSE(config.IsHeldOut(0));
  EXPECT_FALSE(config.IsHeldOut(5));
  config.frames.first = 2;
  config.heldout_every = 3;
  // Every third fitted frame, counted from frames.first: 4, 7, 10, ...
  for (int frame : {0, 1, 2, 3, 5, 6, 8}) EXPECT_FALSE(config.IsHeldOut(frame)) << frame;
  for (int frame : {4, 7, 10}) EXPECT_TRUE(config.IsHeldOut(frame)) << frame;
}

// Configs built in code are held to the same rules, plus canonical names.
TEST(JobConfig, ValidateCodeBuiltConfigs) {
  EXPECT_TRUE(JobConfig{}.Validate().ok());
  const auto expect_invalid = [](const JobConfig& config, const std::string& prefix,
                                 const std::string& reason) {
    const Status status = config.Validate();
    ASSERT_FALSE(status.ok()) << "accepted; expected " << prefix;
    EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
    EXPECT_EQ(status.message().rfind(prefix, 0), 0u) << status.message();
    EXPECT_NE(status.message().find(reason), std::string::npos) << status.message();
  };
  JobConfig config;
  config.solver.cells = 1;
  expect_invalid(config, "cells = 1: ", "must be \"auto\" or an integer >= 2");
  config = JobConfig{};
  config.frames = {5, 3};
  expect_invalid(config, "frames.last = 3: ", "frames.first (5)");
  config = JobConfig{};
  config.solver.gradient_tolerance = -1.0;
  expect_invalid(config, "gradient_tolerance = -1.0: ", "must be a finite number > 0");
  config = JobConfig{};
  config.solver.cell_size_m = -0.01;
  expect_invalid(config, "cell_size = -0.01: ", "must be a finite number > 0");
  config = JobConfig{};
  config.fit = {"ground"};
  expect_invalid(config, "fit[0] = \"ground\": ", "must be \"ground_plane\"");
  config = JobConfig{};
  config.initial["youngs_modulus"] = InitialValue{};
  expect_invalid(config, "initial.youngs_modulus: ", "exactly one of value and range");
  config = JobConfig{};
  config.initial["poisson_ratio"].value = 0.3;
  expect_invalid(config, "initial.poisson_ratio = 0.3: ", "is not in \"fit\"");
  config = JobConfig{};
  config.initial["youngs_modulus"].range = ScalarRange{2e5, 1e5};
  expect_invalid(config, "initial.youngs_modulus.min = 200000.0: ", "must be below max");
  config = JobConfig{};
  config.fixed["ground_plane"] = nullptr;
  expect_invalid(config, "fixed.ground_plane: ", "must be keyed \"ground\"");
  config = JobConfig{};
  config.fixed["density"] = -3.0;
  expect_invalid(config, "fixed.density = -3.0: ", "must be positive and finite");
}

TEST(JobConfig, ApplyToParametersSetsFixedAndInitialValues) {
  fem::PhysicalParameters base;
  base.youngs_modulus = 2e5;
  base.poisson_ratio = 0.25;
  base.density = 1100.0;
  base.mass_damping = 0.3;
  base.drag_linear = 0.05;
  base.ground = fem::GroundPlane{Eigen::Vector3d::UnitZ(), 0.0};
  const Result<JobConfig> config = JobConfigFromJson(json::parse(R"({
    "fit": ["youngs_modulus", "poisson_ratio", "initial_velocity"],
    "initial": {"youngs_modulus": 5e4, "poisson_ratio": {"min": 0.2, "max": 0.45},
                "initial_velocity": [0, 0, -1]},
    "fixed": {"density": 950, "gravity": [0, 0, -9.8],
              "ground": {"normal": [0, 0.2, 1], "offset": 0.01}}
  })"));
  ASSERT_TRUE(config.ok()) << config.status().ToString();
  const Result<fem::PhysicalParameters> applied = ApplyToParameters(*config, base);
  ASSERT_TRUE(applied.ok()) << applied.status().ToString();
  EXPECT_EQ(applied->youngs_modulus, 5e4);  // plain initial value
  EXPECT_EQ(applied->initial_velocity, Eigen::Vector3d(0, 0, -1));
  EXPECT_EQ(applied->poisson_ratio, 0.25);  // ranged: stays at base
  EXPECT_EQ(applied->density, 950.0);       // fixed
  EXPECT_EQ(applied->gravity, Eigen::Vector3d(0, 0, -9.8));
  ASSERT_TRUE(applied->ground.has_value());
  EXPECT_NEAR(applied->ground->normal.norm(), 1.0, 1e-15);
  EXPECT_NEAR(applied->ground->normal.y(), 0.2 / std::sqrt(1.04), 1e-15);
  EXPECT_EQ(applied->ground->offset, 0.01);

  // Everything else is untouched.
  json expected = fem::ToJson(base);
  json actual = fem::ToJson(*applied);
  for (const char* changed :
       {"youngs_modulus", "initial_velocity", "density", "gravity", "ground"}) {
    expected.erase(changed);
    actual.erase(changed);
  }
  EXPECT_EQ(actual, expected);
  EXPECT_EQ(applied->mass_damping, 0.3);
  EXPECT_EQ(applied->drag_linear, 0.05);

  // Fixing "ground": null selects free flight over a base with a floor.
  const Result<JobConfig> free_flight =
      JobConfigFromJson(json::parse(R"({"fixed": {"ground": null}})"));
  ASSERT_TRUE(free_flight.ok());
  const Result<fem::PhysicalParameters> flying = ApplyToParameters(*free_flight, base);
  ASSERT_TRUE(flying.ok()) << flying.status().ToString();
  EXPECT_FALSE(flying->ground.has_value());
}

TEST(JobConfig, ApplyToParametersNeedsAStartPlane) {
  const Result<JobConfig> config = JobConfigFromJson(json::parse(R"({"fit": ["ground"]})"));
  ASSERT_TRUE(config.ok());
  fem::PhysicalParameters no_floor;  // free flight by default
  const Result<fem::PhysicalParameters> missing = ApplyToParameters(*config, no_floor);
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(missing.status().message().find("ground_plane is fitted"), std::string::npos);
  fem::PhysicalParameters with_floor;
  with_floor.ground = fem::GroundPlane{};
  EXPECT_TRUE(ApplyToParameters(*config, with_floor).ok());

  // An invalid base is named as such.
  fem::PhysicalParameters bad_base;
  bad_base.density = -1.0;
  const Result<fem::PhysicalParameters> bad = ApplyToParameters(JobConfig{}, bad_base);
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().message(), "base parameters: density = -1.0: must be positive and finite");
}

TEST(ReadJobConfig, ReadsAFile) {
  const TempFile file("job.json");
  file.Write(R"({"fit": ["youngs_modulus", "density"], "cells": 12})");
  const Result<JobConfig> config = ReadJobConfig(file.path());
  ASSERT_TRUE(config.ok()) << config.status().ToString();
  EXPECT_EQ(config->fit, (std::vector<std::string>{"youngs_modulus", "density"}));
  EXPECT_EQ(config->solver.cells, 12);
}

TEST(ReadJobConfig, MissingFileIsNotFound) {
  const TempFile file("absent.json");
  const Result<JobConfig> config = ReadJobConfig(file.path());
  ASSERT_FALSE(config.ok());
  EXPECT_EQ(config.status().code(), StatusCode::kNotFound);
  EXPECT_EQ(config.status().message(), file.path().string() + ": job config not found");
}

TEST(ReadJobConfig, SyntaxErrorNamesFileAndLine) {
  const TempFile file("broken.json");
  file.Write("{\n  \"cells\": 12,\n  \"substeps\": ,\n}\n");
  const Result<JobConfig> config = ReadJobConfig(file.path());
  ASSERT_FALSE(config.ok());
  EXPECT_EQ(config.status().code(), StatusCode::kInvalidArgument);
  const std::string& message = config.status().message();
  EXPECT_EQ(message.rfind(file.path().string() + ": invalid JSON: parse error at line 3", 0), 0u)
      << message;
  EXPECT_EQ(message.find("[json.exception"), std::string::npos) << message;
}

TEST(ReadJobConfig, InvalidContentNamesFileFieldAndValue) {
  const TempFile file("invalid.json");
  file.Write(R"({"substeps": 0})");
  const Result<JobConfig> config = ReadJobConfig(file.path());
  ASSERT_FALSE(config.ok());
  EXPECT_EQ(config.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(config.status().message(),
            file.path().string() + ": substeps = 0: must be \"auto\" or an integer >= 1");
}

TEST(JobConfigFromString, NamesTheSource) {
  const Result<JobConfig> config = JobConfigFromString(R"({"gradient": "magic"})", "request");
  ASSERT_FALSE(config.ok());
  EXPECT_EQ(config.status().message(),
            "request: gradient = \"magic\": must be \"adjoint\" or \"finite_difference\"");
  const Result<JobConfig> truncated = JobConfigFromString("{\"cells\": 4", "request");
  ASSERT_FALSE(truncated.ok());
  EXPECT_EQ(truncated.status().message().rfind("request: invalid JSON: parse error at line 1", 0),
            0u)
      << truncated.status().message();
  // Numbers beyond double range are JSON errors too, not exceptions.
  const Result<JobConfig> overflow = JobConfigFromString(R"({"cell_size": 1e400})", "request");
  ASSERT_FALSE(overflow.ok());
  EXPECT_EQ(overflow.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(overflow.status().message().rfind("request: invalid JSON: number overflow", 0), 0u)
      << overflow.status().message();
}

TEST(JobConfig, SubstepsAutoIsTheDefaultAndRoundTrips) {
  const Result<JobConfig> automatic = JobConfigFromJson(json::parse(R"({"substeps": "auto"})"));
  ASSERT_TRUE(automatic.ok()) << automatic.status().ToString();
  EXPECT_EQ(automatic->solver.substeps, kAutoSubsteps);
  EXPECT_EQ(ToJson(*automatic)["substeps"], "auto");
  EXPECT_EQ(ToJson(JobConfig{})["substeps"], "auto");
  const Result<JobConfig> explicit_steps = JobConfigFromJson(json::parse(R"({"substeps": 5})"));
  ASSERT_TRUE(explicit_steps.ok());
  EXPECT_EQ(ToJson(*explicit_steps)["substeps"], 5);
}

TEST(JobConfig, CellsAutoIsTheDefaultAndRoundTrips) {
  const Result<JobConfig> automatic = JobConfigFromJson(json::parse(R"({"cells": "auto"})"));
  ASSERT_TRUE(automatic.ok()) << automatic.status().ToString();
  EXPECT_EQ(automatic->solver.cells, kAutoCells);
  EXPECT_EQ(ToJson(*automatic)["cells"], "auto");
  EXPECT_EQ(ToJson(JobConfig{})["cells"], "auto");
  EXPECT_TRUE(JobConfig{}.Validate().ok());
  const Result<JobConfig> explicit_cells = JobConfigFromJson(json::parse(R"({"cells": 12})"));
  ASSERT_TRUE(explicit_cells.ok());
  EXPECT_EQ(ToJson(*explicit_cells)["cells"], 12);
}

}  // namespace
}  // namespace softid::inverse
