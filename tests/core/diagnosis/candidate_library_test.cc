#include "core/diagnosis/candidate_library.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "core/fem/parameter_registry.h"

namespace softid::diagnosis {
namespace {

fem::PhysicalParameters NullParameters() {
  fem::PhysicalParameters p;
  p.youngs_modulus = 3000.0;
  return p;
}

// A split refit's E is one half's modulus: the null model restarts from the geometric mean over
// the volume, not from that half.
TEST(NullModelStart, StiffnessSplitStartsAtTheVolumeMean) {
  const Eigen::AlignedBox3d body(Eigen::Vector3d(-0.1, -0.05, 0.0),
                                 Eigen::Vector3d(0.1, 0.05, 0.1));
  fem::PhysicalParameters refit = NullParameters();
  refit.youngs_modulus = 8000.0;
  refit.stiffness_field = HalvesField(body, /*axis=*/0, /*ratio=*/0.25);
  const fem::PhysicalParameters start =
      NullModelStart(Extension::kHeterogeneousStiffness, NullParameters(), refit, body);
  EXPECT_EQ(start.stiffness_field.kind, fem::StiffnessField::Kind::kUniform);
  EXPECT_NEAR(start.youngs_modulus, 8000.0 * std::sqrt(0.25), 1e-9);

  // A region over a quarter of the body (split at x = -0.05): E r^(1/4).
  refit.stiffness_field.regions[0].box.max().x() = -0.05;
  EXPECT_NEAR(NullModelStart(Extension::kHeterogeneousStiffness, NullParameters(), refit, body)
                  .youngs_modulus,
              8000.0 * std::pow(0.25, 0.25), 1e-9);
}

// Every other extension goes back to its null and keeps the refit's base parameters.
TEST(NullModelStart, OtherExtensionsKeepTheRefitsBaseParameters) {
  const Eigen::AlignedBox3d body(Eigen::Vector3d::Zero(), Eigen::Vector3d::Constant(0.1));
  fem::PhysicalParameters refit = NullParameters();
  refit.youngs_modulus = 5000.0;
  refit.stiffness_damping = 0.004;
  refit.friction_coefficient = 0.4;
  refit.contact_stiffness = 2e6;
  refit.contact_damping = 1e-3;
  const fem::PhysicalParameters friction =
      NullModelStart(Extension::kFriction, NullParameters(), refit, body);
  EXPECT_EQ(friction.friction_coefficient, 0.0);
  EXPECT_EQ(friction.youngs_modulus, 5000.0);
  EXPECT_EQ(friction.stiffness_damping, 0.004);
  const fem::PhysicalParameters contact =
      NullModelStart(Extension::kContact, NullParameters(), refit, body);
  EXPECT_EQ(contact.contact_stiffness, NullParameters().contact_stiffness);
  EXPECT_EQ(contact.contact_damping, NullParameters().contact_damping);
  EXPECT_EQ(contact.youngs_modulus, 5000.0);
}

// A model without the stiffness split gets the split at ratio 1 along the refit's axis (a field a
// joint refit can free); other extensions' nulls are the model's own values.
TEST(WithExtensionAtNull, AStiffnessSplitAtRatioOneAlongTheRefitsAxis) {
  const Eigen::AlignedBox3d body(Eigen::Vector3d::Zero(), Eigen::Vector3d(0.1, 0.2, 0.3));
  fem::PhysicalParameters refit = NullParameters();
  refit.stiffness_field = HalvesField(body, 2, 4.0);
  fem::PhysicalParameters model = NullParameters();
  model.contact_stiffness = 2e6;
  const fem::PhysicalParameters out =
      WithExtensionAtNull(Extension::kHeterogeneousStiffness, refit, model, body);
  ASSERT_EQ(out.stiffness_field.regions.size(), 1u);
  EXPECT_EQ(out.stiffness_field.regions[0].scale, 1.0);
  EXPECT_EQ(out.stiffness_field.regions[0].box.min(), refit.stiffness_field.regions[0].box.min());
  EXPECT_EQ(out.stiffness_field.regions[0].box.max(), refit.stiffness_field.regions[0].box.max());
  EXPECT_EQ(out.contact_stiffness, 2e6);
  refit.friction_coefficient = 0.4;
  EXPECT_EQ(WithExtensionAtNull(Extension::kFriction, refit, model, body).friction_coefficient,
            model.friction_coefficient);
}

// The library names the parameters it frees under their registry names, and an extension's copy
// takes exactly those from the refit.
TEST(CandidateLibrary, FreesRegistryParameters) {
  fem::PhysicalParameters from = NullParameters();
  from.friction_coefficient = 0.4;
  from.drag_quadratic = 0.6;
  from.contact_stiffness = 2e6;
  from.contact_damping = 1e-3;
  from.initial_angular_velocity = Eigen::Vector3d(1, 2, 3);
  from.stiffness_field = HalvesField(
      Eigen::AlignedBox3d(Eigen::Vector3d::Zero(), Eigen::Vector3d::Constant(0.1)), 0, 2.0);
  for (const Candidate& candidate : CandidateLibrary()) {
    SCOPED_TRACE(ToString(candidate.extension));
    const fem::PhysicalParameters copy = CopyExtension(candidate.extension, from, {});
    const nlohmann::json copied = fem::ToJson(copy),
                         defaults = fem::ToJson(fem::PhysicalParameters{});
    for (const fem::ParameterInfo& parameter : fem::ParameterRegistry()) {
      const bool freed = std::find(candidate.parameters.begin(), candidate.parameters.end(),
                                   parameter.name) != candidate.parameters.end();
      const std::string key(parameter.json_key);
      EXPECT_EQ(copied[key], freed ? fem::ToJson(from, parameter) : defaults[key]) << key;
    }
    for (const std::string& name : candidate.parameters) {
      const fem::ParameterInfo* parameter = fem::FindParameter(name);
      ASSERT_NE(parameter, nullptr) << name;
      EXPECT_EQ(parameter->name, name);
    }
  }
}

}  // namespace
}  // namespace softid::diagnosis
