// SqliteJobStore behaviour beyond the shared contract: several connections on one file, crashes
// of the process (simulated by closing without finishing, and by SIGKILL), backups.
#include "server/store/sqlite_job_store.h"

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <random>
#include <set>
#include <thread>

#include "server/store/sha256.h"
#include "server/store/sqlite_schema.h"
#include "tests/server/temp_dir.h"

namespace softid::server::store {
namespace {

namespace fs = std::filesystem;
using std::chrono::seconds;
using testing::TempDir;

std::unique_ptr<SqliteJobStore> OpenStore(const fs::path& path) {
  Result<std::unique_ptr<SqliteJobStore>> store = SqliteJobStore::Open(path);
  EXPECT_TRUE(store.ok()) << store.status().ToString();
  return store.ok() ? std::move(store).value() : nullptr;
}

std::string NewQueuedJob(SqliteJobStore& store) {
  static const std::vector<ManifestEntry> kManifest = {{"capture.json", Sha256::Hex("c"), 1}};
  const Result<Capture> capture = store.CreateCapture(kManifest, "");
  EXPECT_TRUE(capture.ok()) << capture.status().ToString();
  const Result<Job> job = store.CreateJob(capture->id, {{"model", "corotated"}}, "");
  EXPECT_TRUE(job.ok()) << job.status().ToString();
  return job.ok() ? job->id : "";
}

Result<int64_t> QueryInt(SqliteDatabase& db, const std::string& sql) {
  SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt, db.Prepare(sql));
  SOFTID_ASSIGN_OR_RETURN(const bool has_row, stmt.Step());
  if (!has_row) return Status::Internal("no row for " + sql);
  return stmt.ColumnInt64(0);
}

// A job claimed by a process that then went away (store closed without completing it) is
// requeued by RecoverAfterCrash after reopening, and FAILED once it used up max_attempts.
TEST(SqliteJobStore, JobOfACrashedProcessIsRecoveredOnReopen) {
  TempDir dir;
  const fs::path path = dir.path() / "jobs.db";
  std::string job_id;
  {
    auto store = OpenStore(path);
    job_id = NewQueuedJob(*store);
    ASSERT_TRUE(store->ClaimNextJob("worker-1", seconds(30))->has_value());
    ASSERT_TRUE(store->AppendProgress(job_id, {.iteration = 0, .cost = 2.0}).ok());
  }  // "crash": the store is dropped with the job RUNNING
  {
    auto store = OpenStore(path);
    EXPECT_EQ(store->GetJob(job_id)->state, JobState::kRunning);
    const Result<RecoverySummary> recovered =
        store->RecoverAfterCrash(2, RecoveryScope::kAllRunning);
    ASSERT_TRUE(recovered.ok());
    EXPECT_EQ(recovered->num_requeued, 1);
    EXPECT_EQ(store->GetJob(job_id)->state, JobState::kQueued);
    const auto claimed = store->ClaimNextJob("worker-2", seconds(30));
    ASSERT_TRUE(claimed.ok() && claimed->has_value());
    EXPECT_EQ((*claimed)->attempts, 2);
    ASSERT_TRUE(store->Close().ok());
  }
  {
    auto store = OpenStore(path);
    EXPECT_EQ(store->RecoverAfterCrash(2, RecoveryScope::kAllRunning)->num_failed, 1);
    const Job job = *store->GetJob(job_id);
    EXPECT_EQ(job.state, JobState::kFailed);
    EXPECT_NE(job.error.find("gave up after 2 attempt(s)"), std::string::npos) << job.error;
    // The first attempt's progress survived both restarts.
    const auto history = *store->ListProgress(job_id, 0);
    ASSERT_GE(history.size(), 4u);
    EXPECT_EQ(history[2].kind, ProgressKind::kIteration);
    EXPECT_EQ(history[2].attempt, 1);
    EXPECT_EQ(history[2].cost, 2.0);
  }
}

// Workers with their own connections to one file (as separate processes would have) never claim
// the same job, and together they claim all of them.
TEST(SqliteJobStore, SeparateConnectionsNeverClaimTheSameJob) {
  TempDir dir;
  const fs::path path = dir.path() / "jobs.db";
  std::set<std::string> created;
  {
    auto store = OpenStore(path);
    for (int i = 0; i < 50; ++i) created.insert(NewQueuedJob(*store));
  }
  constexpr int kNumWorkers = 4;
  std::vector<std::vector<std::string>> claimed(kNumWorkers);
  std::atomic<int> num_errors{0};
  std::vector<std::thread> workers;
  for (int w = 0; w < kNumWorkers; ++w) {
    workers.emplace_back([&, w] {
      auto store = OpenStore(path);
      if (store == nullptr) return;
      const std::string name = "worker-" + std::to_string(w);
      while (true) {
        const Result<std::optional<Job>> job = store->ClaimNextJob(name, seconds(30));
        if (!job.ok()) {
          ++num_errors;
          ADD_FAILURE() << job.status().ToString();
          return;
        }
        if (!job->has_value()) return;
        claimed[w].push_back((*job)->id);
        if (!store->CompleteJob((*job)->id, {{"by", name}}).ok()) ++num_errors;
      }
    });
  }
  for (std::thread& worker : workers) worker.join();
  EXPECT_EQ(num_errors.load(), 0);
  std::multiset<std::string> all;
  for (const auto& ids : claimed) all.insert(ids.begin(), ids.end());
  EXPECT_EQ(all.size(), 50u) << "a job was claimed twice or not at all";
  EXPECT_EQ(std::set<std::string>(all.begin(), all.end()), created);
  auto store = OpenStore(path);
  EXPECT_EQ(*store->CountJobs(JobState::kSucceeded), 50);
}

// Several processes (here threads with their own connections) creating the same new database at
// once all succeed, and the schema is created once.
TEST(SqliteJobStore, ConcurrentFirstOpenCreatesTheSchemaOnce) {
  TempDir dir;
  const fs::path path = dir.path() / "jobs.db";
  std::atomic<int> num_failures{0};
  std::vector<std::thread> openers;
  for (int i = 0; i < 4; ++i) {
    openers.emplace_back([&] {
      if (!SqliteJobStore::Open(path).ok()) ++num_failures;
    });
  }
  for (std::thread& opener : openers) opener.join();
  EXPECT_EQ(num_failures.load(), 0);
  Result<SqliteDatabase> db = SqliteDatabase::Open(path);
  ASSERT_TRUE(db.ok());
  EXPECT_EQ(*ReadSchemaVersion(*db), kSqliteSchemaVersion);
}

// Deleting a job removes its progress rows and checkpoint from the database, not just from view.
TEST(SqliteJobStore, DeleteCascadesToProgressAndCheckpoint) {
  TempDir dir;
  const fs::path path = dir.path() / "jobs.db";
  {
    auto store = OpenStore(path);
    const std::string job_id = NewQueuedJob(*store);
    ASSERT_TRUE(store->ClaimNextJob("w", seconds(30))->has_value());
    ASSERT_TRUE(store->AppendProgress(job_id, {.iteration = 0}).ok());
    ASSERT_TRUE(store->SaveCheckpoint(job_id, {{"iteration", 0}}).ok());
    ASSERT_TRUE(store->FailJob(job_id, "stopped").ok());
    ASSERT_TRUE(store->DeleteJob(job_id).ok());
  }
  Result<SqliteDatabase> db = SqliteDatabase::Open(path);
  ASSERT_TRUE(db.ok());
  EXPECT_EQ(*QueryInt(*db, "SELECT count(*) FROM progress"), 0);
  EXPECT_EQ(*QueryInt(*db, "SELECT count(*) FROM checkpoints"), 0);
  EXPECT_EQ(*QueryInt(*db, "SELECT count(*) FROM captures"), 1);
}

// Backup writes a consistent copy that opens as a store with the same jobs.
TEST(SqliteJobStore, BackupIsAnOpenableCopy) {
  TempDir dir;
  auto store = OpenStore(dir.path() / "jobs.db");
  const std::string job_id = NewQueuedJob(*store);
  ASSERT_TRUE(store->Backup(dir.path() / "backup.db").ok());
  const Status again = store->Backup(dir.path() / "backup.db");
  EXPECT_FALSE(again.ok()) << "VACUUM INTO must not overwrite an existing file";
  auto copy = OpenStore(dir.path() / "backup.db");
  ASSERT_NE(copy, nullptr);
  EXPECT_EQ(*copy->GetJob(job_id), *store->GetJob(job_id));
}

// A writer killed with SIGKILL at arbitrary points while appending progress (each append one
// transaction) leaves a database that opens, passes PRAGMA integrity_check and holds exactly the
// committed prefix of its progress: every append it reported as done, in order, no gaps.
TEST(SqliteJobStore, KilledWriterLeavesAConsistentPrefix) {
  TempDir dir;
  const fs::path path = dir.path() / "jobs.db";
  std::string job_id;
  {
    auto store = OpenStore(path);
    job_id = NewQueuedJob(*store);
    ASSERT_TRUE(store->ClaimNextJob("worker-1", seconds(3600))->has_value());
  }
  std::mt19937 random(12345);
  int next_iteration = 0;
  for (int round = 0; round < 3; ++round) {
    int fds[2];
    ASSERT_EQ(::pipe(fds), 0);
    const pid_t child = ::fork();
    ASSERT_GE(child, 0);
    if (child == 0) {
      // The child appends iterations forever, reporting each one after it committed. It must not
      // return into GoogleTest: every exit is _exit.
      ::close(fds[0]);
      Result<std::unique_ptr<SqliteJobStore>> store = SqliteJobStore::Open(path);
      if (!store.ok()) ::_exit(2);
      // A few KB per row so transactions span pages and WAL checkpoints happen during the run.
      std::vector<double> parameters(300);
      for (int i = next_iteration;; ++i) {
        for (size_t k = 0; k < parameters.size(); ++k) parameters[k] = i + 1e-3 * k;
        ProgressEvent event{.iteration = i, .cost = 1.0 / (i + 1), .parameters = parameters};
        if (!(*store)->AppendProgress(job_id, event).ok()) ::_exit(3);
        if (i % 10 == 0 && !(*store)->SaveCheckpoint(job_id, {{"iteration", i}}).ok()) ::_exit(4);
        if (::write(fds[1], &i, sizeof i) != sizeof i) ::_exit(5);
      }
    }
    ::close(fds[1]);
    int last_reported = -1;
    int value = 0;
    const int kill_after = next_iteration + 150 + static_cast<int>(random() % 100);
    while (last_reported < kill_after && ::read(fds[0], &value, sizeof value) == sizeof value) {
      last_reported = value;
    }
    ::usleep(random() % 2000);  // land the kill at a varying point of the next transaction
    ::kill(child, SIGKILL);
    while (::read(fds[0], &value, sizeof value) == sizeof value) last_reported = value;
    ::close(fds[0]);
    int wait_status = 0;
    ASSERT_EQ(::waitpid(child, &wait_status, 0), child);
    ASSERT_TRUE(WIFSIGNALED(wait_status) && WTERMSIG(wait_status) == SIGKILL)
        << "the writer stopped by itself (exit code "
        << (WIFEXITED(wait_status) ? WEXITSTATUS(wait_status) : -1) << ") before round " << round
        << " could kill it";

    {
      Result<SqliteDatabase> db = SqliteDatabase::Open(path);
      ASSERT_TRUE(db.ok()) << db.status().ToString();
      Result<SqliteStatement> check = db->Prepare("PRAGMA integrity_check");
      ASSERT_TRUE(check.ok());
      ASSERT_TRUE(*check->Step());
      EXPECT_EQ(check->ColumnText(0), "ok");
      EXPECT_FALSE(*check->Step());
      Result<SqliteStatement> foreign = db->Prepare("PRAGMA foreign_key_check");
      ASSERT_TRUE(foreign.ok());
      EXPECT_FALSE(*foreign->Step()) << "dangling foreign key after the kill";
    }
    auto store = OpenStore(path);
    ASSERT_NE(store, nullptr);
    const auto history = store->ListProgress(job_id, 0);
    ASSERT_TRUE(history.ok()) << history.status().ToString();
    int expected_iteration = 0;
    int64_t expected_seq = 1;
    for (const ProgressEvent& event : *history) {
      ASSERT_EQ(event.seq, expected_seq++) << "gap in the history";
      if (event.kind != ProgressKind::kIteration) continue;
      ASSERT_EQ(event.iteration, expected_iteration++) << "iterations out of order or missing";
      ASSERT_EQ(event.parameters.size(), 300u);
      ASSERT_EQ(event.parameters[299].get<double>(), event.iteration + 0.299);
    }
    const int last_stored = expected_iteration - 1;
    EXPECT_GE(last_stored, last_reported) << "a committed append was lost";
    EXPECT_LE(last_stored, last_reported + 1) << "more rows than the writer can have committed";
    const int checkpoint = (**store->LoadCheckpoint(job_id))["iteration"].get<int>();
    EXPECT_TRUE(checkpoint == last_stored / 10 * 10 || checkpoint == last_stored / 10 * 10 - 10)
        << "checkpoint " << checkpoint << " after iteration " << last_stored;
    EXPECT_EQ(store->GetJob(job_id)->state, JobState::kRunning);
    next_iteration = last_stored + 1;
  }
}

}  // namespace
}  // namespace softid::server::store
