// A reconstruction job as the store keeps it, and its life cycle:
//
//   QUEUED --claim--> RUNNING --complete--> SUCCEEDED
//     |                 |  |----fail------> FAILED
//     |                 |  `--cancel seen-> CANCELLED (cancel_requested set, worker stopped)
//     |                 |--worker lost----> QUEUED again, or FAILED after max attempts
//     |                 `--released-------> QUEUED again (shutdown; the attempt does not count)
//     `--cancel-----------------------------> CANCELLED
//
// SUCCEEDED, FAILED and CANCELLED are terminal. A failed optimisation is a FAILED job with an
// error, not a failed store call.
#pragma once

#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>

#include "core/common/status.h"
#include "server/store/timestamp.h"

namespace softid::server::store {

enum class JobState {
  kQueued,
  kRunning,
  kSucceeded,
  kFailed,
  kCancelled,
};

// "QUEUED", "RUNNING", "SUCCEEDED", "FAILED", "CANCELLED": the spelling in the database and in
// the AIP-151 style API.
const char* ToString(JobState state);
// InvalidArgument naming the value for anything but the five spellings above.
Result<JobState> JobStateFromString(std::string_view text);
bool IsTerminal(JobState state);

struct Job {
  std::string id;          // "job-<16 hex>"
  std::string request_id;  // the client's idempotency key; empty when none was given
  std::string capture_id;  // "cap-<16 hex>"
  nlohmann::json config = nlohmann::json::object();  // the fit configuration, a JSON object
  JobState state = JobState::kQueued;
  // Set by RequestCancel on a RUNNING job; the worker polls it and stops (MarkCancelled).
  bool cancel_requested = false;
  // Number of times a worker claimed the job (1 on its first run).
  int attempts = 0;
  // Of those, claims handed back by ReleaseJob (a graceful shutdown): they do not count against
  // max_attempts, which is meant for jobs that keep killing their worker.
  int released_attempts = 0;
  std::string error;  // why the job FAILED; empty otherwise
  Timestamp created_at{};
  std::optional<Timestamp> started_at;   // last claim
  std::optional<Timestamp> finished_at;  // entered a terminal state
  std::string lease_owner;               // worker id while RUNNING; empty otherwise
  // While RUNNING: the worker must renew its lease before this time, or the job counts as lost.
  std::optional<Timestamp> lease_expires_at;
  std::optional<nlohmann::json> result;  // set when SUCCEEDED
  std::string owner;  // the station that created it; empty without authentication
  // For a job on a recording: the capture its ingest made (an ordinary capture of the same
  // owner); empty before the ingest and for a job on a capture.
  std::string derived_capture_id;

  bool operator==(const Job&) const = default;
};

}  // namespace softid::server::store
