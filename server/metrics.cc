#include "server/metrics.h"

#include <fmt/format.h>

namespace softid::server {
namespace {

void AppendHistogram(std::string& out, std::string_view name, std::string_view labels,
                     const std::array<uint64_t, Metrics::kSecondsBuckets.size()>& buckets,
                     uint64_t count, double sum) {
  const std::string prefix = labels.empty() ? "" : std::string(labels) + ",";
  uint64_t cumulative = 0;
  for (size_t i = 0; i < buckets.size(); ++i) {
    cumulative += buckets[i];
    out += fmt::format("{}_bucket{{{}le=\"{:g}\"}} {}\n", name, prefix, Metrics::kSecondsBuckets[i],
                       cumulative);
  }
  out += fmt::format("{}_bucket{{{}le=\"+Inf\"}} {}\n", name, prefix, count);
  const std::string braces = labels.empty() ? "" : "{" + std::string(labels) + "}";
  out += fmt::format("{}_sum{} {:g}\n{}_count{} {}\n", name, braces, sum, name, braces, count);
}

}  // namespace

void Metrics::Histogram::Observe(double value) {
  ++count;
  sum += value;
  for (size_t i = 0; i < kSecondsBuckets.size(); ++i) {
    if (value <= kSecondsBuckets[i]) {
      ++buckets[i];
      return;
    }
  }
}

void Metrics::CountRefused(std::string_view method, std::string_view code) {
  std::lock_guard lock(mutex_);
  ++refused_[{std::string(method), std::string(code)}];
}

void Metrics::CountUpload(bool stored, int64_t bytes) {
  std::lock_guard lock(mutex_);
  if (stored) {
    ++uploads_stored_;
    upload_bytes_ += static_cast<uint64_t>(bytes);
  } else {
    ++uploads_failed_;
  }
}

void Metrics::ObserveQueueWait(double seconds) {
  std::lock_guard lock(mutex_);
  queue_wait_.Observe(seconds);
}

void Metrics::ObserveRun(std::string_view outcome, double seconds) {
  std::lock_guard lock(mutex_);
  run_by_outcome_[std::string(outcome)].Observe(seconds);
}

std::string Metrics::Render(const std::map<std::string, int64_t>& jobs_by_state) const {
  std::string out;
  out += "# HELP softid_jobs Jobs in the store by state.\n# TYPE softid_jobs gauge\n";
  for (const auto& [state, count] : jobs_by_state) {
    out += fmt::format("softid_jobs{{state=\"{}\"}} {}\n", state, count);
  }
  out += "# HELP softid_workers Worker threads of this process.\n# TYPE softid_workers gauge\n";
  out += fmt::format("softid_workers {}\n", workers_.load());
  out += "# HELP softid_workers_busy Workers running a job.\n# TYPE softid_workers_busy gauge\n";
  out += fmt::format("softid_workers_busy {}\n", busy_workers_.load());
  out +=
      "# HELP softid_iterations_total Optimiser iterations finished.\n"
      "# TYPE softid_iterations_total counter\n";
  out += fmt::format("softid_iterations_total {}\n", iterations_.load());
  std::lock_guard lock(mutex_);
  out += "# HELP softid_uploads_total Uploads by outcome.\n# TYPE softid_uploads_total counter\n";
  out += fmt::format("softid_uploads_total{{outcome=\"stored\"}} {}\n", uploads_stored_);
  out += fmt::format("softid_uploads_total{{outcome=\"failed\"}} {}\n", uploads_failed_);
  out +=
      "# HELP softid_upload_bytes_total Bytes of stored uploads.\n"
      "# TYPE softid_upload_bytes_total counter\n";
  out += fmt::format("softid_upload_bytes_total {}\n", upload_bytes_);
  out +=
      "# HELP softid_refused_requests_total Calls answered with an error, by method and code.\n"
      "# TYPE softid_refused_requests_total counter\n";
  for (const auto& [key, count] : refused_) {
    out += fmt::format("softid_refused_requests_total{{method=\"{}\",code=\"{}\"}} {}\n", key.first,
                       key.second, count);
  }
  out +=
      "# HELP softid_job_queue_wait_seconds Time from creation (or requeue) to a worker's "
      "claim.\n# TYPE softid_job_queue_wait_seconds histogram\n";
  AppendHistogram(out, "softid_job_queue_wait_seconds", "", queue_wait_.buckets, queue_wait_.count,
                  queue_wait_.sum);
  out +=
      "# HELP softid_job_run_seconds Time a worker ran a job, by outcome.\n"
      "# TYPE softid_job_run_seconds histogram\n";
  for (const auto& [outcome, histogram] : run_by_outcome_) {
    AppendHistogram(out, "softid_job_run_seconds", fmt::format("outcome=\"{}\"", outcome),
                    histogram.buckets, histogram.count, histogram.sum);
  }
  return out;
}

}  // namespace softid::server
