#include "core/fem/thread_team.h"

#include <system_error>

#include "core/common/check.h"

namespace softid::fem {

ThreadTeam::ThreadTeam(int size) {
  SOFTID_THROW_UNLESS(size >= 1, "thread team size = " + std::to_string(size) + " must be >= 1");
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
    stopping_ = true;
  }
  start_.notify_all();
  for (std::thread& worker : workers_) worker.join();
}

void ThreadTeam::Run(const std::function<void(int)>& task) {
  if (workers_.empty() || BackgroundRunning()) {
    for (int member = 0; member < size(); ++member) task(member);
    return;
  }
  {
    std::lock_guard lock(mutex_);
    task_ = &task;
    running_ = static_cast<int>(workers_.size());
    ++generation_;
  }
  start_.notify_all();
  try {
    task(0);
  } catch (...) {
    errors_[0] = std::current_exception();
  }
  {
    std::unique_lock lock(mutex_);
    done_.wait(lock, [this] { return running_ == 0; });
    task_ = nullptr;
  }
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
  while (true) {
    const std::function<void(int)>* task = nullptr;
    {
      std::unique_lock lock(mutex_);
      start_.wait(lock, [&] { return stopping_ || generation_ != seen; });
      if (stopping_) return;
      seen = generation_;
      task = task_;
    }
    try {
      (*task)(member);
    } catch (...) {
      errors_[member] = std::current_exception();
    }
    bool last = false;
    {
      std::lock_guard lock(mutex_);
      last = --running_ == 0;
    }
    if (last) done_.notify_one();
  }
}

}  // namespace softid::fem
