// Choosing the grid by refinement against the depth noise.
#include "core/inverse/grid_selection.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>

#include "core/geometry/primitives.h"
#include "core/scenes/scene.h"
#include "tests/core/inverse/tilted_block_drop.h"

namespace softid::inverse {
namespace {

// A soft ball landing: the grid sets how much it squashes.
class SelectGridTest : public ::testing::Test {
 protected:
  void SetUp() override { ASSERT_TRUE(scene.ok()) << scene.status().ToString(); }
  Result<GridSelection> Select(double depth_noise_m, const GridSelectionOptions& options) {
    return SelectGrid(scene->mesh, scene->fixed_region, scene->parameters, {}, 60.0, kLastFrame,
                      depth_noise_m, options);
  }
  static GridSelectionOptions SmallGrids() {
    GridSelectionOptions options;
    options.candidates = {4, 6, 9};
    options.substeps = 2;
    options.min_tolerance_fraction = 0.0;
    return options;
  }
  static constexpr int kLastFrame = 24;  // past the first impact
  const Result<scenes::Scene> scene = scenes::MakeBuiltinScene("ball-bounce");
};

TEST_F(SelectGridTest, RefinesUntilTheSurfaceMovesLessThanTheNoise) {
  // Noise no grid can match: every candidate is compared with the next, the finest is taken.
  const Result<GridSelection> all = Select(1e-9, SmallGrids());
  ASSERT_TRUE(all.ok()) << all.status().ToString();
  ASSERT_EQ(all->trials.size(), 2u);  // 4 vs 6, 6 vs 9
  EXPECT_FALSE(all->within_tolerance);
  EXPECT_EQ(all->cells, 9);
  EXPECT_EQ(all->untried_cells, 0);  // 9 is the finest candidate: nothing was left out
  for (const GridTrial& trial : all->trials) {
    EXPECT_FALSE(trial.diverged);
    EXPECT_GT(trial.difference_m, 0.0);
    EXPECT_GT(trial.grid_nodes, 0);
  }
  EXPECT_LT(all->trials[0].grid_nodes, all->trials[1].grid_nodes);

  // Noise between the two differences (tolerance = half the noise): the middle grid is enough
  // when it moves the surface less than the coarse one did.
  const double d0 = all->trials[0].difference_m, d1 = all->trials[1].difference_m;
  ASSERT_NE(d0, d1);
  const double noise = (d0 + d1);  // tolerance (d0 + d1) / 2 lies between them
  const Result<GridSelection> chosen = Select(noise, SmallGrids());
  ASSERT_TRUE(chosen.ok());
  EXPECT_TRUE(chosen->within_tolerance);
  EXPECT_DOUBLE_EQ(chosen->tolerance_m, 0.5 * noise);
  EXPECT_EQ(chosen->cells, d0 > d1 ? 6 : 4);
  EXPECT_LE(chosen->trials.back().difference_m, chosen->tolerance_m);

  // Noise far above any difference: the coarsest grid, after one comparison.
  const Result<GridSelection> coarse = Select(1.0, SmallGrids());
  ASSERT_TRUE(coarse.ok());
  EXPECT_EQ(coarse->cells, 4);
  EXPECT_EQ(coarse->trials.size(), 1u);
  EXPECT_TRUE(coarse->within_tolerance);
  EXPECT_EQ(coarse->trials[0].frames_within_tolerance, kLastFrame + 1);
}

// A block dropped tilted onto a frictionless floor with no damping rocks from corner to corner:
// the runs on two grids agree until it lands and part after the first impacts: the trials say from
// which frame on.
TEST(SelectGrid, TrialsSayUntilWhichFrameTheGridsAgree) {
  const geometry::TriangleMesh block = testing::TiltedBlock();
  const fem::PhysicalParameters parameters = testing::UndampedBlockOnAFloor();
  GridSelectionOptions options;
  options.candidates = {6, 9, 13};
  options.min_tolerance_fraction = 0.0;
  const Result<GridSelection> selection =
      SelectGrid(block, std::nullopt, parameters, {}, 60.0, 47, 1e-3, options);
  ASSERT_TRUE(selection.ok()) << selection.status().ToString();
  ASSERT_EQ(selection->trials.size(), 2u);
  EXPECT_FALSE(selection->within_tolerance);
  // Before the first impact (it falls 4 cm: about 5 frames) the runs agree.
  for (const GridTrial& trial : selection->trials) {
    EXPECT_GT(trial.frames_within_tolerance, 3);
    EXPECT_LT(trial.frames_within_tolerance, 48);
  }
  EXPECT_EQ(ToJson(*selection)["trials"][1]["frames_within_tolerance"],
            selection->trials[1].frames_within_tolerance);
}

TEST_F(SelectGridTest, NeverSimulatesAGridAboveTheNodeBudget) {
  GridSelectionOptions options = SmallGrids();
  // A budget of the 6-cell grid's box admits the 6-cell grid and not the 9-cell one: 9 is never
  // run.
  const Eigen::Vector3d size = scene->mesh.Bounds().sizes();
  options.max_grid_nodes = static_cast<int>(GridNodeEstimate(size, 6));
  ASSERT_GT(GridNodeEstimate(size, 9), options.max_grid_nodes);
  const Result<GridSelection> capped = Select(1e-9, options);
  ASSERT_TRUE(capped.ok());
  EXPECT_EQ(capped->cells, 6);
  EXPECT_FALSE(capped->within_tolerance);
  ASSERT_EQ(capped->trials.size(), 1u);
  EXPECT_EQ(capped->trials[0].finer_cells, 6);
  EXPECT_EQ(ToJson(*capped)["cells"], 6);
  // The result names the grid the budget left out and what it would have kept.
  EXPECT_EQ(capped->untried_cells, 9);
  const Result<int> untried_nodes = CountGridNodes(scene->mesh, {}, false, 9);
  ASSERT_TRUE(untried_nodes.ok());
  EXPECT_EQ(capped->untried_grid_nodes, *untried_nodes);
  EXPECT_GT(capped->untried_grid_nodes, options.max_grid_nodes);
  EXPECT_EQ(ToJson(*capped)["untried_cells"], 9);
  // A ball's grid keeps fewer nodes than its bounding box has.
  EXPECT_LE(capped->trials[0].grid_nodes, GridNodeEstimate(size, 4));
}

// The budget counts the nodes the simulation keeps (CountGridNodes, the run's own count), not
// the bounding box's: a budget the 9-cell box exceeds admits the 9-cell grid of a ball; one node
// less does not.
TEST_F(SelectGridTest, TheBudgetCountsTheGridsOwnNodes) {
  const Result<GridSelection> all = Select(1e-9, SmallGrids());
  ASSERT_TRUE(all.ok()) << all.status().ToString();
  ASSERT_EQ(all->trials.size(), 2u);
  for (const GridTrial& trial : all->trials) {
    const Result<int> counted = CountGridNodes(scene->mesh, {}, false, trial.cells);
    ASSERT_TRUE(counted.ok()) << counted.status().ToString();
    EXPECT_EQ(*counted, trial.grid_nodes) << trial.cells << " cells";
  }
  const Result<int> nodes_9 = CountGridNodes(scene->mesh, {}, false, 9);
  ASSERT_TRUE(nodes_9.ok());
  ASSERT_LT(*nodes_9, 0.8 * GridNodeEstimate(scene->mesh.Bounds().sizes(), 9));

  GridSelectionOptions options = SmallGrids();
  options.max_grid_nodes = *nodes_9;
  const Result<GridSelection> admitted = Select(1e-9, options);
  ASSERT_TRUE(admitted.ok());
  EXPECT_EQ(admitted->cells, 9);
  EXPECT_EQ(admitted->trials.size(), 2u);

  options.max_grid_nodes = *nodes_9 - 1;
  const Result<GridSelection> capped = Select(1e-9, options);
  ASSERT_TRUE(capped.ok());
  EXPECT_EQ(capped->cells, 6);
  EXPECT_EQ(capped->trials.size(), 1u);
  const Result<std::vector<int>> candidates = CandidateGridNodes(scene->mesh, {}, false, options);
  ASSERT_TRUE(candidates.ok());
  EXPECT_EQ(*candidates,
            (std::vector<int>{all->trials[0].grid_nodes, all->trials[1].grid_nodes, *nodes_9}));
}

TEST_F(SelectGridTest, RefusesBadOptionsNamingTheField) {
  GridSelectionOptions options = SmallGrids();
  options.candidates = {6, 4};
  Result<GridSelection> result = Select(1e-3, options);
  ASSERT_FALSE(result.ok());
  EXPECT_NE(result.status().message().find("candidates[1] = 4"), std::string::npos);
  result = Select(0.0, SmallGrids());
  ASSERT_FALSE(result.ok());
  EXPECT_NE(result.status().message().find("depth_noise_m = 0"), std::string::npos);
  options = SmallGrids();
  options.max_grid_nodes = 0;
  result = Select(1e-3, options);
  ASSERT_FALSE(result.ok());
  EXPECT_NE(result.status().message().find("max_grid_nodes"), std::string::npos);
}

TEST_F(SelectGridTest, StopsWhenCancelled) {
  std::atomic<bool> cancel{true};
  GridSelectionOptions options = SmallGrids();
  options.cancel = &cancel;
  const Result<GridSelection> result = Select(1e-3, options);
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.status().code(), StatusCode::kCancelled);
}

// A time limit the first run already uses up: no finer grid is simulated, the coarsest run is
// taken and the selection says why; a limit of 0 is none, a negative one is refused.
TEST_F(SelectGridTest, TakesTheFinestGridRunWithinTheTimeLimit) {
  GridSelectionOptions options = SmallGrids();
  options.max_seconds = 1e-6;
  const Result<GridSelection> limited = Select(1e-9, options);
  ASSERT_TRUE(limited.ok()) << limited.status().ToString();
  EXPECT_EQ(limited->cells, 4);
  EXPECT_TRUE(limited->trials.empty());
  EXPECT_TRUE(limited->stopped_at_time_limit);
  EXPECT_FALSE(limited->within_tolerance);
  EXPECT_TRUE(ToJson(*limited).at("stopped_at_time_limit").get<bool>());
  options.max_seconds = 0.0;
  const Result<GridSelection> unlimited = Select(1e-9, options);
  ASSERT_TRUE(unlimited.ok());
  EXPECT_EQ(unlimited->cells, 9);
  EXPECT_FALSE(unlimited->stopped_at_time_limit);
  options.max_seconds = -1.0;
  const Result<GridSelection> refused = Select(1e-9, options);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("max_seconds = -1"), std::string::npos);
}

}  // namespace
}  // namespace softid::inverse
