#include "core/inverse/parameter_space.h"

#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

namespace softid::inverse {
namespace {

constexpr double kLength = 0.2;  // L [m]

// Every registry parameter away from its default, with a ground plane and a stiffness field of
// `kind` so that both can be fitted.
fem::PhysicalParameters Sample(fem::StiffnessField::Kind kind) {
  fem::PhysicalParameters p;
  p.youngs_modulus = 4.2e4;
  p.poisson_ratio = 0.41;
  p.density = 350.0;
  p.mass_damping = 0.3;
  p.stiffness_damping = 0.004;
  p.gravity = Eigen::Vector3d(0.1, -0.2, -9.7);
  p.initial_velocity = Eigen::Vector3d(0.5, 0.0, -1.0);
  p.initial_angular_velocity = Eigen::Vector3d(1.0, -2.0, 0.25);
  p.initial_pose.rotation = Eigen::Vector3d(0.02, -0.05, 0.01);
  p.initial_pose.translation = Eigen::Vector3d(0.003, 0.001, -0.002);
  p.ground = fem::GroundPlane{Eigen::Vector3d(0.1, -0.2, 1.0).normalized(), 0.015};
  p.friction_coefficient = 0.45;
  p.drag_linear = 0.2;
  p.drag_quadratic = 0.6;
  p.contact_stiffness = 3e6;
  p.contact_damping = 2e-3;
  p.stiffness_field.kind = kind;
  if (kind == fem::StiffnessField::Kind::kRegions) {
    p.stiffness_field.regions = {
        {Eigen::AlignedBox3d(Eigen::Vector3d(-1, -1, -1), Eigen::Vector3d(0, 1, 1)), 2.5},
        {Eigen::AlignedBox3d(Eigen::Vector3d(0, -1, -1), Eigen::Vector3d(1, 1, 1)), 0.7}};
  } else {
    p.stiffness_field.origin = Eigen::Vector3d(0.0, 0.0, 0.05);
    p.stiffness_field.log_gradient = Eigen::Vector3d(3.0, -1.0, 0.5);
  }
  return p;
}

std::vector<std::string> AllNames() {
  std::vector<std::string> names;
  for (const fem::ParameterInfo& parameter : fem::ParameterRegistry())
    names.emplace_back(parameter.name);
  return names;
}

// A cost linear in every parameter, c = w . p, and its gradient d c / d p = w.
struct LinearCost {
  fem::ParameterGradient weights;

  LinearCost() {
    double w = 0.5;
    for (const fem::ParameterInfo& parameter : fem::ParameterRegistry()) {
      w = -1.3 * w + 0.2;  // distinct weights of both signs
      switch (parameter.shape) {
        case fem::ParameterShape::kScalar: weights.*parameter.scalar_gradient = w; break;
        case fem::ParameterShape::kVector3:
          weights.*parameter.vector_gradient = Eigen::Vector3d(w, 0.5 - w, 2.0 * w);
          break;
        case fem::ParameterShape::kPlane:
          weights.ground_normal = Eigen::Vector3d(w, -0.4, 0.9);
          weights.ground_offset = 30.0 * w;
          break;
        case fem::ParameterShape::kStiffnessField: weights.stiffness_field = {w, -w, 0.3}; break;
        case fem::ParameterShape::kPose:
          weights.initial_pose_rotation = Eigen::Vector3d(w, -0.7, 0.2);
          weights.initial_pose_translation = Eigen::Vector3d(0.3, w, -2.0 * w);
          break;
      }
    }
  }

  // The share of one parameter in c.
  double operator()(const fem::ParameterInfo& parameter, const fem::PhysicalParameters& p) const {
    switch (parameter.shape) {
      case fem::ParameterShape::kScalar:
        return weights.*parameter.scalar_gradient * p.*parameter.scalar;
      case fem::ParameterShape::kVector3:
        return (weights.*parameter.vector_gradient).dot(p.*parameter.vector);
      case fem::ParameterShape::kPlane:
        return weights.ground_normal.dot(p.ground->normal) +
               weights.ground_offset * p.ground->offset;
      case fem::ParameterShape::kStiffnessField: {
        const fem::StiffnessField& f = p.stiffness_field;
        double c = 0.0;
        for (size_t k = 0; k < 3; ++k) {
          const double coefficient = f.kind == fem::StiffnessField::Kind::kRegions
                                         ? (k < f.regions.size() ? f.regions[k].scale : 0.0)
                                         : f.log_gradient[k];
          c += weights.stiffness_field[k] * coefficient;
        }
        return c;
      }
      case fem::ParameterShape::kPose:
        return weights.initial_pose_rotation.dot(p.initial_pose.rotation) +
               weights.initial_pose_translation.dot(p.initial_pose.translation);
    }
    return 0.0;
  }
};

// The fitted parameter a variable belongs to: "gravity[2]" -> "gravity".
const fem::ParameterInfo& ParameterOf(const std::string& variable) {
  return *fem::FindParameter(variable.substr(0, variable.find_first_of("[.")));
}

class ParameterSpaceTest : public ::testing::TestWithParam<fem::StiffnessField::Kind> {};

// x = ToVariables(p) encodes every parameter: ToParameters(x) gives p back, whatever the base.
TEST_P(ParameterSpaceTest, EveryParameterRoundTrips) {
  const fem::PhysicalParameters p = Sample(GetParam());
  const Result<ParameterSpace> space = ParameterSpace::Create(AllNames(), p, kLength);
  ASSERT_TRUE(space.ok()) << space.status().ToString();
  const std::vector<double> x = space->ToVariables(p);
  ASSERT_EQ(static_cast<int>(x.size()), space->NumVariables());
  // The base keeps the plane and the field's shape (not fitted: the boxes, the origin).
  fem::PhysicalParameters base;
  base.ground = fem::GroundPlane{};
  base.stiffness_field = p.stiffness_field;
  for (auto& region : base.stiffness_field.regions) region.scale = 1.0;
  base.stiffness_field.log_gradient.setZero();
  const fem::PhysicalParameters back = space->ToParameters(x.data(), base);
  for (const fem::ParameterInfo& parameter : fem::ParameterRegistry()) {
    SCOPED_TRACE(std::string(parameter.name));
    const nlohmann::json expected = fem::ToJson(p, parameter);
    const nlohmann::json actual = fem::ToJson(back, parameter);
    const nlohmann::json flat_expected = expected.flatten(), flat_actual = actual.flatten();
    ASSERT_EQ(flat_actual.size(), flat_expected.size());
    for (const auto& [path, value] : flat_expected.items()) {
      if (value.is_number()) {
        EXPECT_NEAR(flat_actual[path].get<double>(), value.get<double>(),
                    1e-12 * std::max(1.0, std::abs(value.get<double>())))
            << path;
      } else {
        EXPECT_EQ(flat_actual[path], value) << path;
      }
    }
  }
}

// ChainGradient is the derivative of the cost through ToParameters, for every transform.
TEST_P(ParameterSpaceTest, ChainGradientMatchesFiniteDifferences) {
  const fem::PhysicalParameters p = Sample(GetParam());
  const Result<ParameterSpace> space = ParameterSpace::Create(AllNames(), p, kLength);
  ASSERT_TRUE(space.ok()) << space.status().ToString();
  const LinearCost cost;
  std::vector<double> x = space->ToVariables(p);
  std::vector<double> gradient(x.size(), 0.0);
  space->ChainGradient(cost.weights, x.data(), gradient.data());
  constexpr double kStep = 1e-6;
  for (size_t i = 0; i < x.size(); ++i) {
    // Each variable moves one parameter only; its share alone keeps the rounding error small.
    const fem::ParameterInfo& parameter = ParameterOf(space->variable_names()[i]);
    const double xi = x[i];
    x[i] = xi + kStep;
    const double up = cost(parameter, space->ToParameters(x.data(), p));
    x[i] = xi - kStep;
    const double down = cost(parameter, space->ToParameters(x.data(), p));
    x[i] = xi;
    const double finite_difference = (up - down) / (2.0 * kStep);
    EXPECT_NEAR(gradient[i], finite_difference, 1e-6 * std::max(1.0, std::abs(finite_difference)))
        << space->variable_names()[i];
  }
}

INSTANTIATE_TEST_SUITE_P(StiffnessFieldKinds, ParameterSpaceTest,
                         ::testing::Values(fem::StiffnessField::Kind::kRegions,
                                           fem::StiffnessField::Kind::kLinear));

// Values at the edge of a transform's range start just inside it; a zero contact stiffness
// starts at the default it selects.
TEST(ParameterSpace, StartsInsideTheRange) {
  fem::PhysicalParameters p;
  p.ground = fem::GroundPlane{};
  const Result<ParameterSpace> space = ParameterSpace::Create(
      {"mass_damping", "friction_coefficient", "contact_stiffness"}, p, kLength);
  ASSERT_TRUE(space.ok()) << space.status().ToString();
  const std::vector<double> x = space->ToVariables(p);
  const fem::PhysicalParameters start = space->ToParameters(x.data(), p);
  EXPECT_NEAR(start.mass_damping, fem::FindParameter("mass_damping")->minimum_start, 1e-15);
  EXPECT_NEAR(start.friction_coefficient, fem::FindParameter("friction_coefficient")->minimum_start,
              1e-15);
  EXPECT_NEAR(start.contact_stiffness, fem::DefaultContactStiffness(p.youngs_modulus, kLength),
              1e-6);
}

// Only registry names, each once: an unknown name is an error, not a log-scaled guess.
TEST(ParameterSpace, RefusesUnknownAndRepeatedNames) {
  fem::PhysicalParameters p;
  p.ground = fem::GroundPlane{};
  const Result<ParameterSpace> unknown =
      ParameterSpace::Create({"youngs_modulus", "youngs_modulo"}, p, kLength);
  ASSERT_FALSE(unknown.ok());
  EXPECT_EQ(unknown.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(unknown.status().message(), "fit[1] = \"youngs_modulo\": is not a fittable parameter");
  // The alias is resolved by the job config, not here.
  EXPECT_FALSE(ParameterSpace::Create({"ground"}, p, kLength).ok());
  const Result<ParameterSpace> twice = ParameterSpace::Create({"density", "density"}, p, kLength);
  ASSERT_FALSE(twice.ok());
  EXPECT_EQ(twice.status().message(), "fit[1] = \"density\": is listed twice");
}

TEST(ParameterSpace, VariableNames) {
  const fem::PhysicalParameters p = Sample(fem::StiffnessField::Kind::kRegions);
  const Result<ParameterSpace> space = ParameterSpace::Create(
      {"poisson_ratio", "gravity", "ground_plane", "stiffness_field"}, p, kLength);
  ASSERT_TRUE(space.ok()) << space.status().ToString();
  EXPECT_EQ(space->variable_names(),
            (std::vector<std::string>{"poisson_ratio", "gravity[0]", "gravity[1]", "gravity[2]",
                                      "ground_plane.tilt[0]", "ground_plane.tilt[1]",
                                      "ground_plane.offset", "stiffness_field[0]",
                                      "stiffness_field[1]"}));
}

}  // namespace
}  // namespace softid::inverse
