// Wakes watchers when a job's history grows. The store is the source of truth: a watcher re-reads
// the history after every wake-up and also at a fixed interval, so a missed notification (or a
// change made by another process sharing the database) only delays an event, never loses it.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <string>
#include <unordered_map>

namespace softid::server {

// Thread-safe.
class JobEvents {
 public:
  // The job's current version; pass it to WaitForChange.
  uint64_t Version(const std::string& job_id);
  // Something was written to the job's history or state.
  void Notify(const std::string& job_id);
  // Wakes every waiter (shutdown).
  void NotifyAll();
  // Blocks until the job's version differs from `seen`, NotifyAll is called, or `timeout`
  // passed. Returns the version at return.
  uint64_t WaitForChange(const std::string& job_id, uint64_t seen,
                         std::chrono::milliseconds timeout);

 private:
  std::mutex mutex_;
  std::condition_variable changed_;
  std::unordered_map<std::string, uint64_t> versions_;
  uint64_t broadcasts_ = 0;
};

}  // namespace softid::server
