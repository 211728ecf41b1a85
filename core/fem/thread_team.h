// A fixed team of threads for the parallel regions of one simulation: Run(task) calls task(t) for
// every member t = 0 .. size() - 1, member 0 on the calling thread, and returns when all are done.
// The workers persist between regions, so a region costs a wake-up instead of a thread start.
// Between regions a worker first spins (for up to `spin` on the clock) watching for the next one,
// and only then sleeps on a condition variable; the caller waits for the members likewise. Spins
// that run out shrink (see Wait), so a team on busy cores falls back to sleeping. A
// sleeping worker's wake-up measured 50-90 us on the 2-core dev VM (an empty region after 200 us
// of serial work; 25 us back to back), and a contact step of a simulation runs ~80 regions (GMRES:
// two triangular solves and a product per iteration, two per assembly) separated by short serial
// stretches: spinning over those gaps keeps the workers awake for the next region.
//
// Thread-compatibility: one caller at a time (the simulation that owns the team).
#pragma once

#include <atomic>
#include <chrono>
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
  // Default spin before a worker sleeps: longer than the serial stretches between a simulation's
  // regions (Gram-Schmidt, Newton's bookkeeping: tens to hundreds of microseconds), short enough
  // that an idle team gives its cores back within a millisecond.
  static constexpr std::chrono::microseconds kDefaultSpin{500};
  explicit ThreadTeam(int size, std::chrono::microseconds spin = kDefaultSpin);
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
  // A waiter's current spin (each thread keeps its own).
  struct SpinBudget {
    std::chrono::nanoseconds spin;
    long waits = 0;
  };
  static constexpr long kWaitsPerSpinReset = 256;
  // A yield that returns this late means another thread had the core.
  static constexpr std::chrono::microseconds kPreempted{200};
  // Returns once done() holds: spins (yielding) for up to budget->spin, then sleeps on `wake`
  // under mutex_. A spin that ran out halves the budget; every kWaitsPerSpinReset waits it is
  // reset to spin_.
  template <typename Done>
  void Wait(const Done& done, std::condition_variable& wake, SpinBudget* budget);

  std::vector<std::thread> workers_;
  std::chrono::microseconds spin_;
  SpinBudget caller_budget_;
  // Sleeping waits go through the mutex (a waiter checks its condition under it, and whoever
  // changes that condition takes it before notifying), spinning ones read the atomics alone.
  std::mutex mutex_;
  std::condition_variable start_, done_;
  const std::function<void(int)>* task_ = nullptr;  // published by generation_ (release)
  std::atomic<long> generation_{0};  // counts regions; a worker runs each new one once
  std::atomic<int> running_{0};      // workers still inside the current region
  std::atomic<bool> stopping_{false};
  std::vector<std::exception_ptr> errors_;  // per member
  std::thread background_;
  std::atomic<bool> background_running_{false};  // the job has not finished yet
};

}  // namespace softid::fem
