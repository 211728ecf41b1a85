#include "core/scenes/diagnosis_scenes.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "core/scenes/scene_runner.h"

namespace softid::scenes {
namespace {

// Every scene builds as a control with valid parameters and none of the hidden physics.
TEST(DiagnosisScenes, ControlsCarryNoEffect) {
  for (const std::string& name : DiagnosisSceneNames()) {
    Result<ConcealedScene> scene = MakeDiagnosisScene(name, ConcealedEffect::kNone, 0.0);
    ASSERT_TRUE(scene.ok()) << name << ": " << scene.status().ToString();
    const fem::PhysicalParameters& p = scene->scene.parameters;
    EXPECT_TRUE(p.Validate().ok()) << name;
    EXPECT_EQ(p.friction_coefficient, 0.0) << name;
    EXPECT_EQ(p.drag_quadratic, 0.0) << name;
    EXPECT_EQ(p.stiffness_field.kind, fem::StiffnessField::Kind::kUniform) << name;
    EXPECT_EQ(p.initial_angular_velocity.norm(), 0.0) << name;
    ASSERT_TRUE(p.ground.has_value()) << name;
  }
}

// The halves differ by the ratio, split at the middle of the longest (x) side, with the mean
// log-modulus unchanged.
TEST(DiagnosisScenes, HalvesCarryTheStiffnessRatio) {
  Result<ConcealedScene> control = MakeDiagnosisScene("halves-drop", ConcealedEffect::kNone, 0.0);
  Result<ConcealedScene> scene =
      MakeDiagnosisScene("halves-drop", ConcealedEffect::kHeterogeneousStiffness, 4.0);
  ASSERT_TRUE(scene.ok() && control.ok());
  const fem::PhysicalParameters& p = scene->scene.parameters;
  const Eigen::AlignedBox3d bounds = scene->scene.mesh.Bounds();
  const Eigen::Vector3d lower(bounds.min().x() + 0.01, 0.0, bounds.center().z());
  const Eigen::Vector3d upper(bounds.max().x() - 0.01, 0.0, bounds.center().z());
  EXPECT_NEAR(p.stiffness_field.Scale(lower) / p.stiffness_field.Scale(upper), 4.0, 1e-12);
  EXPECT_NEAR(p.youngs_modulus * std::sqrt(4.0), control->scene.parameters.youngs_modulus,
              1e-9 * p.youngs_modulus);
}

// The bar's largest tilt after it first touches the ground: mean height of its -x end minus that
// of its +x end [m] (surface points within 2 cm of either end of the rest bar).
double LargestTiltAfterImpact(const ConcealedScene& scene) {
  RunOptions run;
  run.simulation.cells_along_longest_side = 8;
  run.substeps_per_frame = 2;
  const Eigen::AlignedBox3d rest = scene.scene.mesh.Bounds();
  double largest = 0.0;
  bool touched = false;
  Result<RunSummary> summary = RunScene(scene.scene, run, [&](int, const fem::Simulator& sim) {
    const std::vector<Eigen::Vector3d> now = sim.SurfacePositions();
    const std::vector<Eigen::Vector3d>& at_rest = sim.rest_surface().vertices;
    double low_x = 0.0, high_x = 0.0, bottom = 1e9;
    int n_low = 0, n_high = 0;
    for (size_t i = 0; i < now.size(); ++i) {
      bottom = std::min(bottom, now[i].z());
      if (at_rest[i].x() < rest.min().x() + 0.02) low_x += now[i].z(), ++n_low;
      if (at_rest[i].x() > rest.max().x() - 0.02) high_x += now[i].z(), ++n_high;
    }
    touched |= bottom < 0.005;
    if (touched && n_low > 0 && n_high > 0)
      largest = std::max(largest, std::abs(low_x / n_low - high_x / n_high));
  });
  EXPECT_TRUE(summary.ok() && !summary->diverged);
  return largest;
}

// The scene shows a 2x contrast in the bounce: the bar leaves the ground tilted by well over the
// depth noise (1.5-2 mm at its distance) at its ends; a uniform bar lands and leaves flat.
TEST(DiagnosisScenes, HalvesContrastShowsInTheBounce) {
  const double uniform =
      LargestTiltAfterImpact(*MakeDiagnosisScene("halves-drop", ConcealedEffect::kNone, 0.0));
  const double contrast = LargestTiltAfterImpact(
      *MakeDiagnosisScene("halves-drop", ConcealedEffect::kHeterogeneousStiffness, 2.0));
  EXPECT_LT(uniform, 1e-3);
  EXPECT_GT(contrast, 1e-2) << "uniform " << uniform;
}

// The effect goes where the name says: friction on the ramp, drag and spin on the throw.
TEST(DiagnosisScenes, EffectsAndStrengths) {
  EXPECT_EQ(MakeDiagnosisScene("ramp-block", ConcealedEffect::kFriction, 0.3)
                ->scene.parameters.friction_coefficient,
            0.3);
  EXPECT_EQ(MakeDiagnosisScene("light-throw", ConcealedEffect::kAirDrag, 0.6)
                ->scene.parameters.drag_quadratic,
            0.6);
  EXPECT_EQ(MakeDiagnosisScene("light-throw", ConcealedEffect::kInitialSpin, 4.0)
                ->scene.parameters.initial_angular_velocity.norm(),
            4.0);
  // Controls vary the material by the seeded variation.
  EXPECT_NEAR(MakeDiagnosisScene("ramp-block", ConcealedEffect::kNone, 0.0, 0.1)
                      ->scene.parameters.youngs_modulus /
                  MakeDiagnosisScene("ramp-block", ConcealedEffect::kNone, 0.0)
                      ->scene.parameters.youngs_modulus,
              1.1, 1e-12);
}

TEST(DiagnosisScenes, ErrorsNameTheFieldAndValue) {
  auto message = [](const Result<ConcealedScene>& r) { return r.status().message(); };
  EXPECT_NE(message(MakeDiagnosisScene("teapot", ConcealedEffect::kNone, 0.0)).find("scene = "),
            std::string::npos);
  EXPECT_NE(message(MakeDiagnosisScene("ramp-block", ConcealedEffect::kAirDrag, 0.6))
                .find("effect = \"air_drag\""),
            std::string::npos)
      << message(MakeDiagnosisScene("ramp-block", ConcealedEffect::kAirDrag, 0.6));
  EXPECT_NE(message(MakeDiagnosisScene("ramp-block", ConcealedEffect::kFriction, -0.1))
                .find("strength = -0.1"),
            std::string::npos);
  EXPECT_NE(message(MakeDiagnosisScene("ramp-block", ConcealedEffect::kNone, 0.0, 0.7))
                .find("variation = 0.7"),
            std::string::npos);
  EXPECT_NE(ParseConcealedEffect("gravity", "effect").status().message().find("effect = "),
            std::string::npos);
  EXPECT_EQ(*ParseConcealedEffect("air_drag", "effect"), ConcealedEffect::kAirDrag);
}

}  // namespace
}  // namespace softid::scenes
