// The rules of the job life cycle (job.h) that every store applies inside its transactions, so
// that the backends cannot drift apart: argument checks, the errors of refused transitions, and
// what crash recovery does with a job whose worker was lost. The stores keep only their SQL.
#pragma once

#include <chrono>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>

#include "core/common/status.h"
#include "server/store/job.h"
#include "server/store/job_store.h"
#include "server/store/timestamp.h"

namespace softid::server::store {

// InvalidArgument for a malformed job id, a lease that is not positive, an empty worker id, a
// negative page size or max_attempts below 1.
Status CheckJobId(const std::string& job_id);
Status CheckLease(std::chrono::milliseconds lease);
Status CheckWorkerId(const std::string& worker_id);
Status CheckPageSize(int page_size);
Status CheckMaxAttempts(int max_attempts);
// A request's page size: 0 is the default, larger than the maximum is lowered to it (AIP-158).
int EffectivePageSize(int requested);

// "job job-... is SUCCEEDED: <requirement>" for a transition the job's state does not allow.
Status WrongState(const Job& job, const std::string& requirement);
// "job job-... is leased to A, not B": the caller no longer holds the job.
Status NotLeasedTo(const Job& job, const std::string& worker_id);
// Seconds the current attempt has been running, for state events; 0 before the first claim.
double ElapsedSeconds(const Job& job, Timestamp now);

// What crash recovery does with a RUNNING job whose worker was lost: CANCELLED when a cancel was
// pending, FAILED once it was claimed max_attempts times (released claims do not count), QUEUED
// again otherwise; the history's message, and the job's error when FAILED.
struct RecoveryVerdict {
  JobState state = JobState::kQueued;
  std::string message;
  std::string error;
};
RecoveryVerdict DecideRecovery(const Job& job, int max_attempts, RecoveryScope scope);

// JSON as stored in a text column, and back. Dumping never throws: invalid UTF-8 is stored as
// U+FFFD. Reading text that is not JSON is Internal ("corrupt <what> in the database").
std::string DumpJson(const nlohmann::json& value);
Result<nlohmann::json> ParseStoredJson(const std::string& text, std::string_view what);
std::optional<Timestamp> OptionalTimestamp(const std::optional<int64_t>& us);
std::optional<std::string> NullIfEmpty(const std::string& text);

}  // namespace softid::server::store
