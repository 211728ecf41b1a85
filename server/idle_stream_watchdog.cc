#include "server/idle_stream_watchdog.h"

#include <utility>
#include <vector>

namespace softid::server {

IdleStreamWatchdog::IdleStreamWatchdog(std::chrono::milliseconds idle_timeout,
                                       std::chrono::milliseconds poll)
    : idle_timeout_(idle_timeout), poll_(poll), thread_([this] { Loop(); }) {}

IdleStreamWatchdog::~IdleStreamWatchdog() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_all();
  thread_.join();
}

std::unique_ptr<IdleStreamWatchdog::Watch> IdleStreamWatchdog::Start(std::function<void()> cancel) {
  std::lock_guard lock(mutex_);
  const uint64_t id = next_id_++;
  entries_[id] = Entry{Clock::now(), std::move(cancel)};
  return std::unique_ptr<Watch>(new Watch(this, id));
}

void IdleStreamWatchdog::Watch::BeginWait() {
  std::lock_guard lock(owner_->mutex_);
  Entry& entry = owner_->entries_[id_];
  entry.waiting = true;
  entry.wait_began = Clock::now();
}

void IdleStreamWatchdog::Watch::EndWait() {
  std::lock_guard lock(owner_->mutex_);
  owner_->entries_[id_].waiting = false;
}

IdleStreamWatchdog::Watch::~Watch() {
  std::lock_guard lock(owner_->mutex_);
  owner_->entries_.erase(id_);
}

void IdleStreamWatchdog::Loop() {
  std::unique_lock lock(mutex_);
  while (!wake_.wait_for(lock, poll_, [this] { return stopping_; })) {
    const Clock::time_point now = Clock::now();
    for (auto& [id, entry] : entries_) {
      if (entry.cancelled || !entry.waiting || now - entry.wait_began < idle_timeout_) continue;
      // Under the lock, so the Watch (and the handler's context) cannot go away meanwhile.
      entry.cancelled = true;
      entry.cancel();
    }
  }
}

}  // namespace softid::server
