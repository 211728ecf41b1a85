#include "server/store/start_task.h"

#include <algorithm>

namespace softid::server::store {

const char* ToString(StartTaskState state) {
  switch (state) {
    case StartTaskState::kQueued: return "QUEUED";
    case StartTaskState::kRunning: return "RUNNING";
    case StartTaskState::kDone: return "DONE";
  }
  return "UNKNOWN";
}

Result<StartTaskState> StartTaskStateFromString(std::string_view text) {
  for (const StartTaskState state :
       {StartTaskState::kQueued, StartTaskState::kRunning, StartTaskState::kDone}) {
    if (text == ToString(state)) return state;
  }
  return Status::InvalidArgument("start task state = '" + std::string(text.substr(0, 40)) +
                                 "': must be one of QUEUED, RUNNING, DONE");
}

Status CheckTaskCount(int num_tasks) {
  if (num_tasks >= 1) return Status::Ok();
  return Status::InvalidArgument("num_tasks = " + std::to_string(num_tasks) + ": must be >= 1");
}

Status CheckBatchName(std::string_view batch) {
  const bool printable =
      std::all_of(batch.begin(), batch.end(), [](char c) { return c >= 0x20 && c < 0x7f; });
  if (!batch.empty() && batch.size() <= 100 && printable) return Status::Ok();
  return Status::InvalidArgument("batch = '" + std::string(batch.substr(0, 40)) +
                                 "': must be 1 to 100 printable ASCII characters");
}

Status CheckExistingBatch(const std::string& job_id, std::string_view batch, int64_t existing,
                          int num_tasks) {
  if (existing == 0 || existing == num_tasks) return Status::Ok();
  return Status::FailedPrecondition("job " + job_id + " has " + std::to_string(existing) +
                                    " tasks in batch '" + std::string(batch) + "' already, not " +
                                    std::to_string(num_tasks));
}

Status CheckTaskOwner(const Job& job, const std::string& worker_id) {
  if (job.state != JobState::kRunning) {
    return Status::FailedPrecondition("job " + job.id + " is " + ToString(job.state) +
                                      ": only a RUNNING job is split into start tasks");
  }
  if (job.lease_owner != worker_id) {
    return Status::FailedPrecondition("job " + job.id + " is leased to " + job.lease_owner +
                                      ", not " + worker_id);
  }
  return Status::Ok();
}

Status CheckExistingTasks(const std::string& job_id, int64_t existing, int num_tasks) {
  if (existing == 0 || existing == num_tasks) return Status::Ok();
  return Status::FailedPrecondition("job " + job_id + " has " + std::to_string(existing) +
                                    " start tasks already, not " + std::to_string(num_tasks));
}

Status CheckTaskLease(const StartTask& task, const std::string& worker_id) {
  if (task.state == StartTaskState::kRunning && task.lease_owner == worker_id) return Status::Ok();
  const std::string held = task.state == StartTaskState::kRunning ? "leased to " + task.lease_owner
                                                                  : ToString(task.state);
  return Status::FailedPrecondition("start task " + std::to_string(task.index) + " of job " +
                                    task.job_id + " is " + held + ", not held by " + worker_id);
}

Status CheckTaskHeld(const Job& job, const StartTask& task, const std::string& worker_id) {
  SOFTID_RETURN_IF_ERROR(CheckTaskLease(task, worker_id));
  if (IsTerminal(job.state)) {
    return Status::FailedPrecondition("job " + job.id + " is " + ToString(job.state) +
                                      ": its start tasks stop");
  }
  if (job.cancel_requested) {
    return Status::FailedPrecondition("job " + job.id +
                                      " has a cancel request: its start tasks stop");
  }
  return Status::Ok();
}

}  // namespace softid::server::store
