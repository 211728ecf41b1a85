// Fan-out of a job's starts over workers (store/start_task.h). The job's worker prepares the fit
// (its grid and time step, saved as the job's checkpoint), splits it into one task per start,
// runs tasks of its own job while any is left and waits for those running elsewhere, then
// combines the finished starts into the fit's result. Any worker runs start tasks before it
// claims a new job (RunStartTask). A start computes the same wherever it runs (its simulations'
// thread count comes from the config: workers that give a job the same cores compute it bit for
// bit), so the result is the one the job's worker would have computed alone, in about the time
// of one start per worker.
//
// A worker lost midway loses only its start: its task's lease expires and another worker (or the
// job's own) runs it again. A job whose worker is lost keeps every finished task for its next
// attempt, and its running tasks go on meanwhile.
#pragma once

#include <atomic>
#include <optional>
#include <string>
#include <vector>

#include "core/capture/capture.h"
#include "core/common/status.h"
#include "core/inverse/fit.h"
#include "core/inverse/fit_checkpoint.h"
#include "core/inverse/job_config.h"
#include "server/job_runner.h"
#include "server/store/job.h"
#include "server/store/start_task.h"

namespace softid::server {

enum class StartTaskOutcome {
  kDone,      // completed with the start's result
  kReleased,  // stopped (shutdown, cancel) or could not run: handed back for another worker
  kLost,      // the lease was lost (another worker may hold the task now): nothing written
};

const char* ToString(StartTaskOutcome outcome);

// FailedPrecondition naming a start whose task was claimed more than 2 x context.max_attempts
// times without finishing (shutdowns hand tasks back too, hence the margin): its workers keep
// dying or cannot run it. The job's worker fails the job with it.
Status CheckTaskAttempts(const std::vector<store::StartTask>& tasks,
                         const JobRunnerContext& context);

// Runs `task`, just claimed by `worker_id`: lays out its job's capture in a folder of its own,
// fits the one start from the job's checkpoint with progress into the job's history, keeps the
// task's lease alive, and completes the task with the start's result (a start that diverged is a
// result too). `stop` stops it, and so does `outer_stop` (may be null; polled at the heartbeat
// interval), a cancel request on the job or a lost lease. `error` (may be null) receives why a
// released task could not run.
StartTaskOutcome RunStartTask(const store::StartTask& task, const std::string& worker_id,
                              const JobRunnerContext& context, std::atomic<bool>& stop,
                              const std::atomic<bool>* outer_stop = nullptr,
                              std::string* error = nullptr);

// Runs the job's own tasks (any batch) while any is claimable and waits for those of `batch` (""
// = the starts of the job's fit) running elsewhere; the batch's tasks by index once every one is
// DONE. Cancelled once `cancel` is set; FailedPrecondition naming a task of the job's own that
// cannot run here, or one claimed too often (CheckTaskAttempts).
Result<std::vector<store::StartTask>> RunAndAwaitTasks(const store::Job& job,
                                                       const std::string& worker_id,
                                                       const JobRunnerContext& context,
                                                       std::atomic<bool>& cancel,
                                                       const std::string& batch);

// The fit of `job` (claimed by `worker_id`) with its starts run as tasks. `earlier` is an earlier
// attempt's checkpoint: its discretisation is kept, and so are the starts it finished. Stops with
// StatusCode::kCancelled once `cancel` is set; fails naming the start when one of this worker's
// own tasks cannot run (a capture or config the job cannot fit), with the fit's errors otherwise.
// `kept_starts` (may be null) receives the starts whose tasks an earlier attempt finished.
Result<inverse::FitResult> FitByStartTasks(const store::Job& job, const capture::Capture& capture,
                                           const inverse::JobConfig& config,
                                           const std::optional<inverse::FitCheckpoint>& earlier,
                                           const std::string& worker_id,
                                           const JobRunnerContext& context,
                                           std::atomic<bool>& cancel,
                                           std::vector<int>* kept_starts = nullptr);

}  // namespace softid::server
