#include "core/diagnosis/motion_phases.h"

#include <gtest/gtest.h>

#include "core/fem/simulator.h"
#include "core/scenes/diagnosis_scenes.h"

namespace softid::diagnosis {
namespace {

std::vector<Phase> PhasesOf(const std::string& scene_name, double duration, int cells) {
  Result<scenes::ConcealedScene> scene =
      scenes::MakeDiagnosisScene(scene_name, scenes::ConcealedEffect::kNone, 0.0);
  EXPECT_TRUE(scene.ok());
  fem::SimulationOptions options;
  options.cells_along_longest_side = cells;
  options.time_step = 1.0 / 120.0;
  fem::Simulator sim(scene->scene.mesh, scene->scene.parameters, options);
  std::vector<FrameAt> frames;
  for (int k = 0; k <= static_cast<int>(duration * 60); ++k) frames.push_back({k, k / 60.0});
  Result<std::vector<FrameMotion>> motion = SplitMotionPhases(sim, scene->scene.parameters, frames);
  EXPECT_TRUE(motion.ok()) << motion.status().ToString();
  std::vector<Phase> out;
  for (const FrameMotion& m : *motion) out.push_back(m.phase);
  return out;
}

// A bar dropped 15 cm falls (flight), hits the floor (impact) and, frictionless on a level floor,
// comes to rest or bounces: flight comes first and an impact follows it.
TEST(MotionPhases, DropIsFlightThenImpact) {
  const std::vector<Phase> phases = PhasesOf("halves-drop", 0.3, /*cells=*/6);
  ASSERT_GT(phases.size(), 10u);
  EXPECT_EQ(phases.front(), Phase::kFlight);
  // Free fall over 15 cm takes 0.175 s: 10.5 frames at 60 fps (contact counts from half a cell,
  // 1.3 cm, above the floor: frame 10).
  for (int k = 0; k < 9; ++k) EXPECT_EQ(phases[k], Phase::kFlight) << "frame " << k;
  const auto impact = std::find(phases.begin(), phases.end(), Phase::kImpact);
  ASSERT_NE(impact, phases.end());
  EXPECT_NEAR(impact - phases.begin(), 10.5, 1.5);
}

// The lively foam bar bounces: the frames in the air after the first contact are rebound, not
// flight, so that a misfit of the bounce is not averaged with the fall before it.
TEST(MotionPhases, BounceIsRebound) {
  const std::vector<Phase> phases = PhasesOf("halves-drop", 0.45, /*cells=*/6);
  const auto impact = std::find(phases.begin(), phases.end(), Phase::kImpact);
  ASSERT_NE(impact, phases.end());
  EXPECT_EQ(std::find(impact, phases.end(), Phase::kFlight), phases.end());
  EXPECT_GE(std::count(impact, phases.end(), Phase::kRebound), 3);
  EXPECT_EQ(std::count(phases.begin(), impact, Phase::kRebound), 0);
  EXPECT_STREQ(ToString(Phase::kRebound), "rebound");
}

// A frictionless block dropped 1 cm onto a 30 degree ramp lands and slides (a grid fine enough
// that half a cell is below the 1 cm gap).
TEST(MotionPhases, RampIsImpactThenSliding) {
  const std::vector<Phase> phases = PhasesOf("ramp-block", 0.4, /*cells=*/12);
  EXPECT_EQ(phases.front(), Phase::kFlight);
  EXPECT_EQ(phases.back(), Phase::kSliding);
  EXPECT_NE(std::find(phases.begin(), phases.end(), Phase::kImpact), phases.end());
}

// The visitor (what a report reads off the same run) sees every frame once, in order, with the
// simulator at the step nearest that frame's time, including frames between simulation steps.
TEST(MotionPhases, VisitorSeesEachFrameAtItsStep) {
  Result<scenes::ConcealedScene> scene =
      scenes::MakeDiagnosisScene("halves-drop", scenes::ConcealedEffect::kNone, 0.0);
  ASSERT_TRUE(scene.ok());
  fem::SimulationOptions options;
  options.cells_along_longest_side = 6;
  options.time_step = 1.0 / 120.0;
  fem::Simulator sim(scene->scene.mesh, scene->scene.parameters, options);
  // Uneven times, as a device clock gives them.
  const std::vector<FrameAt> frames = {{0, 0.0}, {1, 0.017}, {3, 0.051}, {4, 0.0655}, {7, 0.12}};
  std::vector<size_t> seen;
  std::vector<double> times;
  const FrameVisitor visit = [&](size_t index, const fem::Simulator& at_frame) {
    seen.push_back(index);
    times.push_back(at_frame.state().time);
  };
  ASSERT_TRUE(SplitMotionPhases(sim, scene->scene.parameters, frames, {}, visit).ok());
  ASSERT_EQ(seen, (std::vector<size_t>{0, 1, 2, 3, 4}));
  for (size_t i = 0; i < frames.size(); ++i)
    EXPECT_LE(std::abs(times[i] - frames[i].time_s), 0.5 * options.time_step + 1e-12) << i;
}

TEST(MotionPhases, OptionsNameTheField) {
  MotionPhaseOptions options;
  options.contact_cells = 0.0;
  EXPECT_NE(options.Validate().message().find("phases.contact_cells = 0"), std::string::npos);
}

}  // namespace
}  // namespace softid::diagnosis
