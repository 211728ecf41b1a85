#include "core/fem/thread_team.h"

#include <system_error>

#include "core/common/check.h"

namespace softid::fem {

ThreadTeam::ThreadTeam(int size, std::chrono::microseconds spin)
    : spin_(spin), caller_budget_{spin} {
  SOFTID_THROW_UNLESS(size >= 1, "thread team size = " + std::to_string(size) + " must be >= 1");
  SOFTID_THROW_UNLESS(spin.count() >= 0,
                      "thread team spin = " + std::to_string(spin.count()) + " us must be >= 0");
  workers_.reserve(size - 1);
  try {
    for (int member = 1; member < size; ++member)
      workers_.emplace_back([this, member] { WorkerLoop(member); });
  } catch (const std::system_error&) {
    // No more threads to be had: the team is smaller (size() tells).
  }
  errors_.resize(workers_.size() + 1);
}

ThreadTeam::~ThreadTeam() {
  WaitForBackground();
  {
    std::lock_guard lock(mutex_);
    stopping_.store(true, std::memory_order_release);
  }
  start_.notify_all();
  for (std::thread& worker : workers_) worker.join();
}

template <typename Done>
void ThreadTeam::Wait(const Done& done, std::condition_variable& wake, SpinBudget* budget) {
  if (done()) return;
  // Every so often the full spin is tried again: a machine busy for a while is quiet again later.
  if (++budget->waits % kWaitsPerSpinReset == 0) budget->spin = spin_;
  if (budget->spin.count() > 0) {
    auto now = std::chrono::steady_clock::now();
    const auto deadline = now + budget->spin;
    bool preempted = false;
    while (now < deadline && !preempted) {
      if (done()) return;
      // Yield between polls, and stop spinning once a yield gave the core away for long: then
      // the cores are oversubscribed, and a spinning waiter keeps out the very thread it waits
      // for (the sleeping one leaves its core idle, and the scheduler moves that thread there).
      std::this_thread::yield();
      const auto after = std::chrono::steady_clock::now();
      preempted = after - now > kPreempted;
      now = after;
    }
    if (done()) return;
  }
  // The spin ran out or was preempted: halve it, so that on busy cores waiting degrades to plain
  // sleeping instead of fighting for them.
  budget->spin =
      budget->spin >= std::chrono::microseconds(2) ? budget->spin / 2 : std::chrono::nanoseconds(0);
  std::unique_lock lock(mutex_);
  wake.wait(lock, done);
}

void ThreadTeam::Run(const std::function<void(int)>& task) {
  if (workers_.empty() || BackgroundRunning()) {
    for (int member = 0; member < size(); ++member) task(member);
    return;
  }
  task_ = &task;
  running_.store(static_cast<int>(workers_.size()), std::memory_order_relaxed);
  {
    std::lock_guard lock(mutex_);
    generation_.fetch_add(1, std::memory_order_release);
  }
  start_.notify_all();
  try {
    task(0);
  } catch (...) {
    errors_[0] = std::current_exception();
  }
  const auto all_done = [this] { return running_.load(std::memory_order_acquire) == 0; };
  Wait(all_done, done_, &caller_budget_);
  task_ = nullptr;
  std::exception_ptr first;
  for (std::exception_ptr& error : errors_) {
    if (error && !first) first = error;
    error = nullptr;
  }
  if (first) std::rethrow_exception(first);
}

void ThreadTeam::StartBackground(std::function<void()> job) {
  WaitForBackground();
  background_running_.store(true, std::memory_order_release);
  try {
    background_ = std::thread([this, job] {
      job();
      background_running_.store(false, std::memory_order_release);
    });
  } catch (const std::system_error&) {
    job();  // no thread to be had: the caller does the job now
    background_running_.store(false, std::memory_order_release);
  }
}

void ThreadTeam::WaitForBackground() {
  if (background_.joinable()) background_.join();
  background_running_.store(false, std::memory_order_release);
}

void ThreadTeam::WorkerLoop(int member) {
  long seen = 0;
  SpinBudget budget{spin_};
  const auto next_region = [&] {
    return stopping_.load(std::memory_order_acquire) ||
           generation_.load(std::memory_order_acquire) != seen;
  };
  while (true) {
    Wait(next_region, start_, &budget);
    if (stopping_.load(std::memory_order_acquire)) return;
    seen = generation_.load(std::memory_order_acquire);
    try {
      (*task_)(member);
    } catch (...) {
      errors_[member] = std::current_exception();
    }
    if (running_.fetch_sub(1, std::memory_order_acq_rel) == 1) {
      // The caller may be checking its condition under the mutex: taking it here means the caller
      // is either past the check (and sees 0) or already waiting (and is woken).
      { std::lock_guard lock(mutex_); }
      done_.notify_one();
    }
  }
}

}  // namespace softid::fem
