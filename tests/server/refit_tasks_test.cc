// The diagnosis' refits as tasks, against a real SQLite store and blob store: a batch of refits
// run by the job's worker and another worker of a pool gives each refit exactly the result the
// fit computes in one process; the batch is kept for a later attempt (nothing runs again); a
// refit that fails fails the same way as a task.
#include "server/refit_tasks.h"

#include <gtest/gtest.h>
#include <spdlog/spdlog.h>

#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>

#include "core/diagnosis/fit_batch.h"
#include "server/job_events.h"
#include "server/store/blob_store.h"
#include "server/store/sqlite_job_store.h"
#include "server/worker_pool.h"
#include "tests/core/inverse/inverse_test_util.h"
#include "tests/server/temp_dir.h"

namespace softid::server {
namespace {

namespace fs = std::filesystem;
using store::testing::TempDir;

// Every file of the capture folder as blobs; the manifest to create the stored capture with.
std::vector<store::ManifestEntry> PutCapture(const fs::path& dir, const store::BlobStore& blobs) {
  std::vector<store::ManifestEntry> manifest;
  for (const fs::directory_entry& entry : fs::recursive_directory_iterator(dir)) {
    if (!entry.is_regular_file()) continue;
    std::ifstream in(entry.path(), std::ios::binary);
    std::stringstream bytes;
    bytes << in.rdbuf();
    Result<std::string> sha = blobs.Put(bytes.str());
    EXPECT_TRUE(sha.ok()) << sha.status().ToString();
    manifest.push_back({fs::relative(entry.path(), dir).generic_string(), *sha,
                        static_cast<int64_t>(bytes.str().size())});
  }
  return manifest;
}

// A refit config: Young's modulus from `e0`, one start, a few iterations, one thread.
inverse::JobConfig RefitConfig(const fem::PhysicalParameters& truth, double e0) {
  inverse::JobConfig config = inverse::testing::YoungsModulusConfig(truth, 1, 4);
  config.initial["youngs_modulus"] = inverse::InitialValue{e0, std::nullopt};
  config.solver.threads = 1;
  return config;
}

TEST(RefitTasks, ABatchRunAsTasksGivesTheOneProcessFits) {
  spdlog::set_level(spdlog::level::err);
  auto* small = new inverse::testing::SmallCapture(
      inverse::testing::MakeSmallCapture("torus-drop", 0.3, /*cameras=*/1));
  std::unique_ptr<inverse::testing::SmallCapture> owned(small);
  ASSERT_TRUE(small->ok) << small->error;
  TempDir data;
  Result<std::unique_ptr<store::SqliteJobStore>> jobs =
      store::SqliteJobStore::Open(data.path() / "softid.db");
  ASSERT_TRUE(jobs.ok()) << jobs.status().ToString();
  Result<store::BlobStore> blobs = store::BlobStore::Open(data.path());
  ASSERT_TRUE(blobs.ok());
  Result<store::Capture> stored = (*jobs)->CreateCapture(PutCapture(small->directory, *blobs), "");
  ASSERT_TRUE(stored.ok()) << stored.status().ToString();
  Result<store::Job> job = (*jobs)->CreateJob(
      stored->id, ToJson(RefitConfig(small->truth, small->truth.youngs_modulus)), "");
  ASSERT_TRUE(job.ok()) << job.status().ToString();
  Result<std::optional<store::Job>> claimed =
      (*jobs)->ClaimNextJob("leader", std::chrono::seconds(60));
  ASSERT_TRUE(claimed.ok() && claimed->has_value());

  // Another worker, as in another process, takes refit tasks too.
  JobEvents events;
  WorkerPoolOptions pool_options;
  pool_options.num_workers = 1;
  pool_options.idle_poll_interval = std::chrono::milliseconds(20);
  pool_options.work_root = data.path() / "work";
  WorkerPool pool(jobs->get(), &*blobs, &events, pool_options, spdlog::default_logger());
  pool.Start();

  JobRunnerContext context;
  context.jobs = jobs->get();
  context.blobs = &*blobs;
  context.events = &events;
  context.work_root = data.path() / "work";
  context.logger = spdlog::default_logger();
  context.task_poll_interval = std::chrono::milliseconds(20);
  const double e = small->truth.youngs_modulus;
  std::vector<inverse::JobConfig> configs = {RefitConfig(small->truth, 0.6 * e),
                                             RefitConfig(small->truth, 1.5 * e),
                                             RefitConfig(small->truth, 0.9 * e)};
  configs[2].frames.last = 999;  // beyond the capture: the refit fails wherever it runs
  std::atomic<bool> cancel{false};
  const std::vector<Result<inverse::FitResult>> tasks =
      FitBatchByTasks(**claimed, small->capture, configs, 1, "leader", context, cancel);
  const std::vector<Result<inverse::FitResult>> here =
      diagnosis::RunFitsInProcess(small->capture, configs, inverse::FitOptions());
  ASSERT_EQ(tasks.size(), 3u);
  for (size_t i = 0; i < 2; ++i) {
    ASSERT_TRUE(tasks[i].ok()) << i << ": " << tasks[i].status().ToString();
    ASSERT_TRUE(here[i].ok()) << i << ": " << here[i].status().ToString();
    EXPECT_EQ(fem::ToJson(tasks[i]->Best().final), fem::ToJson(here[i]->Best().final)) << i;
    EXPECT_EQ(tasks[i]->Best().final_cost, here[i]->Best().final_cost) << i;
    EXPECT_EQ(tasks[i]->Best().iterations, here[i]->Best().iterations) << i;
    EXPECT_GT(here[i]->Best().iterations, 0) << i;
  }
  ASSERT_FALSE(here[2].ok());
  EXPECT_EQ(tasks[2].status().code(), here[2].status().code());
  EXPECT_EQ(tasks[2].status().message(), here[2].status().message());

  // A later attempt's diagnosis finds the batch done: the same results, nothing claimed again.
  const std::vector<Result<inverse::FitResult>> again =
      FitBatchByTasks(**claimed, small->capture, configs, 1, "leader", context, cancel);
  pool.Stop();
  ASSERT_TRUE(again[0].ok());
  EXPECT_EQ(again[0]->Best().final_cost, here[0]->Best().final_cost);
  Result<std::vector<store::StartTask>> listed = (*jobs)->ListStartTasks(job->id);
  ASSERT_TRUE(listed.ok());
  ASSERT_EQ(listed->size(), 3u);
  for (const store::StartTask& task : *listed) {
    EXPECT_EQ(task.state, store::StartTaskState::kDone);
    EXPECT_EQ(task.attempts, 1) << task.index;
    EXPECT_EQ(task.batch.rfind("diagnosis 1 ", 0), 0u) << task.batch;
  }
}

}  // namespace
}  // namespace softid::server
