// N worker threads that claim QUEUED jobs from the store (with a lease) and run them
// (job_runner.h). Threads wait for a Wake() or poll the store at an interval, so jobs queued by
// another process sharing the database are picked up too.
//
// States: constructed (idle) -> Start() -> running -> Stop() -> stopped. Stop() stops claiming,
// interrupts running fits (their jobs are QUEUED again without using up an attempt, see
// JobStore::ReleaseJob) and joins the threads.
#pragma once

#include <spdlog/logger.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <filesystem>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "server/job_events.h"
#include "server/job_runner.h"
#include "server/metrics.h"
#include "server/store/blob_store.h"
#include "server/store/job_store.h"

namespace softid::server {

struct WorkerPoolOptions {
  int num_workers = 1;  // >= 0; 0 runs nothing (an API-only node)
  // A claimed job belongs to its worker this long without renewal. Long against the heartbeat so
  // a busy machine does not lose jobs; short enough that a lost worker's job is retried soon by
  // a periodic sweep (multi-node).
  std::chrono::milliseconds lease{60000};
  std::chrono::milliseconds heartbeat_interval{2000};
  // See JobRunnerContext::max_attempts.
  int max_attempts = 3;
  // How often an idle worker looks for jobs without a Wake().
  std::chrono::milliseconds idle_poll_interval{1000};
  std::filesystem::path work_root;
  // Worker ids are "<prefix>-<index>"; the prefix names the process (host and pid).
  std::string worker_id_prefix = "worker";
  // Where busy workers, queue waits, run times and iterations are counted; may be null.
  Metrics* metrics = nullptr;
  // See JobRunnerContext::blob_puts; may be null.
  std::shared_mutex* blob_puts = nullptr;
  // See JobRunnerContext::reports; may be null.
  const JobReports* reports = nullptr;
  // See JobRunnerContext::fan_out_starts. Workers run other jobs' start tasks either way.
  bool fan_out_starts = false;
};

class WorkerPool {
 public:
  // The stores and `events` must outlive the pool.
  WorkerPool(store::JobStore* jobs, const store::BlobStore* blobs, JobEvents* events,
             WorkerPoolOptions options, std::shared_ptr<spdlog::logger> logger);
  ~WorkerPool();  // Stop()
  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;

  void Start();
  // A job was queued: an idle worker claims it now rather than at its next poll.
  void Wake();
  // Work for every idle worker (a job split into start tasks): all of them look now.
  void WakeAll();
  // Idempotent.
  void Stop();

 private:
  void WorkerLoop(int index);
  // Claims a start task of a running job and runs it; false when there was none.
  bool RunOneStartTask(const std::string& worker_id);
  // FAILED for a job whose run threw.
  void RecordCrash(const std::string& job_id, const std::string& error);

  store::JobStore* jobs_;
  WorkerPoolOptions options_;
  JobRunnerContext context_;
  std::atomic<bool> stopping_{false};
  std::mutex mutex_;
  std::condition_variable wake_;
  uint64_t wakes_ = 0;                    // guarded by mutex_
  std::set<std::atomic<bool>*> running_;  // cancel flags of running fits; guarded by mutex_
  std::vector<std::thread> threads_;
};

}  // namespace softid::server
