#include "server/store/job_rules.h"

#include <algorithm>

#include "server/store/resource_id.h"

namespace softid::server::store {

Status CheckJobId(const std::string& job_id) {
  return CheckResourceId(job_id, kJobIdPrefix, "job id");
}

Status CheckLease(std::chrono::milliseconds lease) {
  if (lease.count() <= 0) {
    return Status::InvalidArgument("lease = " + std::to_string(lease.count()) +
                                   " ms: must be positive");
  }
  return Status::Ok();
}

Status CheckWorkerId(const std::string& worker_id) {
  if (worker_id.empty()) return Status::InvalidArgument("worker_id = '': must not be empty");
  return Status::Ok();
}

Status CheckPageSize(int page_size) {
  if (page_size < 0) {
    return Status::InvalidArgument("page_size = " + std::to_string(page_size) +
                                   ": must not be negative");
  }
  return Status::Ok();
}

Status CheckMaxAttempts(int max_attempts) {
  if (max_attempts < 1) {
    return Status::InvalidArgument("max_attempts = " + std::to_string(max_attempts) +
                                   ": must be at least 1");
  }
  return Status::Ok();
}

int EffectivePageSize(int requested) {
  return std::min(requested == 0 ? ListJobsRequest::kDefaultPageSize : requested,
                  ListJobsRequest::kMaxPageSize);
}

Status WrongState(const Job& job, const std::string& requirement) {
  return Status::FailedPrecondition("job " + job.id + " is " + ToString(job.state) + ": " +
                                    requirement);
}

Status NotLeasedTo(const Job& job, const std::string& worker_id) {
  return Status::FailedPrecondition("job " + job.id + " is leased to " + job.lease_owner +
                                    ", not " + worker_id);
}

double ElapsedSeconds(const Job& job, Timestamp now) {
  if (!job.started_at.has_value()) return 0.0;
  return std::chrono::duration<double>(now - *job.started_at).count();
}

RecoveryVerdict DecideRecovery(const Job& job, int max_attempts, RecoveryScope scope) {
  const std::string cause = scope == RecoveryScope::kAllRunning
                                ? "its worker was lost (the server restarted)"
                                : "its worker's lease expired";
  RecoveryVerdict verdict;
  if (job.cancel_requested) {
    verdict.state = JobState::kCancelled;
    verdict.message = "cancelled: " + cause + " after the cancel was requested";
  } else if (const int counted = job.attempts - job.released_attempts; counted >= max_attempts) {
    verdict.state = JobState::kFailed;
    verdict.error = "gave up after " + std::to_string(counted) + " attempt(s) (max_attempts " +
                    std::to_string(max_attempts) + "): " + cause + " while RUNNING";
    verdict.message = verdict.error;
  } else {
    verdict.state = JobState::kQueued;
    verdict.message = "requeued: " + cause + " during attempt " + std::to_string(job.attempts);
  }
  return verdict;
}

std::string DumpJson(const nlohmann::json& value) {
  return value.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

Result<nlohmann::json> ParseStoredJson(const std::string& text, std::string_view what) {
  nlohmann::json value = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (value.is_discarded()) {
    return Status::Internal("corrupt " + std::string(what) + " in the database: not JSON");
  }
  return value;
}

std::optional<Timestamp> OptionalTimestamp(const std::optional<int64_t>& us) {
  if (!us.has_value()) return std::nullopt;
  return FromUnixMicros(*us);
}

std::optional<std::string> NullIfEmpty(const std::string& text) {
  if (text.empty()) return std::nullopt;
  return text;
}

}  // namespace softid::server::store
