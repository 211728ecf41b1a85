// Checkpoints of a fit: a fit resumed from the checkpoint of its first finished start computes
// exactly what the uninterrupted fit did, runs only the missing starts, and chooses no grid or
// time step again; starts run one at a time (only_starts) match the whole fit's; checkpoints
// survive JSON exactly and malformed or foreign ones are refused by name.
#include "core/inverse/fit_checkpoint.h"

#include <gtest/gtest.h>

#include <set>

#include "tests/core/inverse/inverse_test_util.h"

namespace softid::inverse {
namespace {

JobConfig ThreeStartConfig(const fem::PhysicalParameters& truth) {
  return testing::YoungsModulusConfig(truth, /*starts=*/3, /*max_iterations=*/8);
}

class FitCheckpointTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    small_ = new testing::SmallCapture(testing::MakeSmallCapture("torus-drop", 0.25));
  }
  static void TearDownTestSuite() {
    delete small_;
    small_ = nullptr;
  }
  void SetUp() override { ASSERT_TRUE(small_->ok) << small_->error; }

  static testing::SmallCapture* small_;
};
testing::SmallCapture* FitCheckpointTest::small_ = nullptr;

void ExpectSameStart(const StartResult& a, const StartResult& b) {
  SCOPED_TRACE("start " + std::to_string(a.index));
  EXPECT_EQ(a.index, b.index);
  EXPECT_EQ(a.initial.youngs_modulus, b.initial.youngs_modulus);
  EXPECT_EQ(a.final.youngs_modulus, b.final.youngs_modulus);
  EXPECT_EQ(a.final_cost, b.final_cost);
  EXPECT_EQ(a.iterations, b.iterations);
  EXPECT_EQ(a.cost_history, b.cost_history);
  EXPECT_EQ(a.termination, b.termination);
}

TEST_F(FitCheckpointTest, ResumedFitComputesWhatTheUninterruptedOneDid) {
  const JobConfig config = ThreeStartConfig(small_->truth);
  std::vector<nlohmann::json> saved;
  FitOptions options;
  options.on_checkpoint = [&](const FitCheckpoint& c) { saved.push_back(ToJson(c)); };
  Result<FitResult> whole = Fit(small_->capture, config, options);
  ASSERT_TRUE(whole.ok()) << whole.status().ToString();
  // Once with the discretisation, then after each of the three starts.
  ASSERT_EQ(saved.size(), 4u);
  EXPECT_TRUE(saved[0]["finished"].empty());
  EXPECT_EQ(saved[3]["finished"].size(), 3u);

  // Interrupted after its first finished start: the resumed fit runs the other two only.
  Result<FitCheckpoint> checkpoint = FitCheckpointFromJson(saved[1]);
  ASSERT_TRUE(checkpoint.ok()) << checkpoint.status().ToString();
  ASSERT_EQ(checkpoint->finished.size(), 1u);
  const int done = checkpoint->finished[0].index;
  std::set<int> reporting;
  FitOptions resume;
  resume.resume_from = &*checkpoint;
  resume.on_progress = [&](const FitProgress& p) { reporting.insert(p.start); };
  Result<FitResult> resumed = Fit(small_->capture, config, resume);
  ASSERT_TRUE(resumed.ok()) << resumed.status().ToString();
  EXPECT_EQ(reporting.count(done), 0u);
  EXPECT_EQ(reporting.size(), 2u);
  ASSERT_EQ(resumed->starts.size(), whole->starts.size());
  for (size_t s = 0; s < whole->starts.size(); ++s)
    ExpectSameStart(resumed->starts[s], whole->starts[s]);
  EXPECT_EQ(resumed->best, whole->best);
  EXPECT_EQ(ToJson(*resumed)["parameters"], ToJson(*whole)["parameters"]);
}

TEST_F(FitCheckpointTest, StartsRunOneByOneMatchTheWholeFit) {
  JobConfig config = ThreeStartConfig(small_->truth);
  config.solver.substeps = kAutoSubsteps;  // chosen once, by PrepareFit, then from its checkpoint
  Result<FitCheckpoint> prepared = PrepareFit(small_->capture, config);
  ASSERT_TRUE(prepared.ok()) << prepared.status().ToString();
  ASSERT_TRUE(prepared->substep_selection.has_value());
  EXPECT_EQ(prepared->num_starts, 3);
  EXPECT_TRUE(prepared->finished.empty());

  // Each start alone (as a worker elsewhere would run it), its result carried as JSON text.
  FitCheckpoint all = *prepared;
  for (int s : {2, 0, 1}) {
    FitOptions one;
    one.only_starts = {s};
    one.resume_from = &*prepared;
    Result<FitResult> task = Fit(small_->capture, config, one);
    ASSERT_TRUE(task.ok()) << task.status().ToString();
    // The selection's record, kept from the checkpoint; the other starts did not run.
    ASSERT_TRUE(task->substep_selection.has_value());
    EXPECT_FALSE(task->substep_selection->trials.empty());
    EXPECT_EQ(task->starts[(s + 1) % 3].evaluations, 0);
    Result<StartResult> carried =
        StartFromCheckpointJson(nlohmann::json::parse(StartCheckpointJson(task->starts[s]).dump()));
    ASSERT_TRUE(carried.ok()) << carried.status().ToString();
    all.finished.push_back(*carried);
  }
  // The last step runs nothing and picks the best.
  FitOptions combine;
  combine.resume_from = &all;
  Result<FitResult> combined = Fit(small_->capture, config, combine);
  ASSERT_TRUE(combined.ok()) << combined.status().ToString();

  Result<FitResult> whole = Fit(small_->capture, config);
  ASSERT_TRUE(whole.ok()) << whole.status().ToString();
  EXPECT_EQ(combined->substeps, whole->substeps);
  for (size_t s = 0; s < whole->starts.size(); ++s)
    ExpectSameStart(combined->starts[s], whole->starts[s]);
  EXPECT_EQ(combined->best, whole->best);
  EXPECT_EQ(StartFromCheckpointJson(nlohmann::json::object()).status().code(),
            StatusCode::kInvalidArgument);
}

TEST_F(FitCheckpointTest, SurvivesJsonExactly) {
  const JobConfig config = ThreeStartConfig(small_->truth);
  FitOptions options;
  options.only_starts = {1};
  std::optional<FitCheckpoint> last;
  options.on_checkpoint = [&](const FitCheckpoint& c) { last = c; };
  ASSERT_TRUE(Fit(small_->capture, config, options).ok());
  ASSERT_TRUE(last.has_value());
  ASSERT_EQ(last->finished.size(), 1u);
  const nlohmann::json json = ToJson(*last);
  Result<FitCheckpoint> read = FitCheckpointFromJson(nlohmann::json::parse(json.dump()));
  ASSERT_TRUE(read.ok()) << read.status().ToString();
  EXPECT_EQ(ToJson(*read), json);
  ExpectSameStart(read->finished[0], last->finished[0]);
  EXPECT_EQ(read->finished[0].stages.size(), last->finished[0].stages.size());
}

TEST_F(FitCheckpointTest, RefusesMalformedAndForeignCheckpoints) {
  const JobConfig config = ThreeStartConfig(small_->truth);
  FitCheckpoint checkpoint;
  checkpoint.num_starts = 3;
  checkpoint.cells = 8;
  checkpoint.cell_size_m = 0.01;
  checkpoint.substeps = 2;
  const nlohmann::json good = ToJson(checkpoint);
  ASSERT_TRUE(FitCheckpointFromJson(good).ok());

  nlohmann::json wrong_format = good;
  wrong_format["format"] = "softid-fit-checkpoint/0";
  EXPECT_NE(FitCheckpointFromJson(wrong_format).status().message().find("format"),
            std::string::npos);
  nlohmann::json missing = good;
  missing["grid"].erase("cells");
  EXPECT_NE(FitCheckpointFromJson(missing).status().message().find("cells"), std::string::npos);
  nlohmann::json bad_type = good;
  bad_type["num_starts"] = "three";
  EXPECT_EQ(FitCheckpointFromJson(bad_type).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(FitCheckpointFromJson(nlohmann::json::array()).status().code(),
            StatusCode::kInvalidArgument);

  // Another config's checkpoint (two starts) is not resumed.
  FitCheckpoint foreign = checkpoint;
  foreign.num_starts = 2;
  FitOptions options;
  options.resume_from = &foreign;
  Result<FitResult> refused = Fit(small_->capture, config, options);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("resume_from"), std::string::npos);

  FitOptions out_of_range;
  out_of_range.only_starts = {3};
  Result<FitResult> no_such_start = Fit(small_->capture, config, out_of_range);
  ASSERT_FALSE(no_such_start.ok());
  EXPECT_NE(no_such_start.status().message().find("only_starts"), std::string::npos);
}

TEST_F(FitCheckpointTest, AStartStoppedByACancelIsNotFinished) {
  const JobConfig config = ThreeStartConfig(small_->truth);
  std::atomic<bool> cancel{false};
  std::optional<FitCheckpoint> last;
  FitOptions options;
  options.cancel = &cancel;
  options.on_progress = [&](const FitProgress& p) {
    if (p.iteration >= 2) cancel.store(true);
  };
  options.on_checkpoint = [&](const FitCheckpoint& c) { last = c; };
  Result<FitResult> stopped = Fit(small_->capture, config, options);
  ASSERT_TRUE(last.has_value());
  EXPECT_TRUE(last->finished.empty());
  if (stopped.ok()) {
    EXPECT_TRUE(stopped->cancelled);
  }
}

}  // namespace
}  // namespace softid::inverse
