#include "core/fem/physical_parameters.h"

#include <gtest/gtest.h>

namespace softid::fem {
namespace {

// Every public parameter survives a JSON round trip under its public name.
TEST(PhysicalParameters, JsonRoundTrip) {
  PhysicalParameters p;
  p.youngs_modulus = 3450.0;
  p.poisson_ratio = 0.41;
  p.density = 120.0;
  p.mass_damping = 0.24;
  p.stiffness_damping = 0.027;
  p.gravity = Eigen::Vector3d(0.1, 0.2, -9.7);
  p.initial_velocity = Eigen::Vector3d(1, 2, 3);
  p.initial_angular_velocity = Eigen::Vector3d(0.5, 0, -1);
  p.ground = GroundPlane{Eigen::Vector3d(0, 0.6, 0.8), 0.127};
  p.friction_coefficient = 0.3;
  p.drag_linear = 0.1;
  p.drag_quadratic = 0.6;
  p.stiffness_field.kind = StiffnessField::Kind::kRegions;
  p.stiffness_field.regions.push_back(
      {Eigen::AlignedBox3d(Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(1, 1, 1)), 2.0});
  const nlohmann::json j = ToJson(p);
  EXPECT_EQ(j["ground"]["offset"], 0.127);
  const Result<PhysicalParameters> back = PhysicalParametersFromJson(j);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(ToJson(*back), j);
}

// Unknown names and impossible values are rejected with the field and value named.
TEST(PhysicalParameters, RejectsUnknownAndInvalid) {
  const auto unknown = PhysicalParametersFromJson({{"youngs_modulos", 1000}});
  ASSERT_FALSE(unknown.ok());
  EXPECT_EQ(unknown.status().message(), "youngs_modulos = 1000: is not a known parameter name");
  const auto negative = PhysicalParametersFromJson({{"density", -5}});
  ASSERT_FALSE(negative.ok());
  EXPECT_EQ(negative.status().message(), "density = -5.0: must be positive and finite");
  const auto bad_vector = PhysicalParametersFromJson({{"gravity", {0, -9.81}}});
  ASSERT_FALSE(bad_vector.ok());
  EXPECT_NE(bad_vector.status().message().find("gravity = [0,-9.81]"), std::string::npos);
  const auto bad_plane =
      PhysicalParametersFromJson({{"ground", {{"normal", {0, 0, 0}}, {"offset", 0}}}});
  ASSERT_FALSE(bad_plane.ok());
  EXPECT_NE(bad_plane.status().message().find("ground.normal"), std::string::npos);
}

// The stiffness field scales E per region (last match wins) or log-linearly.
TEST(StiffnessField, Scale) {
  StiffnessField regions;
  regions.kind = StiffnessField::Kind::kRegions;
  regions.regions.push_back(
      {Eigen::AlignedBox3d(Eigen::Vector3d(-1, -1, -1), Eigen::Vector3d(0, 1, 1)), 4.0});
  EXPECT_EQ(regions.Scale(Eigen::Vector3d(-0.5, 0, 0)), 4.0);
  EXPECT_EQ(regions.Scale(Eigen::Vector3d(0.5, 0, 0)), 1.0);
  StiffnessField linear;
  linear.kind = StiffnessField::Kind::kLinear;
  linear.log_gradient = Eigen::Vector3d(std::log(2.0), 0, 0);
  EXPECT_NEAR(linear.Scale(Eigen::Vector3d(1, 5, 5)), 2.0, 1e-12);
}

}  // namespace
}  // namespace softid::fem
