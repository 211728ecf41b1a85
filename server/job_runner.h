// Runs one claimed job to its end: lays the capture out in a private folder (a raw recording is
// ingested into a capture first, recording_ingest.h), runs the core fit
// with progress written to the store (and pushed to watchers) after every iteration, keeps the
// lease alive, stops on cancel, and records the outcome. A job's failure is its state and error;
// nothing here throws on bad input.
#pragma once

#include <spdlog/logger.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <functional>
#include <memory>
#include <shared_mutex>
#include <string>

#include "server/job_events.h"
#include "server/job_reports.h"
#include "server/metrics.h"
#include "server/store/blob_store.h"
#include "server/store/job_store.h"

namespace softid::server {

struct JobRunnerContext {
  store::JobStore* jobs = nullptr;
  const store::BlobStore* blobs = nullptr;
  JobEvents* events = nullptr;
  // Per-job folders <work_root>/<job id>, removed when the job ends.
  std::filesystem::path work_root;
  // A claim holds the job this long without renewal; see WorkerPoolOptions.
  std::chrono::milliseconds lease{60000};
  // How often the lease is renewed and a cancel request polled between iterations.
  std::chrono::milliseconds heartbeat_interval{2000};
  // Cores a job may use when its config leaves "threads" at 0 (every core): the machine's cores
  // shared among the workers, so parallel jobs do not oversubscribe it (a job's starts and its
  // simulations' teams take what it is given). 0: every core.
  int cores_per_job = 0;
  std::shared_ptr<spdlog::logger> logger;
  // Counts optimiser iterations; may be null.
  Metrics* metrics = nullptr;
  // Held shared while the capture ingested from a recording is stored (JobServiceOptions::
  // blob_puts); may be null when nothing removes blobs meanwhile.
  std::shared_mutex* blob_puts = nullptr;
  // Where a finished job's report (its PNGs) is kept; null: no report is drawn.
  const JobReports* reports = nullptr;
  // Runs a job's starts as tasks any worker can claim (start_tasks.h), instead of all of them
  // in the job's worker. For several worker processes sharing a store.
  bool fan_out_starts = false;
  // A start task claimed this many times over (its workers lost, or it could not run on them)
  // fails its job, as a job does after max_attempts lost workers (ServerOptions::max_attempts).
  int max_attempts = 3;
  // How often a job's worker looks whether the tasks running elsewhere have finished.
  std::chrono::milliseconds task_poll_interval{500};
  // Wakes this process's idle workers (new start tasks to claim); may be empty. Other processes'
  // workers find them at their next poll.
  std::function<void()> wake_workers;
};

enum class JobOutcome {
  kSucceeded,
  kFailed,
  kCancelled,
  // Stopped by a server shutdown: the job is QUEUED again (JobStore::ReleaseJob) without using
  // up an attempt, its progress history kept.
  kInterrupted,
  // The lease was lost (another worker may own the job now): nothing more is written.
  kLost,
};

const char* ToString(JobOutcome outcome);

// Runs `job` (just claimed by `worker_id`). `cancel` is the fit's stop flag: the caller sets it
// together with `shutdown` to interrupt the job; the runner sets it on a cancel request or a lost
// lease.
JobOutcome RunClaimedJob(const store::Job& job, const std::string& worker_id,
                         const JobRunnerContext& context, std::atomic<bool>& cancel,
                         const std::atomic<bool>& shutdown);

}  // namespace softid::server
