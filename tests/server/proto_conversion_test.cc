// The API's typed forms: result.json's parameters as numbers with their 1-sigma and their
// discretisation error, in the order result.json writes them (an undetermined one, null, is +inf);
// progress events with their parameters' units.
#include "server/proto_conversion.h"

#include <gtest/gtest.h>

#include <cmath>

namespace softid::server {
namespace {

TEST(ProtoConversion, FittedParametersAreTyped) {
  const nlohmann::json result = nlohmann::json::parse(R"({
    "parameters": {
      "youngs_modulus": {"value": 38900.0, "unit": "Pa", "initial": 1e4,
                         "standard_uncertainty": 400.0, "relative_uncertainty": 0.0103,
                         "discretisation_error": {"grid": 600.0, "time_step": 100.0,
                                                  "total": 700.0}},
      "ground_plane": {"value": {"normal": [0, 0, 1], "offset": -0.01}, "unit": "m",
                       "initial": {"normal": [0, 0, 1], "offset": 0},
                       "standard_uncertainty": {"normal": [0.01, 0.02, 0], "offset": null},
                       "discretisation_error": {"total": {"normal": [0, 0, 0], "offset": null}}},
      "gravity": {"value": [0, 0, -9.8], "unit": "m/s^2", "initial": [0, 0, -9.81]},
      "broken": 3
    }})");
  v1::Result out;
  FittedParametersToProto(result, &out);
  ASSERT_EQ(out.parameters_size(), 3);  // "broken" is not a parameter entry
  // nlohmann's objects iterate in key order.
  const v1::FittedParameter& gravity = out.parameters(0);
  EXPECT_EQ(gravity.name(), "gravity");
  ASSERT_EQ(gravity.value_size(), 3);
  EXPECT_DOUBLE_EQ(gravity.value(2), -9.8);
  EXPECT_EQ(gravity.standard_uncertainty_size(), 0);  // no analysis
  EXPECT_EQ(gravity.discretisation_error_size(), 0);
  const v1::FittedParameter& plane = out.parameters(1);
  EXPECT_EQ(plane.name(), "ground_plane");
  ASSERT_EQ(plane.value_size(), 4);
  EXPECT_DOUBLE_EQ(plane.value(3), -0.01);
  ASSERT_EQ(plane.standard_uncertainty_size(), 4);
  EXPECT_DOUBLE_EQ(plane.standard_uncertainty(1), 0.02);
  EXPECT_TRUE(std::isinf(plane.standard_uncertainty(3)));
  ASSERT_EQ(plane.discretisation_error_size(), 4);
  EXPECT_TRUE(std::isinf(plane.discretisation_error(3)));
  const v1::FittedParameter& youngs = out.parameters(2);
  EXPECT_EQ(youngs.unit(), "Pa");
  ASSERT_EQ(youngs.value_size(), 1);
  EXPECT_DOUBLE_EQ(youngs.value(0), 38900.0);
  EXPECT_DOUBLE_EQ(youngs.standard_uncertainty(0), 400.0);
  EXPECT_DOUBLE_EQ(youngs.initial(0), 1e4);
  ASSERT_EQ(youngs.discretisation_error_size(), 1);
  EXPECT_DOUBLE_EQ(youngs.discretisation_error(0), 700.0);  // the total

  v1::Result none;
  FittedParametersToProto(nlohmann::json::parse(R"({"cost": 1})"), &none);
  EXPECT_EQ(none.parameters_size(), 0);
}

}  // namespace
}  // namespace softid::server

namespace softid::server {
namespace {

// An iteration event names each parameter's unit from the registry; names it does not know get
// none (the values stand alone).
TEST(ProtoConversion, IterationEventsCarryTheParametersUnits) {
  store::ProgressEvent event;
  event.kind = store::ProgressKind::kIteration;
  event.parameters = {{"youngs_modulus", 4e4}, {"initial_velocity", {0, 0, 1}}, {"made_up", 1}};
  store::Job job;
  v1::JobEvent out;
  ToProto(event, job, &out);
  EXPECT_EQ(out.parameter_units().at("youngs_modulus"), "Pa");
  EXPECT_EQ(out.parameter_units().at("initial_velocity"), "m/s");
  EXPECT_EQ(out.parameter_units().count("made_up"), 0u);
}

}  // namespace
}  // namespace softid::server
