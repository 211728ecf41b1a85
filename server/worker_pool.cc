#include "server/worker_pool.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <exception>
#include <thread>

#include "server/log_context.h"
#include "server/start_tasks.h"

namespace softid::server {

namespace {

// A job began running: one more worker busy, and how long the job waited in the queue.
void CountJobStarted(Metrics* metrics, const store::Job& job) {
  if (metrics != nullptr) {
    metrics->AddBusyWorkers(1);
    if (job.started_at.has_value()) {
      metrics->ObserveQueueWait(
          std::chrono::duration<double>(*job.started_at - job.created_at).count());
    }
  }
}

// A job's run ended: its worker free again, and the run's outcome and duration.
void CountJobEnded(Metrics* metrics, const std::string& outcome_name,
                   std::chrono::steady_clock::time_point began) {
  if (metrics != nullptr) {
    metrics->AddBusyWorkers(-1);
    metrics->ObserveRun(
        outcome_name,
        std::chrono::duration<double>(std::chrono::steady_clock::now() - began).count());
  }
}

}  // namespace

WorkerPool::WorkerPool(store::JobStore* jobs, const store::BlobStore* blobs, JobEvents* events,
                       WorkerPoolOptions options, std::shared_ptr<spdlog::logger> logger)
    : jobs_(jobs), options_(std::move(options)) {
  context_.jobs = jobs;
  context_.blobs = blobs;
  context_.events = events;
  context_.work_root = options_.work_root;
  context_.lease = options_.lease;
  context_.max_attempts = options_.max_attempts;
  context_.heartbeat_interval = options_.heartbeat_interval;
  const int cores = static_cast<int>(std::thread::hardware_concurrency());
  context_.cores_per_job = cores > 0 ? std::max(1, cores / std::max(1, options_.num_workers)) : 0;
  context_.logger = logger ? std::move(logger) : spdlog::default_logger();
  context_.metrics = options_.metrics;
  context_.blob_puts = options_.blob_puts;
  context_.reports = options_.reports;
  context_.fan_out_starts = options_.fan_out_starts;
  context_.wake_workers = [this] { WakeAll(); };
  if (options_.metrics != nullptr) options_.metrics->SetWorkers(options_.num_workers);
}

WorkerPool::~WorkerPool() {
  Stop();
}

void WorkerPool::Start() {
  for (int i = 0; i < options_.num_workers; ++i) {
    threads_.emplace_back([this, i] { WorkerLoop(i); });
  }
  context_.logger->info("worker pool: {} worker(s) started, {} core(s) per job",
                        options_.num_workers, context_.cores_per_job);
}

void WorkerPool::Wake() {
  {
    std::lock_guard lock(mutex_);
    ++wakes_;
  }
  wake_.notify_one();
}

void WorkerPool::WakeAll() {
  {
    std::lock_guard lock(mutex_);
    ++wakes_;
  }
  wake_.notify_all();
}

void WorkerPool::Stop() {
  {
    std::lock_guard lock(mutex_);
    stopping_.store(true);
    for (std::atomic<bool>* cancel : running_) cancel->store(true);
  }
  wake_.notify_all();
  for (std::thread& thread : threads_) {
    if (thread.joinable()) thread.join();
  }
  threads_.clear();
}

void WorkerPool::RecordCrash(const std::string& job_id, const std::string& error) {
  // A job whose cancel was asked for ends CANCELLED however its fit stopped.
  if (Result<bool> requested = jobs_->IsCancelRequested(job_id); requested.ok() && *requested) {
    if (Status marked = jobs_->MarkCancelled(job_id); marked.ok()) {
      context_.events->Notify(job_id);
      return;
    }
  }
  if (Status failed = jobs_->FailJob(job_id, error); !failed.ok()) {
    context_.logger->error("job {}: cannot record the failure: {}", job_id, failed.message());
  }
  context_.events->Notify(job_id);
}

bool WorkerPool::RunOneStartTask(const std::string& worker_id) {
  Result<std::optional<store::StartTask>> task = jobs_->ClaimStartTask(worker_id, options_.lease);
  if (!task.ok()) {
    context_.logger->error("{}: cannot claim a start task: {}", worker_id, task.status().message());
  }
  if (!task.ok() || !task->has_value()) return false;
  std::atomic<bool> stop{false};
  {
    std::lock_guard lock(mutex_);
    if (stopping_.load()) stop.store(true);  // claimed while Stop ran: released at once
    running_.insert(&stop);
  }
  if (options_.metrics != nullptr) options_.metrics->AddBusyWorkers(1);
  const ScopedJobLog job_log((*task)->job_id);
  // Exceptions must not cross the thread boundary; the task's lease then expires and another
  // worker runs it.
  try {
    RunStartTask(**task, worker_id, context_, stop);
  } catch (const std::exception& e) {
    context_.logger->error("job {} start {}: internal error: {}", (*task)->job_id, (*task)->index,
                           e.what());
  }
  if (options_.metrics != nullptr) options_.metrics->AddBusyWorkers(-1);
  std::lock_guard lock(mutex_);
  running_.erase(&stop);
  return true;
}

void WorkerPool::WorkerLoop(int index) {
  const std::string worker_id = options_.worker_id_prefix + "-" + std::to_string(index);
  const auto& log = context_.logger;
  while (!stopping_.load()) {
    uint64_t seen_wakes = 0;
    {
      std::lock_guard lock(mutex_);
      seen_wakes = wakes_;
    }
    // Starts of running jobs first: they finish a job that is already under way.
    if (RunOneStartTask(worker_id)) continue;
    Result<std::optional<store::Job>> claimed = jobs_->ClaimNextJob(worker_id, options_.lease);
    if (!claimed.ok()) {
      log->error("{}: cannot claim a job: {}", worker_id, claimed.status().message());
    }
    if (!claimed.ok() || !claimed->has_value()) {
      std::unique_lock lock(mutex_);
      wake_.wait_for(lock, options_.idle_poll_interval,
                     [&] { return stopping_.load() || wakes_ != seen_wakes; });
      continue;
    }
    const store::Job& job = **claimed;
    context_.events->Notify(job.id);
    std::atomic<bool> cancel{false};
    {
      std::lock_guard lock(mutex_);
      // Claimed while Stop ran: interrupt at once; the runner releases it.
      if (stopping_.load()) cancel.store(true);
      running_.insert(&cancel);
    }
    Metrics* metrics = options_.metrics;
    const auto began = std::chrono::steady_clock::now();
    CountJobStarted(metrics, job);
    std::string outcome_name = "failed";
    const ScopedJobLog job_log(job.id);  // this thread's lines name the job, the core's too
    // Exceptions must not cross the thread boundary (they would terminate the server).
    try {
      const JobOutcome outcome = RunClaimedJob(job, worker_id, context_, cancel, stopping_);
      outcome_name = ToString(outcome);
      log->debug("job {}: {} on {}", job.id, ToString(outcome), worker_id);
    } catch (const std::exception& e) {
      log->error("job {}: internal error: {}", job.id, e.what());
      RecordCrash(job.id, std::string("internal error: ") + e.what());
    } catch (...) {
      log->error("job {}: internal error (unknown exception)", job.id);
      RecordCrash(job.id, "internal error (unknown exception)");
    }
    CountJobEnded(metrics, outcome_name, began);
    std::lock_guard lock(mutex_);
    running_.erase(&cancel);
  }
}

}  // namespace softid::server
