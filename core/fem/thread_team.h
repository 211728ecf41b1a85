// A fixed team of threads for the parallel regions of one simulation: Run(task) calls task(t) for
// every member t = 0 .. size() - 1, member 0 on the calling thread, and returns when all are done.
// The workers persist between regions, so a region costs a wake-up (microseconds) instead of a
// thread start: regions as short as a preconditioner application (~1-3 ms) pay.
//
// Thread-compatibility: one caller at a time (the simulation that owns the team).
#pragma once

#include <atomic>
#include <condition_variable>
#include <exception>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace softid::fem {

class ThreadTeam {
 public:
  // size >= 1; a team of one runs every region on the caller and starts no thread. When the
  // system refuses a thread, the team is smaller than asked (size() tells).
  explicit ThreadTeam(int size);
  ~ThreadTeam();
  ThreadTeam(const ThreadTeam&) = delete;
  ThreadTeam& operator=(const ThreadTeam&) = delete;

  int size() const { return static_cast<int>(workers_.size()) + 1; }

  // Runs task(t) for t in [0, size()), concurrently; rethrows the first exception a member threw
  // once every member has finished. While a background job runs, the caller runs every member's
  // task itself, in member order: each task does the same work either way, so the results are
  // the same (only slower).
  void Run(const std::function<void(int)>& task);

  // Starts `job` on a thread of its own, to overlap with the caller's work; until it finishes the
  // team's members stay off the cores (see Run). One job at a time: a previous one is waited for
  // first. `job` must not throw.
  void StartBackground(std::function<void()> job);
  bool BackgroundRunning() const { return background_running_.load(std::memory_order_acquire); }
  // Waits for the background job, if any, to finish.
  void WaitForBackground();

 private:
  void WorkerLoop(int member);

  std::vector<std::thread> workers_;
  std::mutex mutex_;
  std::condition_variable start_, done_;
  const std::function<void(int)>* task_ = nullptr;
  long generation_ = 0;  // counts regions; a worker runs each new one once
  int running_ = 0;      // workers still inside the current region
  bool stopping_ = false;
  std::vector<std::exception_ptr> errors_;  // per member
  std::thread background_;
  std::atomic<bool> background_running_{false};  // the job has not finished yet
};

}  // namespace softid::fem
