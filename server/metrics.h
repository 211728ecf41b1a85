// The server's operational metrics in the Prometheus text format (version 0.0.4): jobs by state,
// queue wait and run time histograms, optimiser iterations, uploads and their bytes, refused
// calls by reason, busy workers. Hand-written because Debian ships no Prometheus client library
// for C++; the format is a few lines of text per metric. Thread-safe.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <map>
#include <mutex>
#include <string>
#include <string_view>

namespace softid::server {

class Metrics {
 public:
  // Upper bounds of the time histograms' buckets [s] (+Inf implied).
  static constexpr std::array<double, 9> kSecondsBuckets = {1,   5,    15,    60,   300,
                                                            900, 3600, 14400, 86400};

  // A call answered with an error; `code` is its status name (INVALID_ARGUMENT, ...).
  void CountRefused(std::string_view method, std::string_view code);
  // An upload that ended: stored (`bytes` of files) or not.
  void CountUpload(bool stored, int64_t bytes);
  void CountIteration() { iterations_.fetch_add(1, std::memory_order_relaxed); }
  // A job claimed after waiting `seconds` in the queue.
  void ObserveQueueWait(double seconds);
  // A job's run that ended with `outcome` (succeeded, failed, cancelled, interrupted, lost).
  void ObserveRun(std::string_view outcome, double seconds);
  void SetWorkers(int workers) { workers_.store(workers); }
  void AddBusyWorkers(int delta) { busy_workers_.fetch_add(delta); }

  // The exposition text; `jobs_by_state` is read from the store at scrape time.
  std::string Render(const std::map<std::string, int64_t>& jobs_by_state) const;

 private:
  struct Histogram {
    std::array<uint64_t, kSecondsBuckets.size()> buckets{};  // non-cumulative counts
    uint64_t count = 0;
    double sum = 0.0;
    void Observe(double value);
  };

  mutable std::mutex mutex_;
  std::map<std::pair<std::string, std::string>, uint64_t> refused_;  // (method, code)
  uint64_t uploads_stored_ = 0, uploads_failed_ = 0, upload_bytes_ = 0;
  Histogram queue_wait_;
  std::map<std::string, Histogram> run_by_outcome_;
  std::atomic<uint64_t> iterations_{0};
  std::atomic<int> workers_{0}, busy_workers_{0};
};

}  // namespace softid::server
