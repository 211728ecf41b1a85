// One of a job's starts, run as a task any worker can claim (fan-out): the job's worker splits
// its fit into one task per start (JobStore::CreateStartTasks), workers anywhere claim them,
// renew their lease while they run and complete them with the start's result, and the job's
// worker combines the results. A task's life cycle:
//
//   QUEUED --claim--> RUNNING --complete--> DONE
//                       |--released-------> QUEUED (shutdown)
//                       `--lease expired--> claimed again by the next claimer
//
// Tasks live as long as their job and survive its requeue: a later attempt keeps those DONE.
//
// Besides the starts of the job's fit (batch ""), a job may add named batches of other fits
// (JobStore::CreateTaskBatch): the diagnosis' refits, each task with its fit's config as `input`.
// A batch's tasks take the indexes after the job's existing tasks; all share one life cycle.
#pragma once

#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>

#include "core/common/status.h"
#include "server/store/job.h"
#include "server/store/timestamp.h"

namespace softid::server::store {

enum class StartTaskState { kQueued, kRunning, kDone };

// "QUEUED", "RUNNING", "DONE": the spelling in the database.
const char* ToString(StartTaskState state);
Result<StartTaskState> StartTaskStateFromString(std::string_view text);

struct StartTask {
  std::string job_id;
  // Unique within the job: the start's index in the job's fit (0 .. num_starts - 1), then the
  // batches' tasks in the order they were added.
  int index = 0;
  std::string batch;                    // "" = a start of the job's fit; else its batch
  std::optional<nlohmann::json> input;  // what a batch's task fits; none for the job's fit
  StartTaskState state = StartTaskState::kQueued;
  int attempts = 0;                           // claims so far
  std::string lease_owner;                    // worker id while RUNNING; empty otherwise
  std::optional<Timestamp> lease_expires_at;  // while RUNNING
  std::optional<nlohmann::json> result;       // when DONE

  bool operator==(const StartTask&) const = default;
};

// The rules every store applies inside its transactions (JobStore's start task calls), so that
// the backends agree; each returns the error the call reports.
// num_tasks must be >= 1 (InvalidArgument).
Status CheckTaskCount(int num_tasks);
// A batch's name: 1 .. 100 printable ASCII characters (InvalidArgument naming it).
Status CheckBatchName(std::string_view batch);
// A batch made before is kept: `existing` (its tasks) must be 0 or `num_tasks`.
Status CheckExistingBatch(const std::string& job_id, std::string_view batch, int64_t existing,
                          int num_tasks);
// Only the worker holding a RUNNING job splits it (FailedPrecondition).
Status CheckTaskOwner(const Job& job, const std::string& worker_id);
// A job split before keeps its tasks: `existing` must be 0 or `num_tasks` (FailedPrecondition).
Status CheckExistingTasks(const std::string& job_id, int64_t existing, int num_tasks);
// The task is RUNNING and leased to `worker_id` (FailedPrecondition).
Status CheckTaskLease(const StartTask& task, const std::string& worker_id);
// CheckTaskLease, and its job has neither ended nor a cancel request: the worker may go on.
Status CheckTaskHeld(const Job& job, const StartTask& task, const std::string& worker_id);

}  // namespace softid::server::store
