#include "server/store/job.h"

namespace softid::server::store {

const char* ToString(JobState state) {
  switch (state) {
    case JobState::kQueued: return "QUEUED";
    case JobState::kRunning: return "RUNNING";
    case JobState::kSucceeded: return "SUCCEEDED";
    case JobState::kFailed: return "FAILED";
    case JobState::kCancelled: return "CANCELLED";
  }
  return "UNKNOWN";
}

Result<JobState> JobStateFromString(std::string_view text) {
  for (const JobState state : {JobState::kQueued, JobState::kRunning, JobState::kSucceeded,
                               JobState::kFailed, JobState::kCancelled}) {
    if (text == ToString(state)) return state;
  }
  return Status::InvalidArgument("job state = '" + std::string(text.substr(0, 40)) +
                                 "': must be one of QUEUED, RUNNING, SUCCEEDED, FAILED, CANCELLED");
}

bool IsTerminal(JobState state) {
  return state == JobState::kSucceeded || state == JobState::kFailed ||
         state == JobState::kCancelled;
}

}  // namespace softid::server::store
