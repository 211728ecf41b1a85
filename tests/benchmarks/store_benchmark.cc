// The job store's throughput and claim latency, SQLite (the single-node default, a file) against
// PostgreSQL (the shared store of several processes), with 1 and 4 threads calling at once as
// worker threads do. PostgreSQL runs when SOFTID_TEST_POSTGRES_URL names a server, as
// tests/server/with_postgres.sh sets it:
//   bash tests/server/with_postgres.sh build/tests/benchmarks/softid_store_benchmarks
// Each case works in a store of its own (a fresh SQLite file, a fresh PostgreSQL database).
#include <benchmark/benchmark.h>
#include <unistd.h>

#include <atomic>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <mutex>
#include <string>

#include "server/store/postgres_job_store.h"
#include "server/store/sha256.h"
#include "server/store/sqlite_job_store.h"
#include "tests/server/postgres_test_server.h"

namespace softid::server::store {
namespace {

namespace fs = std::filesystem;

enum Backend { kSqlite = 0, kPostgres = 1 };

// One store per benchmark case, shared by its threads; made by thread 0 before the others run.
class Shared {
 public:
  static Shared& Get() {
    static Shared shared;
    return shared;
  }

  // Opens a fresh store (thread 0, before the timed loop; the other threads take it inside the
  // loop, after the barrier that starts it).
  void Open(Backend backend, const std::string& name) {
    Close();
    if (backend == kSqlite) {
      directory_ = fs::temp_directory_path() / ("softid-store-bench-" + std::to_string(::getpid()));
      fs::remove_all(directory_);
      fs::create_directories(directory_);
      Result<std::unique_ptr<SqliteJobStore>> opened = SqliteJobStore::Open(directory_ / "jobs.db");
      if (opened.ok()) store_ = std::move(opened).value();
    } else {
      database_key_ = "bench-" + name;
      Result<std::string> url = testing::TestDatabase(database_key_);
      if (url.ok()) {
        PostgresJobStoreOptions options;
        options.max_connections = 8;
        Result<std::unique_ptr<PostgresJobStore>> opened = PostgresJobStore::Open(*url, options);
        if (opened.ok()) store_ = std::move(opened).value();
      }
    }
    if (store_ == nullptr) return;
    Result<Capture> capture =
        store_->CreateCapture({{"capture.json", Sha256::Hex("bench"), 812}}, "");
    capture_id_ = capture.ok() ? capture->id : "";
  }

  JobStore* store() const { return store_.get(); }
  const std::string& capture_id() const { return capture_id_; }

  void Close() {
    store_.reset();
    if (!directory_.empty()) fs::remove_all(directory_);
    directory_.clear();
    if (!database_key_.empty()) (void)testing::DropTestDatabase(database_key_);
    database_key_.clear();
  }

 private:
  std::unique_ptr<JobStore> store_;
  fs::path directory_;
  std::string database_key_;
  std::string capture_id_;
};

// Every thread decides alike, before any of them waits for the others.
bool Available(benchmark::State& state, Backend backend) {
  if (backend == kPostgres && testing::PostgresUnavailable()) {
    state.SkipWithError("PostgreSQL: SOFTID_TEST_POSTGRES_URL is not set (with_postgres.sh)");
    return false;
  }
  return true;
}

ProgressEvent OneIteration() {
  ProgressEvent event;
  event.kind = ProgressKind::kIteration;
  event.iteration = 1;
  event.cost = 1e-6;
  event.gradient_norm = 1e-3;
  event.parameters = {{"youngs_modulus", 2.1e4}};
  event.elapsed_s = 0.1;
  return event;
}

// A job's whole life through the store, as the service drives it: created (API), claimed, one
// progress event, completed (worker). jobs_per_second: completed jobs per second of all threads.
void BM_JobLife(benchmark::State& state, Backend backend) {
  if (!Available(state, backend)) return;
  Shared& shared = Shared::Get();
  if (state.thread_index() == 0) shared.Open(backend, "life");
  JobStore* store = nullptr;
  const std::string worker = "worker-" + std::to_string(state.thread_index());
  const nlohmann::json config = {{"fit", {"youngs_modulus"}}};
  const ProgressEvent event = OneIteration();
  int64_t completed = 0;
  for (auto _ : state) {
    if (store == nullptr && (store = shared.store()) == nullptr) {
      state.SkipWithError("cannot open the store");
      break;
    }
    Result<Job> created = store->CreateJob(shared.capture_id(), config, "");
    Result<std::optional<Job>> claimed = store->ClaimNextJob(worker, std::chrono::seconds(60));
    if (!created.ok() || !claimed.ok()) {
      state.SkipWithError("create or claim failed");
      break;
    }
    // With several threads another may have taken the job just created: it finishes it.
    if (!claimed->has_value()) continue;
    const std::string& id = (**claimed).id;
    if (!store->AppendProgress(id, event).ok() ||
        !store->CompleteJob(id, {{"parameters", {}}}).ok()) {
      state.SkipWithError("progress or completion failed");
      break;
    }
    ++completed;
  }
  state.counters["jobs_per_second"] =
      benchmark::Counter(static_cast<double>(completed), benchmark::Counter::kIsRate);
  if (state.thread_index() == 0) shared.Close();
}

// ClaimNextJob alone (the job created outside the timing): a worker's wait for its next job when
// one is queued. items_per_second: claims per second of all threads.
void BM_Claim(benchmark::State& state, Backend backend) {
  if (!Available(state, backend)) return;
  Shared& shared = Shared::Get();
  if (state.thread_index() == 0) shared.Open(backend, "claim");
  JobStore* store = nullptr;
  const std::string worker = "worker-" + std::to_string(state.thread_index());
  for (auto _ : state) {
    if (store == nullptr && (store = shared.store()) == nullptr) {
      state.SkipWithError("cannot open the store");
      break;
    }
    state.PauseTiming();
    const bool created = store->CreateJob(shared.capture_id(), {{"fit", {"e"}}}, "").ok();
    state.ResumeTiming();
    // Another thread may take the job just created; this claim then takes another, or none.
    Result<std::optional<Job>> claimed = store->ClaimNextJob(worker, std::chrono::seconds(60));
    if (!created || !claimed.ok()) {
      state.SkipWithError("create or claim failed");
      break;
    }
  }
  state.SetItemsProcessed(state.iterations());
  if (state.thread_index() == 0) shared.Close();
}

BENCHMARK_CAPTURE(BM_JobLife, sqlite, kSqlite)->Threads(1)->Threads(4)->UseRealTime();
BENCHMARK_CAPTURE(BM_JobLife, postgres, kPostgres)->Threads(1)->Threads(4)->UseRealTime();
BENCHMARK_CAPTURE(BM_Claim, sqlite, kSqlite)->Threads(1)->Threads(4)->UseRealTime();
BENCHMARK_CAPTURE(BM_Claim, postgres, kPostgres)->Threads(1)->Threads(4)->UseRealTime();

}  // namespace
}  // namespace softid::server::store

BENCHMARK_MAIN();
