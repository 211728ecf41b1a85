#include "core/inverse/job_resources.h"

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "core/inverse/grid_selection.h"
#include "core/inverse/time_step_selection.h"

namespace softid::inverse {
namespace {

// A 28 x 28 x 10 cm object seen in 61 frames by one camera.
CaptureExtent TorusSized() {
  CaptureExtent extent;
  extent.mesh_bounds =
      Eigen::AlignedBox3d(Eigen::Vector3d(-0.14, -0.14, 0.0), Eigen::Vector3d(0.14, 0.14, 0.1));
  extent.num_frames = 61;
  extent.num_cameras = 1;
  return extent;
}

void ExpectRefused(const Result<JobResourceEstimate>& estimate, const std::string& part) {
  ASSERT_FALSE(estimate.ok());
  EXPECT_EQ(estimate.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(estimate.status().message().find(part), std::string::npos)
      << estimate.status().message();
}

TEST(JobResources, DefaultConfigFitsWithRoom) {
  JobResourceLimits limits;
  limits.cores = 2;
  const Result<JobResourceEstimate> estimate = EstimateJobResources({}, TorusSized(), limits);
  ASSERT_TRUE(estimate.ok()) << estimate.status().ToString();
  // "auto" cells: the finest candidate the selection may simulate. 24 cells make 25 x 25 x 10
  // nodes, over the 6000-node budget; 16 make 17 x 17 x 7.
  ASSERT_EQ(GridSelectionOptions{}.max_grid_nodes, 6000);
  EXPECT_DOUBLE_EQ(estimate->cell_size_m, 0.28 / 16);
  EXPECT_EQ(estimate->grid_nodes, 17 * 17 * 7);
  // "auto" substeps: the largest candidate on that grid, 64 (2023 nodes x 64 is within the
  // node-step budget).
  EXPECT_EQ(LargestSubstepCandidate(17 * 17 * 7, SubstepSelectionOptions{}), 64);
  EXPECT_EQ(estimate->steps_per_run, 60 * 64);
  EXPECT_EQ(estimate->concurrent_starts, 2);
  EXPECT_LT(estimate->memory_bytes, 0.5 * limits.max_memory_bytes);
}

// With the grids' own node counts known (CandidateGridNodes), "auto" cells take the finest grid
// whose own nodes are within the budget, not its bounding box's: a slim body affords a finer grid.
TEST(JobResources, AutoCellsCountTheGridsOwnNodesWhenKnown) {
  JobResourceLimits limits;
  limits.cores = 2;
  const GridSelectionOptions selection;
  ASSERT_EQ(selection.candidates, (std::vector<int>{8, 12, 16, 24, 32, 48}));
  ASSERT_EQ(selection.max_grid_nodes, 6000);
  CaptureExtent slim = TorusSized();
  // A body that keeps a third of its box at every candidate: 32 cells keep 33 x 33 x 13 / 3 =
  // 4719 nodes, 48 cells 15206.
  for (const int cells : selection.candidates) {
    slim.candidate_grid_nodes.push_back(
        static_cast<int>(GridNodeEstimate(slim.mesh_bounds.sizes(), cells) / 3));
  }
  const Result<JobResourceEstimate> estimate = EstimateJobResources({}, slim, limits);
  ASSERT_TRUE(estimate.ok()) << estimate.status().ToString();
  EXPECT_DOUBLE_EQ(estimate->cell_size_m, 0.28 / 32);
  EXPECT_EQ(estimate->grid_nodes, slim.candidate_grid_nodes[4]);
  // A count over the budget stops the choice before it, as the selection would.
  slim.candidate_grid_nodes[4] = selection.max_grid_nodes + 1;
  const Result<JobResourceEstimate> capped = EstimateJobResources({}, slim, limits);
  ASSERT_TRUE(capped.ok()) << capped.status().ToString();
  EXPECT_DOUBLE_EQ(capped->cell_size_m, 0.28 / 24);
  EXPECT_EQ(capped->grid_nodes, slim.candidate_grid_nodes[3]);
  // A count that no grid can have is refused naming it.
  slim.candidate_grid_nodes[1] = 0;
  ExpectRefused(EstimateJobResources({}, slim, limits), "candidate_grid_nodes[1] = 0");
}

// The configs an attacker or an unlucky user sent: each refused, naming the key.
TEST(JobResources, OversizedConfigsAreRefusedNamingTheKey) {
  const JobResourceLimits limits;
  JobConfig cells;
  cells.solver.cells = 300;
  ExpectRefused(EstimateJobResources(cells, TorusSized(), limits), "cells = 300: the job would");
  cells.solver.cells = 100000;
  ExpectRefused(EstimateJobResources(cells, TorusSized(), limits), "at most 4 GiB is accepted");
  JobConfig substeps;
  substeps.solver.substeps = 20000;
  ExpectRefused(EstimateJobResources(substeps, TorusSized(), limits), "substeps = 20000");
  JobConfig cell_size;
  cell_size.solver.cell_size_m = 1e-9;
  ExpectRefused(EstimateJobResources(cell_size, TorusSized(), limits), "cell_size = 1e-09");
}

// Time: the default job is hours below the limit; an absurd iteration or start count is refused
// naming the key; the estimate grows with the work and a diagnosis multiplies it.
TEST(JobResources, WallTimeIsEstimatedAndBounded) {
  JobResourceLimits limits;
  limits.cores = 2;
  const Result<JobResourceEstimate> plain = EstimateJobResources({}, TorusSized(), limits);
  ASSERT_TRUE(plain.ok()) << plain.status().ToString();
  EXPECT_GT(plain->wall_seconds, 60.0);
  EXPECT_LT(plain->wall_seconds, 0.25 * limits.max_wall_seconds);

  JobConfig iterations;
  iterations.solver.max_iterations = 100000;
  ExpectRefused(EstimateJobResources(iterations, TorusSized(), limits),
                "max_iterations = 100000: the job could run for about");
  ExpectRefused(EstimateJobResources(iterations, TorusSized(), limits), "at most 24 h is accepted");
  JobConfig starts;
  starts.solver.starts = 5000;
  ExpectRefused(EstimateJobResources(starts, TorusSized(), limits), "starts = 5000");

  JobConfig longer;
  longer.solver.max_iterations = 2 * JobConfig{}.solver.max_iterations;
  ASSERT_TRUE(EstimateJobResources(longer, TorusSized(), limits).ok())
      << EstimateJobResources(longer, TorusSized(), limits).status().ToString();
  EXPECT_GT(EstimateJobResources(longer, TorusSized(), limits)->wall_seconds,
            1.9 * plain->wall_seconds);
  JobConfig diagnosed;
  diagnosed.diagnose = true;
  ASSERT_TRUE(EstimateJobResources(diagnosed, TorusSized(), limits).ok())
      << EstimateJobResources(diagnosed, TorusSized(), limits).status().ToString();
  EXPECT_GT(EstimateJobResources(diagnosed, TorusSized(), limits)->wall_seconds,
            4.0 * plain->wall_seconds);
  // More cores for the same starts: never slower.
  limits.cores = 8;
  ASSERT_TRUE(EstimateJobResources({}, TorusSized(), limits).ok())
      << EstimateJobResources({}, TorusSized(), limits).status().ToString();
  EXPECT_LE(EstimateJobResources({}, TorusSized(), limits)->wall_seconds, plain->wall_seconds);
  limits.max_wall_seconds = 0;
  EXPECT_FALSE(EstimateJobResources({}, TorusSized(), limits).ok());
}

// "refine_grid" adds one start on cells 1.5 x smaller after the fit: more time, and the memory of
// that one start where it exceeds the concurrent starts'.
TEST(JobResources, GridRefinementAddsTheRefitOnTheFinerGrid) {
  JobResourceLimits limits;
  limits.cores = 2;
  JobConfig config;
  config.solver.cells = 12;
  config.solver.substeps = 8;
  config.solver.starts = 2;
  const Result<JobResourceEstimate> plain = EstimateJobResources(config, TorusSized(), limits);
  config.refine_grid = true;
  const Result<JobResourceEstimate> refined = EstimateJobResources(config, TorusSized(), limits);
  ASSERT_TRUE(plain.ok()) << plain.status().ToString();
  ASSERT_TRUE(refined.ok()) << refined.status().ToString();
  EXPECT_EQ(refined->grid_nodes, plain->grid_nodes);  // the fit's own grid
  // One start on 3.4 x the nodes (12 cells: 13 x 13 x 6 = 1014 nodes) against two at once.
  EXPECT_GT(refined->memory_bytes, 1.5 * plain->memory_bytes);
  EXPECT_GT(refined->wall_seconds, 1.5 * plain->wall_seconds);

  // The refit is held to the refinement's node budget (18000 nodes; 48 cells after 32 would keep
  // about 47000), so that a fine grid's fit of 4 starts gains less than half its time.
  config.solver.cells = 32;
  config.solver.starts = 4;
  const Result<JobResourceEstimate> large = EstimateJobResources(config, TorusSized(), limits);
  ASSERT_TRUE(large.ok()) << large.status().ToString();
  config.refine_grid = false;
  const Result<JobResourceEstimate> large_plain =
      EstimateJobResources(config, TorusSized(), limits);
  ASSERT_TRUE(large_plain.ok());
  EXPECT_LT(large->wall_seconds, 1.5 * large_plain->wall_seconds);
}

TEST(JobResources, FramesMustLieInTheCapture) {
  const JobResourceLimits limits;
  JobConfig last;
  last.frames.last = 61;
  ExpectRefused(EstimateJobResources(last, TorusSized(), limits),
                "frames.last = 61: the capture has 61 frames (0-60)");
  JobConfig first;
  first.frames.first = 70;
  ExpectRefused(EstimateJobResources(first, TorusSized(), limits), "frames.first = 70");
  last.frames.last = 60;
  EXPECT_TRUE(EstimateJobResources(last, TorusSized(), limits).ok());
}

// Memory grows with the work: more frames or starts at once never make the estimate smaller.
TEST(JobResources, EstimateGrowsWithFramesAndConcurrentStarts) {
  JobResourceLimits limits;
  limits.cores = 1;
  CaptureExtent longer = TorusSized();
  longer.num_frames = 121;
  const double one = EstimateJobResources({}, TorusSized(), limits)->memory_bytes;
  // Twice the steps: the stored trajectory doubles, the simulator's own memory does not.
  EXPECT_GT(EstimateJobResources({}, longer, limits)->memory_bytes, 1.5 * one);
  limits.cores = 4;
  EXPECT_DOUBLE_EQ(EstimateJobResources({}, TorusSized(), limits)->memory_bytes, 4 * one);
  limits.max_memory_bytes = 0;
  EXPECT_FALSE(EstimateJobResources({}, TorusSized(), limits).ok());
}

// Steps follow the frames' times, not their count: frames dropped from a capture with frame_times
// still cost their simulation steps.
TEST(JobResources, StepsFollowTheFrameTimes) {
  JobResourceLimits limits;
  CaptureExtent even = TorusSized();
  CaptureExtent sparse = TorusSized();
  for (int k = 0; k < sparse.num_frames; ++k) sparse.frame_periods.push_back(2.0 * k + 0.3);
  const auto a = EstimateJobResources({}, even, limits);
  const auto b = EstimateJobResources({}, sparse, limits);
  ASSERT_TRUE(a.ok() && b.ok());
  // The last frame is frame 60 (60 periods) in one and at 120.3 periods in the other.
  EXPECT_EQ(b->steps_per_run * 60, a->steps_per_run * 121);
  sparse.frame_periods.pop_back();
  EXPECT_FALSE(EstimateJobResources({}, sparse, limits).ok());
}

}  // namespace
}  // namespace softid::inverse
