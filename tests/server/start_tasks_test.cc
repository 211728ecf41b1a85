// Start tasks in a worker pool, against a real SQLite store: a task that cannot run on a worker
// (here: its job has no checkpoint to start from) is left to its lease instead of being handed
// back at once, so idle workers do not take it again and again; and a task claimed too often
// fails its job, naming the start.
#include "server/start_tasks.h"

#include <gtest/gtest.h>
#include <spdlog/spdlog.h>

#include <chrono>
#include <memory>
#include <thread>

#include "server/job_events.h"
#include "server/store/blob_store.h"
#include "server/store/sha256.h"
#include "server/store/sqlite_job_store.h"
#include "server/worker_pool.h"
#include "tests/server/temp_dir.h"

namespace softid::server {
namespace {

using store::testing::TempDir;

TEST(StartTasks, ATaskThatCannotRunIsLeftToItsLeaseNotTakenAgainAndAgain) {
  spdlog::set_level(spdlog::level::err);
  TempDir data;
  Result<std::unique_ptr<store::SqliteJobStore>> jobs =
      store::SqliteJobStore::Open(data.path() / "softid.db");
  ASSERT_TRUE(jobs.ok()) << jobs.status().ToString();
  Result<store::BlobStore> blobs = store::BlobStore::Open(data.path());
  ASSERT_TRUE(blobs.ok());
  Result<store::Capture> capture =
      (*jobs)->CreateCapture({{"capture.json", store::Sha256::Hex("x"), 10}}, "");
  ASSERT_TRUE(capture.ok());
  Result<store::Job> job = (*jobs)->CreateJob(capture->id, {{"fit", {"youngs_modulus"}}}, "");
  ASSERT_TRUE(job.ok());
  // Another process's worker leads the job and split it, but saved no checkpoint.
  ASSERT_TRUE((*jobs)->ClaimNextJob("leader", std::chrono::seconds(60))->has_value());
  ASSERT_TRUE((*jobs)->CreateStartTasks(job->id, "leader", 2).ok());

  JobEvents events;
  WorkerPoolOptions options;
  options.num_workers = 1;
  options.lease = std::chrono::seconds(30);
  options.idle_poll_interval = std::chrono::milliseconds(20);
  options.work_root = data.path() / "work";
  WorkerPool pool(jobs->get(), &*blobs, &events, options, spdlog::default_logger());
  pool.Start();
  auto attempts = [&] {
    int total = 0;
    for (const store::StartTask& task : *(*jobs)->ListStartTasks(job->id)) total += task.attempts;
    return total;
  };
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (attempts() < 2 && std::chrono::steady_clock::now() < give_up) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  // Many idle polls later, neither task has been taken again.
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  pool.Stop();
  for (const store::StartTask& task : *(*jobs)->ListStartTasks(job->id)) {
    EXPECT_EQ(task.attempts, 1) << "start " << task.index;
    EXPECT_EQ(task.state, store::StartTaskState::kRunning) << "start " << task.index;
  }
}

TEST(StartTasks, ATaskClaimedTooOftenFailsItsJobNamingTheStart) {
  JobRunnerContext context;
  context.max_attempts = 3;
  std::vector<store::StartTask> tasks(3);
  for (int i = 0; i < 3; ++i) tasks[i].index = i;
  tasks[0].state = store::StartTaskState::kDone;
  tasks[0].attempts = 9;  // finished: however often it was claimed
  tasks[1].attempts = 6;  // shutdowns and lost workers, within the margin
  EXPECT_TRUE(CheckTaskAttempts(tasks, context).ok());
  tasks[2].attempts = 7;
  const Status failed = CheckTaskAttempts(tasks, context);
  EXPECT_EQ(failed.code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(failed.message(), "start 2 did not finish in 7 claims by workers (see their logs)");
}

}  // namespace
}  // namespace softid::server
