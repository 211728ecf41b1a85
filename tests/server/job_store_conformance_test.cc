// The JobStore contract (job_store.h), written against the interface only so that every backend
// runs the same suite: the embedded SQLite store, and the PostgreSQL store on a server that
// tests/server/with_postgres.sh starts (ctest runs those cases as softid_store_tests.postgres; run
// alone, they skip).
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <functional>
#include <memory>
#include <set>
#include <thread>

#include "server/store/api_token.h"
#include "server/store/job_store.h"
#include "server/store/postgres_job_store.h"
#include "server/store/sha256.h"
#include "server/store/sqlite_job_store.h"
#include "tests/server/postgres_test_server.h"
#include "tests/server/temp_dir.h"

namespace softid::server::store {
namespace {

namespace fs = std::filesystem;
using std::chrono::milliseconds;
using std::chrono::seconds;
using testing::TempDir;

// A clock that advances 1 ms on every reading, so creation order is strict and deterministic, and
// that tests can move forward to expire leases. Thread-safe.
class SteppingClock {
 public:
  std::chrono::system_clock::time_point Now() {
    return std::chrono::system_clock::time_point(std::chrono::seconds(1'763'712'000)) +
           milliseconds(ticks_.fetch_add(1) + offset_ms_.load());
  }
  void Advance(milliseconds by) { offset_ms_ += by.count(); }
  Clock AsClock() {
    return [this] { return Now(); };
  }

 private:
  std::atomic<int64_t> ticks_{0};
  std::atomic<int64_t> offset_ms_{0};
};

struct Backend {
  std::string name;
  // Opens the store kept in `dir`; opening the same dir again reopens the same data.
  std::function<Result<std::unique_ptr<JobStore>>(const fs::path& dir, Clock clock)> open;
  // Removes what `open` made outside `dir`, once the test's stores are closed; may be empty.
  std::function<Status(const fs::path& dir)> remove = nullptr;
  // Why the backend cannot run here (the test skips), or nullopt; may be empty.
  std::function<std::optional<std::string>()> unavailable = nullptr;
};

// Names the backend in test output instead of dumping its bytes.
void PrintTo(const Backend& backend, std::ostream* out) {
  *out << backend.name;
}

const Backend kSqlite{"Sqlite",
                      [](const fs::path& dir, Clock clock) -> Result<std::unique_ptr<JobStore>> {
                        SqliteJobStoreOptions options;
                        options.clock = std::move(clock);
                        SOFTID_ASSIGN_OR_RETURN(std::unique_ptr<SqliteJobStore> store,
                                                SqliteJobStore::Open(dir / "jobs.db", options));
                        return std::unique_ptr<JobStore>(std::move(store));
                      }};

// A database per test directory on the server with_postgres.sh started.
const Backend kPostgres{"Postgres",
                        [](const fs::path& dir, Clock clock) -> Result<std::unique_ptr<JobStore>> {
                          SOFTID_ASSIGN_OR_RETURN(const std::string url,
                                                  testing::TestDatabase(dir.string()));
                          PostgresJobStoreOptions options;
                          options.clock = std::move(clock);
                          SOFTID_ASSIGN_OR_RETURN(std::unique_ptr<PostgresJobStore> store,
                                                  PostgresJobStore::Open(url, options));
                          return std::unique_ptr<JobStore>(std::move(store));
                        },
                        [](const fs::path& dir) { return testing::DropTestDatabase(dir.string()); },
                        testing::PostgresUnavailable};

std::vector<ManifestEntry> Manifest(const std::string& seed) {
  return {{"capture.json", Sha256::Hex(seed + "json"), 812},
          {"frames/cam0_0000.png", Sha256::Hex(seed + "png"), 614400}};
}

ProgressEvent Iteration(int iteration, double cost) {
  ProgressEvent event;
  event.kind = ProgressKind::kIteration;
  event.iteration = iteration;
  event.cost = cost;
  event.gradient_norm = cost / 10;
  event.parameters = {{"youngs_modulus_pa", 1e5 + iteration}, {"poisson_ratio", 0.45}};
  event.elapsed_s = 0.5 * iteration;
  return event;
}

class JobStoreConformance : public ::testing::TestWithParam<Backend> {
 protected:
  void SetUp() override {
    if (GetParam().unavailable) {
      if (const std::optional<std::string> why = GetParam().unavailable()) GTEST_SKIP() << *why;
    }
    store_ = Open();
    ASSERT_NE(store_, nullptr);
  }

  void TearDown() override {
    store_.reset();
    if (GetParam().remove && !IsSkipped()) {
      const Status removed = GetParam().remove(dir_.path());
      EXPECT_TRUE(removed.ok()) << removed.ToString();
    }
  }

  std::unique_ptr<JobStore> Open() {
    Result<std::unique_ptr<JobStore>> store = GetParam().open(dir_.path(), clock_.AsClock());
    EXPECT_TRUE(store.ok()) << store.status().ToString();
    return store.ok() ? std::move(store).value() : nullptr;
  }

  Capture NewCapture(const std::string& request_id = "") {
    Result<Capture> capture = store_->CreateCapture(Manifest("default"), request_id);
    EXPECT_TRUE(capture.ok()) << capture.status().ToString();
    return capture.ok() ? *capture : Capture{};
  }

  Job NewJob(const std::string& capture_id, const std::string& request_id = "",
             const nlohmann::json& config = {{"model", "corotated"}}) {
    Result<Job> job = store_->CreateJob(capture_id, config, request_id);
    EXPECT_TRUE(job.ok()) << job.status().ToString();
    return job.ok() ? *job : Job{};
  }

  // Claims the next job, which must exist.
  Job Claim(const std::string& worker = "worker-1", milliseconds lease = seconds(30)) {
    Result<std::optional<Job>> claimed = store_->ClaimNextJob(worker, lease);
    EXPECT_TRUE(claimed.ok()) << claimed.status().ToString();
    EXPECT_TRUE(claimed.ok() && claimed->has_value()) << "no job to claim";
    return claimed.ok() && claimed->has_value() ? **claimed : Job{};
  }

  JobState StateOf(const std::string& job_id) {
    Result<Job> job = store_->GetJob(job_id);
    EXPECT_TRUE(job.ok()) << job.status().ToString();
    return job.ok() ? job->state : JobState::kQueued;
  }

  std::vector<Job> AllPages(const ListJobsRequest& first, std::vector<size_t>* page_sizes) {
    std::vector<Job> jobs;
    ListJobsRequest request = first;
    for (int guard = 0; guard < 100; ++guard) {
      Result<JobPage> page = store_->ListJobs(request);
      EXPECT_TRUE(page.ok()) << page.status().ToString();
      if (!page.ok()) break;
      page_sizes->push_back(page->jobs.size());
      jobs.insert(jobs.end(), page->jobs.begin(), page->jobs.end());
      if (page->next_page_token.empty()) break;
      request.page_token = page->next_page_token;
    }
    return jobs;
  }

  TempDir dir_;
  SteppingClock clock_;
  std::unique_ptr<JobStore> store_;
};

// --- Captures --------------------------------------------------------------------------------

// Repeating a capture upload with its request_id returns the first capture; other request ids or
// none create new ones; the same request_id with another manifest is refused.
TEST_P(JobStoreConformance, CaptureCreationIsIdempotent) {
  const Capture first = NewCapture("upload-1");
  EXPECT_EQ(first.id.rfind("cap-", 0), 0u);
  EXPECT_EQ(first.manifest, Manifest("default"));
  EXPECT_EQ(*store_->GetCapture(first.id), first);
  EXPECT_EQ(NewCapture("upload-1"), first);
  EXPECT_NE(NewCapture("upload-2").id, first.id);
  EXPECT_NE(NewCapture().id, NewCapture().id);  // no request_id: never deduplicated

  const Result<Capture> conflict = store_->CreateCapture(Manifest("other"), "upload-1");
  ASSERT_FALSE(conflict.ok());
  EXPECT_EQ(conflict.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(conflict.status().message(),
            "request_id 'upload-1' was already used to create capture " + first.id +
                " with a different manifest");
}

// Unknown captures are NotFound, malformed ids and manifests InvalidArgument.
TEST_P(JobStoreConformance, CaptureErrors) {
  const Result<Capture> unknown = store_->GetCapture("cap-0000000000000000");
  EXPECT_EQ(unknown.status().code(), StatusCode::kNotFound);
  EXPECT_EQ(unknown.status().message(), "capture cap-0000000000000000 not found");
  EXPECT_EQ(store_->GetCapture("job-0000000000000000").status().code(),
            StatusCode::kInvalidArgument);
  auto manifest = Manifest("x");
  manifest[0].sha256 = "nope";
  const Result<Capture> invalid = store_->CreateCapture(manifest, "");
  EXPECT_EQ(invalid.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(invalid.status().message(),
            "manifest[0].sha256 = \"nope\": must be 64 lowercase hex digits");
}

// --- Creating jobs -----------------------------------------------------------------------------

// A new job is QUEUED with its config and no run history, and its history starts with "created".
TEST_P(JobStoreConformance, CreateJobStartsQueued) {
  const Capture capture = NewCapture();
  const nlohmann::json config = {{"model", "neo_hookean"}, {"max_num_iterations", 40}};
  const Job job = NewJob(capture.id, "", config);
  EXPECT_EQ(job.id.rfind("job-", 0), 0u);
  EXPECT_EQ(job.capture_id, capture.id);
  EXPECT_EQ(job.config, config);
  EXPECT_EQ(job.state, JobState::kQueued);
  EXPECT_EQ(job.attempts, 0);
  EXPECT_FALSE(job.cancel_requested);
  EXPECT_FALSE(job.started_at.has_value());
  EXPECT_FALSE(job.finished_at.has_value());
  EXPECT_FALSE(job.lease_expires_at.has_value());
  EXPECT_FALSE(job.result.has_value());
  EXPECT_EQ(*store_->GetJob(job.id), job);

  const auto history = store_->ListProgress(job.id, 0);
  ASSERT_TRUE(history.ok());
  ASSERT_EQ(history->size(), 1u);
  EXPECT_EQ((*history)[0].kind, ProgressKind::kState);
  EXPECT_EQ((*history)[0].state, JobState::kQueued);
  EXPECT_EQ((*history)[0].message, "created");
}

// The capture must exist and the config must be a JSON object.
TEST_P(JobStoreConformance, CreateJobValidatesItsArguments) {
  const Result<Job> orphan =
      store_->CreateJob("cap-0123456789abcdef", nlohmann::json::object(), "");
  EXPECT_EQ(orphan.status().code(), StatusCode::kNotFound);
  EXPECT_EQ(orphan.status().message(), "capture cap-0123456789abcdef not found");
  const Capture capture = NewCapture();
  const Result<Job> array = store_->CreateJob(capture.id, nlohmann::json::array({1}), "");
  EXPECT_EQ(array.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(array.status().message(), "config = [1]: must be a JSON object");
  EXPECT_EQ(store_->CreateJob(capture.id, {}, std::string(300, 'r')).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(*store_->CountJobs(std::nullopt), 0);
}

// A repeated create with the same request_id returns the original job, whatever its state now;
// reusing the request_id for another config or capture is refused.
TEST_P(JobStoreConformance, JobCreationIsIdempotent) {
  const Capture capture = NewCapture();
  const Job first = NewJob(capture.id, "create-1");
  Claim();
  const Result<Job> again = store_->CreateJob(capture.id, first.config, "create-1");
  ASSERT_TRUE(again.ok()) << again.status().ToString();
  EXPECT_EQ(again->id, first.id);
  EXPECT_EQ(again->state, JobState::kRunning);
  EXPECT_EQ(*store_->CountJobs(std::nullopt), 1);

  const Result<Job> other_config = store_->CreateJob(capture.id, {{"model", "other"}}, "create-1");
  EXPECT_EQ(other_config.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(other_config.status().message(),
            "request_id 'create-1' was already used to create job " + first.id +
                " with a different config");
  const Capture other = NewCapture();
  const Result<Job> other_capture = store_->CreateJob(other.id, first.config, "create-1");
  EXPECT_NE(other_capture.status().message().find("with a different capture"), std::string::npos);
  EXPECT_EQ(*store_->CountJobs(std::nullopt), 1);
}

// The bounded create refuses (nullopt, nothing created) once max_queued jobs are QUEUED; a
// repeated request_id still gets its job, and an unknown capture is still NotFound.
TEST_P(JobStoreConformance, CreateJobBoundedRefusesWhenTheQueueIsFull) {
  const Capture capture = NewCapture();
  const nlohmann::json config = {{"model", "corotated"}};
  EXPECT_EQ(store_->CreateJobBounded(capture.id, config, "", 0).status().code(),
            StatusCode::kInvalidArgument);
  const Result<std::optional<Job>> first = store_->CreateJobBounded(capture.id, config, "r-1", 2);
  ASSERT_TRUE(first.ok() && first->has_value()) << first.status().ToString();
  ASSERT_TRUE(store_->CreateJobBounded(capture.id, config, "", 2)->has_value());
  const Result<std::optional<Job>> full = store_->CreateJobBounded(capture.id, config, "r-2", 2);
  ASSERT_TRUE(full.ok()) << full.status().ToString();
  EXPECT_FALSE(full->has_value());
  EXPECT_EQ(*store_->CountJobs(std::nullopt), 2);

  const Result<std::optional<Job>> repeat = store_->CreateJobBounded(capture.id, config, "r-1", 2);
  ASSERT_TRUE(repeat.ok() && repeat->has_value()) << repeat.status().ToString();
  EXPECT_EQ((*repeat)->id, (*first)->id);
  EXPECT_EQ(store_->CreateJobBounded("cap-0123456789abcdef", config, "", 2).status().code(),
            StatusCode::kNotFound);

  Claim();  // one QUEUED job left: room for one more
  const Result<std::optional<Job>> after = store_->CreateJobBounded(capture.id, config, "r-2", 2);
  ASSERT_TRUE(after.ok() && after->has_value());
  EXPECT_EQ((*after)->request_id, "r-2");
  EXPECT_EQ(*store_->CountJobs(JobState::kQueued), 2);
}

// Concurrent bounded creates never overshoot the bound: the count and the insert are one
// transaction.
TEST_P(JobStoreConformance, CreateJobBoundedHoldsUnderConcurrency) {
  const Capture capture = NewCapture();
  constexpr int kNumThreads = 6;
  constexpr int kMaxQueued = 10;
  std::atomic<int> created{0};
  std::atomic<int> refused{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < kNumThreads; ++t) {
    threads.emplace_back([&] {
      for (int i = 0; i < 4; ++i) {
        Result<std::optional<Job>> job =
            store_->CreateJobBounded(capture.id, nlohmann::json::object(), "", kMaxQueued);
        EXPECT_TRUE(job.ok()) << job.status().ToString();
        if (job.ok()) ++(job->has_value() ? created : refused);
      }
    });
  }
  for (std::thread& thread : threads) thread.join();
  EXPECT_EQ(created.load(), kMaxQueued);
  EXPECT_EQ(refused.load(), kNumThreads * 4 - kMaxQueued);
  EXPECT_EQ(*store_->CountJobs(JobState::kQueued), kMaxQueued);
}

// Concurrent creates with one request_id make one capture and one job, which every caller gets:
// the lookup and the insert are one transaction.
TEST_P(JobStoreConformance, ConcurrentCreatesWithOneRequestIdMakeOneResource) {
  constexpr int kNumThreads = 6;
  std::vector<std::string> captures(kNumThreads), jobs(kNumThreads);
  std::vector<std::thread> threads;
  for (int t = 0; t < kNumThreads; ++t) {
    threads.emplace_back([&, t] {
      const Result<Capture> capture = store_->CreateCapture(Manifest("same"), "take-1", "lab-1");
      ASSERT_TRUE(capture.ok()) << capture.status().ToString();
      captures[t] = capture->id;
      const Result<Job> job = store_->CreateJob(capture->id, {{"cells", 8}}, "job-1", "lab-1");
      ASSERT_TRUE(job.ok()) << job.status().ToString();
      jobs[t] = job->id;
    });
  }
  for (std::thread& thread : threads) thread.join();
  EXPECT_EQ(std::set<std::string>(captures.begin(), captures.end()).size(), 1u);
  EXPECT_EQ(std::set<std::string>(jobs.begin(), jobs.end()).size(), 1u);
  EXPECT_EQ(*store_->CountJobs(std::nullopt), 1);
  EXPECT_EQ(store_->ListCaptures({})->captures.size(), 1u);
}

// --- Running jobs ------------------------------------------------------------------------------

// QUEUED -> RUNNING -> SUCCEEDED, with iteration progress, a checkpoint and the result; the
// history lists every state change and iteration in order.
TEST_P(JobStoreConformance, FullLifecycleWithProgress) {
  const Capture capture = NewCapture();
  const Job created = NewJob(capture.id);
  const Job running = Claim("worker-7", seconds(30));
  EXPECT_EQ(running.id, created.id);
  EXPECT_EQ(running.state, JobState::kRunning);
  EXPECT_EQ(running.attempts, 1);
  EXPECT_EQ(running.lease_owner, "worker-7");
  ASSERT_TRUE(running.started_at.has_value());
  ASSERT_TRUE(running.lease_expires_at.has_value());
  EXPECT_EQ(*running.lease_expires_at - *running.started_at, seconds(30));
  EXPECT_EQ(*store_->GetJob(created.id), running);

  for (int i = 0; i < 5; ++i) {
    const Result<int64_t> seq = store_->AppendProgress(created.id, Iteration(i, 100.0 / (i + 1)));
    ASSERT_TRUE(seq.ok()) << seq.status().ToString();
    EXPECT_EQ(*seq, 3 + i);  // after "created" and "claimed"
  }
  ASSERT_TRUE(store_->SaveCheckpoint(created.id, {{"iteration", 4}}).ok());
  const nlohmann::json result = {{"youngs_modulus_pa", 1.2e5}, {"final_cost", 0.01}};
  ASSERT_TRUE(store_->CompleteJob(created.id, result).ok());

  const Job done = *store_->GetJob(created.id);
  EXPECT_EQ(done.state, JobState::kSucceeded);
  EXPECT_EQ(done.result, result);
  ASSERT_TRUE(done.finished_at.has_value());
  EXPECT_GT(*done.finished_at, *done.started_at);
  EXPECT_TRUE(done.lease_owner.empty());
  EXPECT_FALSE(done.lease_expires_at.has_value());
  EXPECT_EQ(done.error, "");

  const auto history = store_->ListProgress(created.id, 0);
  ASSERT_TRUE(history.ok());
  ASSERT_EQ(history->size(), 8u);
  std::vector<std::string> kinds;
  for (size_t i = 0; i < history->size(); ++i) {
    const ProgressEvent& event = (*history)[i];
    EXPECT_EQ(event.seq, static_cast<int64_t>(i + 1));
    kinds.push_back(event.kind == ProgressKind::kState
                        ? ToString(*event.state)
                        : "iteration " + std::to_string(event.iteration));
  }
  EXPECT_EQ(kinds,
            (std::vector<std::string>{"QUEUED", "RUNNING", "iteration 0", "iteration 1",
                                      "iteration 2", "iteration 3", "iteration 4", "SUCCEEDED"}));
  const ProgressEvent& third = (*history)[4];
  EXPECT_EQ(third.attempt, 1);
  EXPECT_DOUBLE_EQ(third.cost, 100.0 / 3);
  EXPECT_DOUBLE_EQ(third.gradient_norm, 100.0 / 30);
  EXPECT_EQ(third.parameters, Iteration(2, 0).parameters);
  EXPECT_DOUBLE_EQ(third.elapsed_s, 1.0);
  EXPECT_EQ((*history)[7].iteration, 4);  // a state event carries the latest iteration

  // Resuming a watch from iteration 3 yields iterations 3 and 4 and what followed them.
  const auto tail = store_->ListProgress(created.id, 3);
  ASSERT_TRUE(tail.ok());
  ASSERT_EQ(tail->size(), 3u);
  EXPECT_EQ((*tail)[0].iteration, 3);
  EXPECT_EQ((*tail)[2].state, JobState::kSucceeded);
}

// Claims take the oldest QUEUED job first and find nothing once the queue is empty.
TEST_P(JobStoreConformance, ClaimsOldestFirst) {
  const Capture capture = NewCapture();
  std::vector<std::string> created;
  for (int i = 0; i < 3; ++i) created.push_back(NewJob(capture.id).id);
  std::vector<std::string> claimed;
  for (int i = 0; i < 3; ++i) claimed.push_back(Claim().id);
  EXPECT_EQ(claimed, created);
  const Result<std::optional<Job>> none = store_->ClaimNextJob("worker-1", seconds(30));
  ASSERT_TRUE(none.ok());
  EXPECT_FALSE(none->has_value());
  EXPECT_EQ(store_->ClaimNextJob("", seconds(30)).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(store_->ClaimNextJob("w", milliseconds(0)).status().code(),
            StatusCode::kInvalidArgument);
}

// Iteration events and checkpoints are only accepted while RUNNING; state notes at any time.
TEST_P(JobStoreConformance, ProgressOnlyWhileRunning) {
  const Capture capture = NewCapture();
  const Job job = NewJob(capture.id);
  const Result<int64_t> early = store_->AppendProgress(job.id, Iteration(0, 1.0));
  EXPECT_EQ(early.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(early.status().message(),
            "job " + job.id + " is QUEUED: iteration progress is only accepted while RUNNING");
  EXPECT_EQ(store_->SaveCheckpoint(job.id, {}).code(), StatusCode::kFailedPrecondition);

  ProgressEvent note;
  note.kind = ProgressKind::kState;
  note.message = "waiting for a worker";
  note.state = JobState::kSucceeded;  // ignored: the store records the actual state
  ASSERT_TRUE(store_->AppendProgress(job.id, note).ok());
  const auto history = store_->ListProgress(job.id, 0);
  ASSERT_TRUE(history.ok());
  EXPECT_EQ(history->back().message, "waiting for a worker");
  EXPECT_EQ(history->back().state, JobState::kQueued);

  Claim();
  ProgressEvent negative = Iteration(-1, 1.0);
  EXPECT_EQ(store_->AppendProgress(job.id, negative).status().code(), StatusCode::kInvalidArgument);
  ProgressEvent nan_cost = Iteration(0, std::nan(""));  // a diverged iteration is still recorded
  ASSERT_TRUE(store_->AppendProgress(job.id, nan_cost).ok());
  EXPECT_TRUE(std::isnan(store_->ListProgress(job.id, 0)->back().cost));
  ASSERT_TRUE(store_->FailJob(job.id, "diverged").ok());
  EXPECT_EQ(store_->AppendProgress(job.id, Iteration(1, 1.0)).status().code(),
            StatusCode::kFailedPrecondition);
}

// Every finishing transition requires RUNNING and says which state the job was in.
TEST_P(JobStoreConformance, TransitionsAreValidated) {
  const Capture capture = NewCapture();
  const Job queued = NewJob(capture.id);
  const Status complete_queued = store_->CompleteJob(queued.id, {});
  EXPECT_EQ(complete_queued.code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(complete_queued.message(),
            "job " + queued.id + " is QUEUED: only a RUNNING job can be completed");
  EXPECT_EQ(store_->FailJob(queued.id, "x").code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(store_->MarkCancelled(queued.id).code(), StatusCode::kFailedPrecondition);

  ASSERT_TRUE(store_->RequestCancel(queued.id).ok());
  const Status complete_cancelled = store_->CompleteJob(queued.id, {});
  EXPECT_EQ(complete_cancelled.message(),
            "job " + queued.id + " is CANCELLED: only a RUNNING job can be completed");

  const Job failing = NewJob(capture.id);
  Claim();
  EXPECT_EQ(store_->FailJob(failing.id, "").code(), StatusCode::kInvalidArgument);
  const Status no_request = store_->MarkCancelled(failing.id);
  EXPECT_EQ(no_request.message(), "job " + failing.id +
                                      " is RUNNING: no cancel was requested (use FailJob to stop "
                                      "for another reason)");
  ASSERT_TRUE(store_->FailJob(failing.id, "capture has no depth frames").ok());
  const Job failed = *store_->GetJob(failing.id);
  EXPECT_EQ(failed.state, JobState::kFailed);
  EXPECT_EQ(failed.error, "capture has no depth frames");
  EXPECT_TRUE(failed.finished_at.has_value());
  EXPECT_EQ(store_->CompleteJob(failing.id, {}).code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(store_->FailJob(failing.id, "again").code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(store_->GetJob(failing.id)->error, "capture has no depth frames");
}

// --- Cancelling --------------------------------------------------------------------------------

// A QUEUED job is cancelled at once and is never claimed.
TEST_P(JobStoreConformance, CancelQueuedJob) {
  const Capture capture = NewCapture();
  const Job job = NewJob(capture.id);
  const Result<Job> cancelled = store_->RequestCancel(job.id);
  ASSERT_TRUE(cancelled.ok());
  EXPECT_EQ(cancelled->state, JobState::kCancelled);
  EXPECT_TRUE(cancelled->finished_at.has_value());
  EXPECT_EQ(*store_->GetJob(job.id), *cancelled);
  EXPECT_TRUE(*store_->IsCancelRequested(job.id));
  EXPECT_FALSE(store_->ClaimNextJob("worker-1", seconds(30))->has_value());
}

// A RUNNING job gets a cancel request, which the worker sees and acknowledges.
TEST_P(JobStoreConformance, CancelRunningJob) {
  const Capture capture = NewCapture();
  const Job job = NewJob(capture.id);
  Claim();
  EXPECT_FALSE(*store_->IsCancelRequested(job.id));
  const Result<Job> requested = store_->RequestCancel(job.id);
  ASSERT_TRUE(requested.ok());
  EXPECT_EQ(requested->state, JobState::kRunning);
  EXPECT_TRUE(requested->cancel_requested);
  EXPECT_TRUE(store_->RequestCancel(job.id).ok());  // asking twice is harmless
  EXPECT_TRUE(*store_->IsCancelRequested(job.id));
  ASSERT_TRUE(store_->AppendProgress(job.id, Iteration(0, 1.0)).ok());  // until it notices
  ASSERT_TRUE(store_->MarkCancelled(job.id).ok());
  const Job cancelled = *store_->GetJob(job.id);
  EXPECT_EQ(cancelled.state, JobState::kCancelled);
  EXPECT_TRUE(cancelled.finished_at.has_value());
  EXPECT_TRUE(cancelled.lease_owner.empty());
  const auto history = *store_->ListProgress(job.id, 0);
  std::vector<std::string> messages;
  for (const ProgressEvent& event : history) {
    if (event.kind == ProgressKind::kState) messages.push_back(event.message);
  }
  EXPECT_EQ(messages[2], "cancel requested");
  EXPECT_EQ(messages.back(), "cancelled");
}

// Finished jobs cannot be cancelled.
TEST_P(JobStoreConformance, CancelFinishedJobFails) {
  const Capture capture = NewCapture();
  const Job succeeded = NewJob(capture.id);
  const Job failed = NewJob(capture.id);
  const Job cancelled = NewJob(capture.id);
  Claim();
  ASSERT_TRUE(store_->CompleteJob(succeeded.id, {{"ok", true}}).ok());
  Claim();
  ASSERT_TRUE(store_->FailJob(failed.id, "diverged").ok());
  ASSERT_TRUE(store_->RequestCancel(cancelled.id).ok());
  for (const auto& [job, state] : {std::pair{succeeded, "SUCCEEDED"}, std::pair{failed, "FAILED"},
                                   std::pair{cancelled, "CANCELLED"}}) {
    const Result<Job> again = store_->RequestCancel(job.id);
    EXPECT_EQ(again.status().code(), StatusCode::kFailedPrecondition);
    EXPECT_EQ(again.status().message(),
              "job " + job.id + " is " + state + ": a finished job cannot be cancelled");
  }
}

// --- Deleting ----------------------------------------------------------------------------------

// RUNNING jobs cannot be deleted; others can, with their history and checkpoint.
TEST_P(JobStoreConformance, DeleteRules) {
  const Capture capture = NewCapture();
  const Job running = NewJob(capture.id);
  const Job queued = NewJob(capture.id);
  Claim();
  ASSERT_TRUE(store_->SaveCheckpoint(running.id, {{"iteration", 1}}).ok());
  const Status refused = store_->DeleteJob(running.id);
  EXPECT_EQ(refused.code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(refused.message(), "job " + running.id +
                                   " is RUNNING: cancel it and wait until it stops before "
                                   "deleting it");
  ASSERT_TRUE(store_->DeleteJob(queued.id).ok());
  EXPECT_EQ(store_->GetJob(queued.id).status().code(), StatusCode::kNotFound);

  ASSERT_TRUE(store_->CompleteJob(running.id, {}).ok());
  ASSERT_TRUE(store_->DeleteJob(running.id).ok());
  EXPECT_EQ(store_->GetJob(running.id).status().message(), "job " + running.id + " not found");
  EXPECT_EQ(store_->ListProgress(running.id, 0).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->LoadCheckpoint(running.id).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->DeleteJob(running.id).code(), StatusCode::kNotFound);
  EXPECT_TRUE(store_->GetCapture(capture.id).ok());  // captures outlive their jobs
  EXPECT_EQ(*store_->CountJobs(std::nullopt), 0);
}

// --- Listing -----------------------------------------------------------------------------------

// Seven jobs in pages of three: 3 + 3 + 1, every job exactly once, in creation order.
TEST_P(JobStoreConformance, PaginationVisitsEveryJobOnceInOrder) {
  const Capture capture = NewCapture();
  std::vector<std::string> created;
  for (int i = 0; i < 7; ++i) created.push_back(NewJob(capture.id).id);
  std::vector<size_t> page_sizes;
  const std::vector<Job> listed = AllPages({.page_size = 3}, &page_sizes);
  EXPECT_EQ(page_sizes, (std::vector<size_t>{3, 3, 1}));
  std::vector<std::string> ids;
  for (const Job& job : listed) ids.push_back(job.id);
  EXPECT_EQ(ids, created);

  // An exact multiple of the page size ends without an empty extra page.
  page_sizes.clear();
  EXPECT_EQ(AllPages({.page_size = 7}, &page_sizes).size(), 7u);
  EXPECT_EQ(page_sizes, (std::vector<size_t>{7}));
  page_sizes.clear();
  EXPECT_EQ(AllPages({}, &page_sizes).size(), 7u);  // default page size
}

// A state filter lists only matching jobs, still in order, and a job created between pages
// shows up on a later page (keyset, not offset).
TEST_P(JobStoreConformance, PaginationFilteredByState) {
  const Capture capture = NewCapture();
  std::vector<std::string> created;
  for (int i = 0; i < 7; ++i) created.push_back(NewJob(capture.id).id);
  for (int i = 0; i < 3; ++i) Claim();
  std::vector<size_t> page_sizes;
  const std::vector<Job> queued =
      AllPages({.state = JobState::kQueued, .page_size = 3}, &page_sizes);
  ASSERT_EQ(queued.size(), 4u);
  EXPECT_EQ(page_sizes, (std::vector<size_t>{3, 1}));
  for (size_t i = 0; i < queued.size(); ++i) {
    EXPECT_EQ(queued[i].id, created[3 + i]);
    EXPECT_EQ(queued[i].state, JobState::kQueued);
  }
  page_sizes.clear();
  EXPECT_EQ(AllPages({.state = JobState::kRunning, .page_size = 2}, &page_sizes).size(), 3u);
  page_sizes.clear();
  EXPECT_TRUE(AllPages({.state = JobState::kFailed}, &page_sizes).empty());

  const Result<JobPage> first = store_->ListJobs({.page_size = 5});
  ASSERT_TRUE(first.ok());
  const std::string late = NewJob(capture.id).id;
  const Result<JobPage> second =
      store_->ListJobs({.page_size = 5, .page_token = first->next_page_token});
  ASSERT_TRUE(second.ok());
  ASSERT_EQ(second->jobs.size(), 3u);
  EXPECT_EQ(second->jobs[0].id, created[5]);
  EXPECT_EQ(second->jobs[2].id, late);
}

// Bad tokens and page sizes are InvalidArgument; oversized pages are capped.
TEST_P(JobStoreConformance, InvalidPageTokensAndSizes) {
  const Capture capture = NewCapture();
  for (int i = 0; i < 3; ++i) NewJob(capture.id);
  const Result<JobPage> garbage = store_->ListJobs({.page_token = "bm90IGEgdG9rZW4"});
  EXPECT_EQ(garbage.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(garbage.status().message().find("page_token = 'bm90IGEgdG9rZW4'"), std::string::npos);
  EXPECT_EQ(store_->ListJobs({.page_token = "%%%"}).status().code(), StatusCode::kInvalidArgument);

  const Result<JobPage> first = store_->ListJobs({.page_size = 1});
  ASSERT_TRUE(first.ok());
  const Result<JobPage> other_filter = store_->ListJobs(
      {.state = JobState::kQueued, .page_size = 1, .page_token = first->next_page_token});
  EXPECT_EQ(other_filter.status().code(), StatusCode::kInvalidArgument);

  const Result<JobPage> negative = store_->ListJobs({.page_size = -1});
  EXPECT_EQ(negative.status().message(), "page_size = -1: must not be negative");
  const Result<JobPage> huge = store_->ListJobs({.page_size = 1'000'000});
  ASSERT_TRUE(huge.ok());
  EXPECT_EQ(huge->jobs.size(), 3u);
}

// Request ids are per station: the same key from two stations makes two captures and two jobs;
// each station's repeat gets its own back.
TEST_P(JobStoreConformance, RequestIdsArePerStation) {
  Result<Capture> a = store_->CreateCapture(Manifest("a"), "take-1", "lab-a");
  Result<Capture> b = store_->CreateCapture(Manifest("b"), "take-1", "lab-b");
  ASSERT_TRUE(a.ok() && b.ok()) << a.status().ToString() << b.status().ToString();
  EXPECT_NE(a->id, b->id);
  EXPECT_EQ(store_->CreateCapture(Manifest("a"), "take-1", "lab-a")->id, a->id);
  EXPECT_EQ(store_->GetCapture(b->id)->request_id, "take-1");

  Result<Job> job_a = store_->CreateJob(a->id, {{"cells", 8}}, "job-1", "lab-a");
  Result<Job> job_b = store_->CreateJob(b->id, {{"cells", 8}}, "job-1", "lab-b");
  ASSERT_TRUE(job_a.ok() && job_b.ok()) << job_a.status().ToString() << job_b.status().ToString();
  EXPECT_NE(job_a->id, job_b->id);
  EXPECT_EQ(job_b->request_id, "job-1");
  EXPECT_EQ(store_->CreateJob(b->id, {{"cells", 8}}, "job-1", "lab-b")->id, job_b->id);
  EXPECT_TRUE(*store_->HasJobWithRequestId("job-1", "lab-a"));
  EXPECT_FALSE(*store_->HasJobWithRequestId("job-1", "lab-c"));
  // Within a station a key still names one job: other arguments are refused.
  EXPECT_EQ(store_->CreateJob(b->id, {{"cells", 9}}, "job-1", "lab-b").status().code(),
            StatusCode::kFailedPrecondition);
}

// Captures list in creation order across pages, all or one station's, each with the number of
// jobs that use it; a job list's token is refused here.
TEST_P(JobStoreConformance, CapturesListByStationWithTheirJobCounts) {
  std::vector<std::string> mine, all;
  for (int i = 0; i < 5; ++i) {
    const std::string owner = i % 2 == 0 ? "lab-1" : "lab-2";
    Result<Capture> capture =
        store_->CreateCapture(Manifest("capture-" + std::to_string(i)), "", owner);
    ASSERT_TRUE(capture.ok()) << capture.status().ToString();
    all.push_back(capture->id);
    if (owner == "lab-1") mine.push_back(capture->id);
  }
  NewJob(all[0]);
  NewJob(all[0]);
  NewJob(all[3]);

  const auto list = [&](std::optional<std::string> owner) {
    std::vector<CaptureListing> listed;
    ListCapturesRequest request{.owner = owner, .page_size = 2};
    while (true) {
      Result<CapturePage> page = store_->ListCaptures(request);
      EXPECT_TRUE(page.ok()) << page.status().ToString();
      if (!page.ok()) break;
      EXPECT_LE(page->captures.size(), 2u);
      listed.insert(listed.end(), page->captures.begin(), page->captures.end());
      if (page->next_page_token.empty()) break;
      request.page_token = page->next_page_token;
    }
    return listed;
  };
  const std::vector<CaptureListing> everything = list(std::nullopt);
  ASSERT_EQ(everything.size(), all.size());
  for (size_t i = 0; i < all.size(); ++i) {
    EXPECT_EQ(everything[i].capture.id, all[i]);
    EXPECT_EQ(everything[i].capture.manifest, Manifest("capture-" + std::to_string(i)));
    EXPECT_EQ(everything[i].num_jobs, i == 0 ? 2 : (i == 3 ? 1 : 0)) << i;
  }
  const std::vector<CaptureListing> lab1 = list("lab-1");
  ASSERT_EQ(lab1.size(), mine.size());
  for (size_t i = 0; i < mine.size(); ++i) {
    EXPECT_EQ(lab1[i].capture.id, mine[i]);
    EXPECT_EQ(lab1[i].capture.owner, "lab-1");
  }
  EXPECT_TRUE(list("nobody").empty());

  const Result<JobPage> jobs = store_->ListJobs({.page_size = 1});
  ASSERT_TRUE(jobs.ok());
  EXPECT_EQ(store_->ListCaptures({.page_token = jobs->next_page_token}).status().code(),
            StatusCode::kInvalidArgument);
  const Result<CapturePage> first = store_->ListCaptures({.page_size = 1});
  ASSERT_TRUE(first.ok());
  EXPECT_EQ(store_->ListCaptures({.owner = "lab-1", .page_token = first->next_page_token})
                .status()
                .code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(store_->ListCaptures({.page_size = -1}).status().message(),
            "page_size = -1: must not be negative");
}

// CountJobs counts per state and in total.
// A recording keeps its format; the capture a job derives from it is used by that job (not
// deletable, counted, not unused) until the job goes, and only its worker may record it.
TEST_P(JobStoreConformance, RecordingsAndDerivedCaptures) {
  Result<Capture> recording =
      store_->CreateCapture(Manifest("recording"), "", "lab-a", kRecordingFormat);
  ASSERT_TRUE(recording.ok()) << recording.status().ToString();
  EXPECT_EQ(store_->GetCapture(recording->id)->format, kRecordingFormat);
  EXPECT_EQ(store_->CreateCapture(Manifest("x"), "", "lab-a", "softid-other/1").status().code(),
            StatusCode::kInvalidArgument);
  const Capture derived = NewCapture();
  EXPECT_EQ(derived.format, kCaptureFormat);
  const Job job = NewJob(recording->id);
  EXPECT_EQ(store_->SetDerivedCapture(job.id, "worker-1", derived.id).code(),
            StatusCode::kFailedPrecondition);  // QUEUED: no worker holds it
  Claim("worker-1");
  EXPECT_EQ(store_->SetDerivedCapture(job.id, "worker-2", derived.id).code(),
            StatusCode::kFailedPrecondition);
  EXPECT_EQ(store_->SetDerivedCapture(job.id, "worker-1", "cap-0000000000000000").code(),
            StatusCode::kNotFound);
  ASSERT_TRUE(store_->SetDerivedCapture(job.id, "worker-1", derived.id).ok());
  EXPECT_EQ(store_->GetJob(job.id)->derived_capture_id, derived.id);

  const Result<Capture> refused = store_->DeleteCapture(derived.id);
  EXPECT_EQ(refused.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(refused.status().message().find(job.id), std::string::npos);
  Result<CapturePage> page = store_->ListCaptures({});
  ASSERT_TRUE(page.ok());
  for (const CaptureListing& listing : page->captures) EXPECT_EQ(listing.num_jobs, 1);
  clock_.Advance(seconds(10));
  EXPECT_TRUE(store_->ListUnusedCaptures(ToTimestamp(clock_.Now()))->empty());

  ASSERT_TRUE(store_->FailJob(job.id, "stop").ok());
  ASSERT_TRUE(store_->DeleteJob(job.id).ok());
  EXPECT_TRUE(store_->DeleteCapture(derived.id).ok());
  EXPECT_TRUE(store_->DeleteCapture(recording->id).ok());
}

TEST_P(JobStoreConformance, CountJobs) {
  const Capture capture = NewCapture();
  for (int i = 0; i < 4; ++i) NewJob(capture.id);
  Claim();
  EXPECT_EQ(*store_->CountJobs(JobState::kQueued), 3);
  EXPECT_EQ(*store_->CountJobs(JobState::kRunning), 1);
  EXPECT_EQ(*store_->CountJobs(JobState::kSucceeded), 0);
  EXPECT_EQ(*store_->CountJobs(std::nullopt), 4);
}

// --- Leases and recovery -----------------------------------------------------------------------

// Only the owner renews; an expired lease makes the job recoverable by the lease sweep, which
// leaves jobs with live leases alone.
TEST_P(JobStoreConformance, LeaseRenewalAndExpiry) {
  const Capture capture = NewCapture();
  const Job first = NewJob(capture.id);
  const Job second = NewJob(capture.id);
  Claim("worker-a", seconds(10));
  Claim("worker-b", seconds(60));
  const Status stolen = store_->RenewLease(first.id, "worker-b", seconds(10));
  EXPECT_EQ(stolen.code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(stolen.message(), "job " + first.id + " is leased to worker-a, not worker-b");

  clock_.Advance(seconds(8));
  ASSERT_TRUE(store_->RenewLease(first.id, "worker-a", seconds(10)).ok());
  clock_.Advance(seconds(8));  // 16 s after the claim: alive only thanks to the renewal
  EXPECT_EQ(store_->RecoverAfterCrash(3, RecoveryScope::kExpiredLeasesOnly)->total(), 0);
  clock_.Advance(seconds(5));
  const Result<RecoverySummary> swept =
      store_->RecoverAfterCrash(3, RecoveryScope::kExpiredLeasesOnly);
  ASSERT_TRUE(swept.ok());
  EXPECT_EQ(swept->num_requeued, 1);
  EXPECT_EQ(StateOf(first.id), JobState::kQueued);
  EXPECT_EQ(StateOf(second.id), JobState::kRunning);
  const Status lost = store_->RenewLease(first.id, "worker-a", seconds(10));
  EXPECT_EQ(lost.message(), "job " + first.id + " is QUEUED: only a RUNNING job has a lease");
}

// A job whose worker is lost is requeued until it has been claimed max_attempts times, then
// FAILED with an error that says so.
TEST_P(JobStoreConformance, RecoveryRequeuesThenFailsAfterMaxAttempts) {
  const Capture capture = NewCapture();
  const Job job = NewJob(capture.id);
  EXPECT_EQ(store_->RecoverAfterCrash(0, RecoveryScope::kAllRunning).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(store_->RecoverAfterCrash(2, RecoveryScope::kAllRunning)->total(), 0);

  EXPECT_EQ(Claim().attempts, 1);
  const Result<RecoverySummary> first = store_->RecoverAfterCrash(2, RecoveryScope::kAllRunning);
  ASSERT_TRUE(first.ok());
  EXPECT_EQ(first->num_requeued, 1);
  const Job requeued = *store_->GetJob(job.id);
  EXPECT_EQ(requeued.state, JobState::kQueued);
  EXPECT_EQ(requeued.attempts, 1);
  EXPECT_TRUE(requeued.lease_owner.empty());

  EXPECT_EQ(Claim().attempts, 2);
  ASSERT_TRUE(store_->AppendProgress(job.id, Iteration(0, 3.0)).ok());
  const Result<RecoverySummary> second = store_->RecoverAfterCrash(2, RecoveryScope::kAllRunning);
  ASSERT_TRUE(second.ok());
  EXPECT_EQ(second->num_failed, 1);
  const Job failed = *store_->GetJob(job.id);
  EXPECT_EQ(failed.state, JobState::kFailed);
  EXPECT_EQ(failed.error,
            "gave up after 2 attempt(s) (max_attempts 2): its worker was lost (the server "
            "restarted) while RUNNING");
  EXPECT_TRUE(failed.finished_at.has_value());
  const auto history = *store_->ListProgress(job.id, 0);
  EXPECT_EQ(history.back().state, JobState::kFailed);
  EXPECT_EQ(history.back().attempt, 2);
}

// A released job (graceful shutdown) is QUEUED again at once, and its attempt is not held against
// max_attempts: with max_attempts 1 it still runs again after a release, and fails only after a
// real loss.
TEST_P(JobStoreConformance, ReleaseRequeuesWithoutUsingAnAttempt) {
  const Capture capture = NewCapture();
  const Job job = NewJob(capture.id);
  EXPECT_EQ(store_->ReleaseJob(job.id, "worker-1", "shutdown").code(),
            StatusCode::kFailedPrecondition);  // QUEUED: nothing to release
  Claim("worker-1");
  ASSERT_TRUE(store_->AppendProgress(job.id, Iteration(0, 2.0)).ok());
  const Status foreign = store_->ReleaseJob(job.id, "worker-2", "shutdown");
  EXPECT_EQ(foreign.message(), "job " + job.id + " is leased to worker-1, not worker-2");
  ASSERT_TRUE(store_->ReleaseJob(job.id, "worker-1", "the server shut down").ok());
  const Job released = *store_->GetJob(job.id);
  EXPECT_EQ(released.state, JobState::kQueued);
  EXPECT_EQ(released.attempts, 1);
  EXPECT_EQ(released.released_attempts, 1);
  EXPECT_TRUE(released.lease_owner.empty());
  EXPECT_FALSE(released.lease_expires_at.has_value());
  const auto history = *store_->ListProgress(job.id, 0);
  EXPECT_EQ(history.back().state, JobState::kQueued);
  EXPECT_EQ(history.back().iteration, 0);
  EXPECT_EQ(history.back().message,
            "requeued: the server shut down during attempt 1 (not counted against max_attempts)");

  EXPECT_EQ(Claim("worker-1").attempts, 2);
  const Result<RecoverySummary> lost = store_->RecoverAfterCrash(1, RecoveryScope::kAllRunning);
  ASSERT_TRUE(lost.ok());
  EXPECT_EQ(lost->num_failed, 1);
  EXPECT_EQ(store_->GetJob(job.id)->error,
            "gave up after 1 attempt(s) (max_attempts 1): its worker was lost (the server "
            "restarted) while RUNNING");
}

// A release with a cancel pending ends the job CANCELLED instead of queueing it again.
TEST_P(JobStoreConformance, ReleaseHonoursPendingCancel) {
  const Capture capture = NewCapture();
  const Job job = NewJob(capture.id);
  Claim("worker-1");
  ASSERT_TRUE(store_->RequestCancel(job.id).ok());
  ASSERT_TRUE(store_->ReleaseJob(job.id, "worker-1", "the server shut down").ok());
  const Job cancelled = *store_->GetJob(job.id);
  EXPECT_EQ(cancelled.state, JobState::kCancelled);
  EXPECT_TRUE(cancelled.finished_at.has_value());
  EXPECT_EQ(cancelled.released_attempts, 0);
}

// Blobs listed by a stored capture are referenced; any other hash is not.
TEST_P(JobStoreConformance, IsBlobReferenced) {
  const std::vector<ManifestEntry> manifest = Manifest("default");
  EXPECT_FALSE(*store_->IsBlobReferenced(manifest[1].sha256));
  NewCapture();
  EXPECT_TRUE(*store_->IsBlobReferenced(manifest[0].sha256));
  EXPECT_TRUE(*store_->IsBlobReferenced(manifest[1].sha256));
  EXPECT_FALSE(*store_->IsBlobReferenced(Sha256::Hex("nothing")));
}

// A lost job that had a cancel pending ends CANCELLED instead of running again.
TEST_P(JobStoreConformance, RecoveryHonoursPendingCancel) {
  const Capture capture = NewCapture();
  const Job job = NewJob(capture.id);
  Claim();
  ASSERT_TRUE(store_->RequestCancel(job.id).ok());
  const Result<RecoverySummary> recovered =
      store_->RecoverAfterCrash(5, RecoveryScope::kAllRunning);
  ASSERT_TRUE(recovered.ok());
  EXPECT_EQ(recovered->num_cancelled, 1);
  EXPECT_EQ(StateOf(job.id), JobState::kCancelled);
}

// A checkpoint is replaced on each save and read back as saved; none before the first save.
TEST_P(JobStoreConformance, CheckpointsRoundTrip) {
  const Capture capture = NewCapture();
  const Job job = NewJob(capture.id);
  EXPECT_EQ(*store_->LoadCheckpoint(job.id), std::nullopt);
  Claim();
  ASSERT_TRUE(store_->SaveCheckpoint(job.id, {{"iteration", 3}, {"x", {1.5, 2.5}}}).ok());
  ASSERT_TRUE(store_->SaveCheckpoint(job.id, {{"iteration", 4}, {"x", {1.25, 2.75}}}).ok());
  const nlohmann::json expected = {{"iteration", 4}, {"x", {1.25, 2.75}}};
  EXPECT_EQ(*store_->LoadCheckpoint(job.id), expected);
  ASSERT_EQ(store_->RecoverAfterCrash(3, RecoveryScope::kAllRunning)->num_requeued, 1);
  EXPECT_EQ(*store_->LoadCheckpoint(job.id), expected);  // what the next attempt resumes from
  EXPECT_EQ(store_->LoadCheckpoint("job-0000000000000000").status().code(), StatusCode::kNotFound);
}

// Malformed ids are InvalidArgument everywhere, unknown ones NotFound.
TEST_P(JobStoreConformance, MalformedAndUnknownIds) {
  EXPECT_EQ(store_->GetJob("42").status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(store_->RequestCancel("job-xyz").status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(store_->DeleteJob("").code(), StatusCode::kInvalidArgument);
  const std::string unknown = "job-0123456789abcdef";
  EXPECT_EQ(store_->GetJob(unknown).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->RequestCancel(unknown).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->CompleteJob(unknown, {}).code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->IsCancelRequested(unknown).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->AppendProgress(unknown, Iteration(0, 1)).status().code(),
            StatusCode::kNotFound);
}

// --- API tokens (the TokenStore every backend also implements)
// ------------------------------------

// Tokens are found by their secret's hash, listed oldest first, and revoked once: a second revoke
// keeps the first time. Bad station names and hashes are refused, unknown ids NotFound.
TEST_P(JobStoreConformance, TokensAreFoundListedAndRevoked) {
  auto* tokens = dynamic_cast<TokenStore*>(store_.get());
  ASSERT_NE(tokens, nullptr) << GetParam().name << " does not implement TokenStore";
  const std::string first_hash = Sha256::Hex("first secret");
  const Timestamp expires = ToTimestamp(clock_.Now()) + std::chrono::hours(24);
  const Result<ApiToken> first = tokens->CreateToken("lab-1", false, expires, first_hash);
  ASSERT_TRUE(first.ok()) << first.status().ToString();
  EXPECT_EQ(first->id.rfind("tok-", 0), 0u);
  EXPECT_EQ(first->expires_at, expires);
  const Result<ApiToken> admin = tokens->CreateToken("hq", true, std::nullopt, Sha256::Hex("x"));
  ASSERT_TRUE(admin.ok()) << admin.status().ToString();

  EXPECT_EQ(**tokens->FindToken(first_hash), *first);
  EXPECT_FALSE(tokens->FindToken(Sha256::Hex("nobody's"))->has_value());
  EXPECT_EQ(*tokens->ListTokens(), (std::vector<ApiToken>{*first, *admin}));

  ASSERT_TRUE(tokens->RevokeToken(first->id).ok());
  const std::optional<Timestamp> revoked_at = (*tokens->FindToken(first_hash))->revoked_at;
  ASSERT_TRUE(revoked_at.has_value());
  ASSERT_TRUE(tokens->RevokeToken(first->id).ok());
  EXPECT_EQ((*tokens->FindToken(first_hash))->revoked_at, revoked_at);
  EXPECT_EQ(tokens->RevokeToken("tok-0123456789abcdef").code(), StatusCode::kNotFound);
  EXPECT_EQ(tokens->RevokeToken("job-0123456789abcdef").code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(tokens->CreateToken("a b", false, std::nullopt, first_hash).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(tokens->CreateToken("lab-2", false, std::nullopt, "nope").status().code(),
            StatusCode::kInvalidArgument);
}

// --- Durability and concurrency ----------------------------------------------------------------

// Closing and reopening keeps captures, jobs, history and checkpoints; a closed store refuses
// calls.
TEST_P(JobStoreConformance, ReopenKeepsEverything) {
  const Capture capture = NewCapture("upload");
  const Job job = NewJob(capture.id, "create");
  Claim();
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(store_->AppendProgress(job.id, Iteration(i, i)).ok());
  ASSERT_TRUE(store_->SaveCheckpoint(job.id, {{"iteration", 2}}).ok());
  const Job before = *store_->GetJob(job.id);
  const auto history_before = *store_->ListProgress(job.id, 0);
  ASSERT_TRUE(store_->Close().ok());
  EXPECT_TRUE(store_->Close().ok());
  EXPECT_EQ(store_->GetJob(job.id).status().code(), StatusCode::kFailedPrecondition);

  store_ = Open();
  ASSERT_NE(store_, nullptr);
  EXPECT_EQ(*store_->GetCapture(capture.id), capture);
  EXPECT_EQ(*store_->GetJob(job.id), before);
  const auto history_after = *store_->ListProgress(job.id, 0);
  ASSERT_EQ(history_after.size(), history_before.size());
  for (size_t i = 0; i < history_after.size(); ++i) {
    EXPECT_EQ(history_after[i].seq, history_before[i].seq);
    EXPECT_EQ(history_after[i].iteration, history_before[i].iteration);
    EXPECT_EQ(history_after[i].message, history_before[i].message);
    EXPECT_EQ(history_after[i].created_at, history_before[i].created_at);
  }
  EXPECT_EQ(**store_->LoadCheckpoint(job.id), (nlohmann::json{{"iteration", 2}}));
  EXPECT_EQ(NewCapture("upload").id, capture.id);  // idempotency survives too
}

// Several threads claiming from one store object each get distinct jobs, and all get claimed.
TEST_P(JobStoreConformance, ThreadsSharingAStoreNeverClaimTheSameJob) {
  const Capture capture = NewCapture();
  std::set<std::string> created;
  for (int i = 0; i < 40; ++i) created.insert(NewJob(capture.id).id);
  constexpr int kNumThreads = 4;
  std::vector<std::vector<std::string>> claimed(kNumThreads);
  std::vector<std::thread> threads;
  for (int t = 0; t < kNumThreads; ++t) {
    threads.emplace_back([&, t] {
      while (true) {
        Result<std::optional<Job>> job =
            store_->ClaimNextJob("worker-" + std::to_string(t), seconds(30));
        if (!job.ok() || !job->has_value()) break;
        claimed[t].push_back((*job)->id);
        EXPECT_TRUE(store_->AppendProgress((*job)->id, Iteration(0, 1.0)).ok());
      }
    });
  }
  for (std::thread& thread : threads) thread.join();
  std::multiset<std::string> all;
  for (const auto& ids : claimed) all.insert(ids.begin(), ids.end());
  EXPECT_EQ(all.size(), created.size());
  EXPECT_EQ(std::set<std::string>(all.begin(), all.end()), created);
}

// --- Start tasks (fan-out) ------------------------------------------------------------------

// The job's worker splits it; workers claim tasks in index order, complete them with results, and
// the list shows each task's state; splitting again is harmless, with another count refused.
TEST_P(JobStoreConformance, StartTasksAreSplitClaimedAndCompleted) {
  const Capture capture = NewCapture();
  const Job job = NewJob(capture.id);
  EXPECT_EQ(store_->CreateStartTasks(job.id, "worker-1", 3).code(),
            StatusCode::kFailedPrecondition);  // QUEUED: nobody holds it
  Claim("worker-1");
  EXPECT_EQ(store_->CreateStartTasks(job.id, "worker-2", 3).message(),
            "job " + job.id + " is leased to worker-1, not worker-2");
  EXPECT_EQ(store_->CreateStartTasks(job.id, "worker-1", 0).code(), StatusCode::kInvalidArgument);
  ASSERT_TRUE(store_->CreateStartTasks(job.id, "worker-1", 3).ok());
  ASSERT_TRUE(store_->CreateStartTasks(job.id, "worker-1", 3).ok());  // idempotent
  EXPECT_EQ(store_->CreateStartTasks(job.id, "worker-1", 4).message(),
            "job " + job.id + " has 3 start tasks already, not 4");

  Result<std::optional<StartTask>> first = store_->ClaimStartTask("worker-2", seconds(30));
  ASSERT_TRUE(first.ok() && first->has_value()) << first.status().ToString();
  EXPECT_EQ((*first)->job_id, job.id);
  EXPECT_EQ((*first)->index, 0);
  EXPECT_EQ((*first)->state, StartTaskState::kRunning);
  EXPECT_EQ((*first)->attempts, 1);
  EXPECT_EQ((*first)->lease_owner, "worker-2");
  Result<std::optional<StartTask>> second = store_->ClaimStartTask("worker-1", seconds(30), job.id);
  ASSERT_TRUE(second.ok() && second->has_value());
  EXPECT_EQ((*second)->index, 1);

  const nlohmann::json result = {{"index", 0}, {"final_cost", 1.25e-7}};
  EXPECT_EQ(store_->CompleteStartTask(job.id, 0, "worker-1", result).message(),
            "start task 0 of job " + job.id + " is leased to worker-2, not held by worker-1");
  ASSERT_TRUE(store_->CompleteStartTask(job.id, 0, "worker-2", result).ok());
  EXPECT_EQ(store_->CompleteStartTask(job.id, 0, "worker-2", result).message(),
            "start task 0 of job " + job.id + " is DONE, not held by worker-2");
  EXPECT_EQ(store_->RenewStartTask(job.id, 7, "worker-2", seconds(30)).code(),
            StatusCode::kNotFound);

  Result<std::vector<StartTask>> tasks = store_->ListStartTasks(job.id);
  ASSERT_TRUE(tasks.ok()) << tasks.status().ToString();
  ASSERT_EQ(tasks->size(), 3u);
  EXPECT_EQ((*tasks)[0].state, StartTaskState::kDone);
  EXPECT_EQ((*tasks)[0].result, result);
  EXPECT_TRUE((*tasks)[0].lease_owner.empty());
  EXPECT_EQ((*tasks)[1].state, StartTaskState::kRunning);
  EXPECT_EQ((*tasks)[2].state, StartTaskState::kQueued);
  EXPECT_FALSE((*tasks)[2].result.has_value());
  // Another job without tasks lists none; an unknown job is NotFound.
  EXPECT_TRUE(store_->ListStartTasks(NewJob(capture.id).id)->empty());
  EXPECT_EQ(store_->ListStartTasks("job-0123456789abcdef").status().code(), StatusCode::kNotFound);
}

// A task whose worker stops renewing is claimed again once its lease expired, by anyone; its old
// worker can no longer renew or complete it. A released task is claimable at once.
TEST_P(JobStoreConformance, StartTasksOfALostWorkerAreClaimedAgain) {
  const Capture capture = NewCapture();
  const Job job = NewJob(capture.id);
  Claim("worker-1");
  ASSERT_TRUE(store_->CreateStartTasks(job.id, "worker-1", 2).ok());
  ASSERT_TRUE(store_->ClaimStartTask("worker-a", seconds(10))->has_value());
  ASSERT_TRUE(store_->ClaimStartTask("worker-b", seconds(10))->has_value());
  EXPECT_FALSE(store_->ClaimStartTask("worker-c", seconds(10))->has_value());
  clock_.Advance(seconds(8));
  ASSERT_TRUE(store_->RenewStartTask(job.id, 1, "worker-b", seconds(10)).ok());
  clock_.Advance(seconds(4));  // task 0's lease expired, task 1's was renewed
  Result<std::optional<StartTask>> again = store_->ClaimStartTask("worker-c", seconds(10));
  ASSERT_TRUE(again.ok() && again->has_value());
  EXPECT_EQ((*again)->index, 0);
  EXPECT_EQ((*again)->attempts, 2);
  EXPECT_EQ(store_->RenewStartTask(job.id, 0, "worker-a", seconds(10)).code(),
            StatusCode::kFailedPrecondition);
  ASSERT_TRUE(store_->ReleaseStartTask(job.id, 1, "worker-b").ok());
  EXPECT_EQ(store_->ReleaseStartTask(job.id, 1, "worker-b").code(),
            StatusCode::kFailedPrecondition);
  Result<std::optional<StartTask>> released = store_->ClaimStartTask("worker-c", seconds(10));
  ASSERT_TRUE(released.ok() && released->has_value());
  EXPECT_EQ((*released)->index, 1);
}

// Only tasks of RUNNING jobs without a cancel request are handed out; a cancel stops the renewal
// of running ones; tasks survive a requeue of their job (the next attempt keeps those DONE) and go
// with a deleted job.
TEST_P(JobStoreConformance, StartTasksFollowTheirJob) {
  const Capture capture = NewCapture();
  const Job job = NewJob(capture.id);
  Claim("worker-1", seconds(10));
  ASSERT_TRUE(store_->CreateStartTasks(job.id, "worker-1", 2).ok());
  ASSERT_TRUE(store_->ClaimStartTask("worker-a", seconds(60))->has_value());
  ASSERT_TRUE(store_->CompleteStartTask(job.id, 0, "worker-a", {{"done", true}}).ok());

  // The job's worker is lost: the job is QUEUED, its queued task not claimable meanwhile.
  clock_.Advance(seconds(11));
  ASSERT_EQ(store_->RecoverAfterCrash(3, RecoveryScope::kExpiredLeasesOnly)->num_requeued, 1);
  EXPECT_FALSE(store_->ClaimStartTask("worker-b", seconds(60))->has_value());
  Claim("worker-2");
  EXPECT_TRUE(store_->CreateStartTasks(job.id, "worker-2", 2).ok());
  Result<std::vector<StartTask>> kept = store_->ListStartTasks(job.id);
  ASSERT_TRUE(kept.ok());
  EXPECT_EQ((*kept)[0].state, StartTaskState::kDone);
  Result<std::optional<StartTask>> rest = store_->ClaimStartTask("worker-b", seconds(60));
  ASSERT_TRUE(rest.ok() && rest->has_value());
  EXPECT_EQ((*rest)->index, 1);

  ASSERT_TRUE(store_->RequestCancel(job.id).ok());
  EXPECT_EQ(store_->RenewStartTask(job.id, 1, "worker-b", seconds(60)).message(),
            "job " + job.id + " has a cancel request: its start tasks stop");
  ASSERT_TRUE(store_->ReleaseStartTask(job.id, 1, "worker-b").ok());
  EXPECT_FALSE(store_->ClaimStartTask("worker-c", seconds(60))->has_value());
  ASSERT_TRUE(store_->MarkCancelled(job.id).ok());
  ASSERT_TRUE(store_->DeleteJob(job.id).ok());
  EXPECT_EQ(store_->ListStartTasks(job.id).status().code(), StatusCode::kNotFound);
}

// Batches of other fits go after the job's starts: their tasks carry their inputs, take the next
// indexes and the same life cycle; adding a batch again returns its first index and keeps it (a
// requeued job's next attempt reuses what finished); another size or a bad name is refused.
TEST_P(JobStoreConformance, TaskBatchesFollowTheJobsStarts) {
  const Capture capture = NewCapture();
  const Job job = NewJob(capture.id);
  const std::vector<nlohmann::json> inputs = {{{"config", {{"starts", 1}}}},
                                              {{"config", {{"starts", 2}}}}};
  EXPECT_EQ(store_->CreateTaskBatch(job.id, "worker-1", "refits 1", inputs).status().code(),
            StatusCode::kFailedPrecondition);  // QUEUED: nobody holds it
  Claim("worker-1");
  ASSERT_TRUE(store_->CreateStartTasks(job.id, "worker-1", 2).ok());
  EXPECT_EQ(store_->CreateTaskBatch(job.id, "worker-1", "", inputs).status().message(),
            "batch = '': must be 1 to 100 printable ASCII characters");
  EXPECT_EQ(store_->CreateTaskBatch(job.id, "worker-1", "refits 1", {}).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(store_->CreateTaskBatch(job.id, "worker-2", "refits 1", inputs).status().code(),
            StatusCode::kFailedPrecondition);
  Result<int> first = store_->CreateTaskBatch(job.id, "worker-1", "refits 1", inputs);
  ASSERT_TRUE(first.ok()) << first.status().ToString();
  EXPECT_EQ(*first, 2);
  EXPECT_EQ(*store_->CreateTaskBatch(job.id, "worker-1", "refits 1", inputs), 2);  // kept
  EXPECT_EQ(store_->CreateTaskBatch(job.id, "worker-1", "refits 1", {inputs[0]}).status().message(),
            "job " + job.id + " has 2 tasks in batch 'refits 1' already, not 1");
  EXPECT_EQ(*store_->CreateTaskBatch(job.id, "worker-1", "refits 2", {inputs[1]}), 4);
  // The job's own starts still count alone.
  EXPECT_TRUE(store_->CreateStartTasks(job.id, "worker-1", 2).ok());

  Result<std::vector<StartTask>> tasks = store_->ListStartTasks(job.id);
  ASSERT_TRUE(tasks.ok()) << tasks.status().ToString();
  ASSERT_EQ(tasks->size(), 5u);
  EXPECT_EQ((*tasks)[1].batch, "");
  EXPECT_FALSE((*tasks)[1].input.has_value());
  EXPECT_EQ((*tasks)[3].batch, "refits 1");
  EXPECT_EQ((*tasks)[3].input, inputs[1]);
  EXPECT_EQ((*tasks)[4].batch, "refits 2");

  // Claimed in index order, completed like any task.
  for (int i = 0; i < 2; ++i)
    ASSERT_TRUE(store_->ClaimStartTask("worker-a", seconds(30))->has_value());
  Result<std::optional<StartTask>> refit = store_->ClaimStartTask("worker-b", seconds(30), job.id);
  ASSERT_TRUE(refit.ok() && refit->has_value());
  EXPECT_EQ((*refit)->index, 2);
  EXPECT_EQ((*refit)->batch, "refits 1");
  EXPECT_EQ((*refit)->input, inputs[0]);
  ASSERT_TRUE(store_->CompleteStartTask(job.id, 2, "worker-b", {{"cost", 1.0}}).ok());
  EXPECT_EQ(store_->ListStartTasks(job.id)->at(2).state, StartTaskState::kDone);
}

// Four threads claiming and completing the tasks of three jobs: each task is completed exactly
// once.
TEST_P(JobStoreConformance, ThreadsSharingAStoreNeverClaimTheSameStartTask) {
  const Capture capture = NewCapture();
  std::vector<std::string> jobs;
  for (int j = 0; j < 3; ++j) {
    jobs.push_back(NewJob(capture.id).id);
    Claim("owner-" + std::to_string(j));
    ASSERT_TRUE(store_->CreateStartTasks(jobs.back(), "owner-" + std::to_string(j), 8).ok());
  }
  std::atomic<int> completed{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] {
      const std::string worker = "worker-" + std::to_string(t);
      while (true) {
        Result<std::optional<StartTask>> task = store_->ClaimStartTask(worker, seconds(30));
        if (!task.ok() || !task->has_value()) break;
        const Status done =
            store_->CompleteStartTask((*task)->job_id, (*task)->index, worker, {{"by", worker}});
        EXPECT_TRUE(done.ok()) << done.ToString();
        if (done.ok()) ++completed;
      }
    });
  }
  for (std::thread& thread : threads) thread.join();
  EXPECT_EQ(completed.load(), 24);
  for (const std::string& job : jobs) {
    for (const StartTask& task : *store_->ListStartTasks(job)) {
      EXPECT_EQ(task.state, StartTaskState::kDone) << job << " " << task.index;
      EXPECT_EQ(task.attempts, 1);
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Backends, JobStoreConformance, ::testing::Values(kSqlite, kPostgres),
                         [](const ::testing::TestParamInfo<Backend>& info) {
                           return info.param.name;
                         });

}  // namespace
}  // namespace softid::server::store
