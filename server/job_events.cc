#include "server/job_events.h"

namespace softid::server {

uint64_t JobEvents::Version(const std::string& job_id) {
  std::lock_guard lock(mutex_);
  auto it = versions_.find(job_id);
  return it == versions_.end() ? 0 : it->second;
}

void JobEvents::Notify(const std::string& job_id) {
  {
    std::lock_guard lock(mutex_);
    ++versions_[job_id];
  }
  changed_.notify_all();
}

void JobEvents::NotifyAll() {
  {
    std::lock_guard lock(mutex_);
    ++broadcasts_;
  }
  changed_.notify_all();
}

uint64_t JobEvents::WaitForChange(const std::string& job_id, uint64_t seen,
                                  std::chrono::milliseconds timeout) {
  std::unique_lock lock(mutex_);
  const uint64_t broadcasts = broadcasts_;
  changed_.wait_for(lock, timeout, [&] {
    auto it = versions_.find(job_id);
    const uint64_t now = it == versions_.end() ? 0 : it->second;
    return now != seen || broadcasts_ != broadcasts;
  });
  auto it = versions_.find(job_id);
  return it == versions_.end() ? 0 : it->second;
}

}  // namespace softid::server
