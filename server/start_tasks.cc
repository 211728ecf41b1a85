#include "server/start_tasks.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <thread>

#include "server/fit_progress.h"
#include "server/job_capture.h"
#include "server/lease_heartbeat.h"
#include "server/refit_tasks.h"
#include "server/work_folder.h"

namespace softid::server {
namespace {

// Seconds since the job's current attempt was claimed (its events' elapsed_s), on any host.
double SecondsSinceClaim(const store::Job& job) {
  if (!job.started_at) return 0.0;
  const auto now =
      std::chrono::time_point_cast<std::chrono::microseconds>(std::chrono::system_clock::now());
  return std::max(0.0, std::chrono::duration<double>(now - *job.started_at).count());
}

// What a start task runs: its job's config (with the worker's cores when it leaves them open)
// and the checkpoint the job's worker saved before splitting it.
struct TaskInputs {
  store::Job job;
  inverse::JobConfig config;
  store::Capture stored;
  inverse::FitCheckpoint checkpoint;  // the job's fit's starts only
};

Result<TaskInputs> LoadTaskInputs(const store::StartTask& task, const JobRunnerContext& context) {
  TaskInputs in;
  SOFTID_ASSIGN_OR_RETURN(in.job, context.jobs->GetJob(task.job_id));
  Result<inverse::JobConfig> config = inverse::JobConfigFromJson(in.job.config);
  if (!config.ok()) return config.status().WithContext("config");
  in.config = std::move(config).value();
  if (in.config.solver.threads == 0 && context.cores_per_job > 0)
    in.config.solver.threads = context.cores_per_job;
  SOFTID_ASSIGN_OR_RETURN(in.stored, context.jobs->GetCapture(in.job.capture_id));
  if (!task.batch.empty()) return in;  // a refit: its config is the task's input
  SOFTID_ASSIGN_OR_RETURN(std::optional<nlohmann::json> saved,
                          context.jobs->LoadCheckpoint(task.job_id));
  if (!saved) return Status::FailedPrecondition("the job has no checkpoint to start from");
  SOFTID_ASSIGN_OR_RETURN(in.checkpoint, inverse::FitCheckpointFromJson(*saved));
  return in;
}

// Fits the task's start; its result once it ran to its end (nullopt when stopped, or when it
// could not run: then `error` says why).
std::optional<inverse::StartResult> FitOneStart(const store::StartTask& task, const TaskInputs& in,
                                                const capture::Capture& capture,
                                                const JobRunnerContext& context,
                                                std::atomic<bool>& stop, std::string* error) {
  std::optional<inverse::StartResult> finished;
  inverse::FitOptions options;
  options.cancel = &stop;
  options.only_starts = {task.index};
  options.resume_from = &in.checkpoint;
  options.on_progress = [&](const inverse::FitProgress& p) {
    RecordIteration(in.job, IterationEvent(p, in.config, SecondsSinceClaim(in.job)), context);
  };
  options.on_checkpoint = [&](const inverse::FitCheckpoint& checkpoint) {
    for (const inverse::StartResult& start : checkpoint.finished) {
      if (start.index == task.index) finished = start;
    }
  };
  // A start that diverged makes the fit fail ("every start failed"), but it finished: its
  // result says so, and the job's worker combines it with the others.
  Result<inverse::FitResult> fit = inverse::Fit(capture, in.config, options);
  if (!finished && !fit.ok() && !stop.load()) *error = fit.status().message();
  return finished;
}

// Runs the task in a folder of its own: a start of the job's fit, or a refit of a batch. The
// result to complete it with once it ran to its end; nullopt when stopped, or when it could not
// run (then `error` says why).
std::optional<nlohmann::json> RunTask(const store::StartTask& task, const TaskInputs& in,
                                      const std::string& worker_id, const JobRunnerContext& context,
                                      std::atomic<bool>& stop, std::string* error) {
  WorkFolder folder(context.work_root / (task.job_id + "-task-" + std::to_string(task.index)));
  nlohmann::json ingest_report;  // the job's worker reported the ingest
  Result<capture::Capture> capture =
      PrepareCapture(in.job, in.stored, worker_id, context, folder.path, stop, &ingest_report);
  if (!capture.ok()) {
    *error = capture.status().message();
    return std::nullopt;
  }
  if (!task.batch.empty()) return RunRefitTask(task, *capture, stop, error);
  std::optional<inverse::StartResult> finished =
      FitOneStart(task, in, *capture, context, stop, error);
  if (!finished) return std::nullopt;
  return inverse::StartCheckpointJson(*finished);
}

// "start 2", or "refit task 9 (diagnosis 1 ...)": a task as logs and errors name it.
std::string TaskName(const store::StartTask& task) {
  if (task.batch.empty()) return "start " + std::to_string(task.index);
  return "refit task " + std::to_string(task.index) + " (" + task.batch + ")";
}

// The task's lease, renewed while it runs; `outer_stop` (the job's worker's, when that worker
// runs the task itself) stops it.
LeaseCalls StartTaskLease(const store::StartTask& task, const std::string& worker_id,
                          const JobRunnerContext& context, const std::atomic<bool>* outer_stop,
                          const std::string& name) {
  LeaseCalls calls;
  calls.renew = [&task, &worker_id, &context] {
    return context.jobs->RenewStartTask(task.job_id, task.index, worker_id, context.lease);
  };
  calls.stop_requested = [outer_stop] { return outer_stop != nullptr && outer_stop->load(); };
  calls.on_lost = [&context, &name](const Status& status) {
    context.logger->warn("{}: stopping: {}", name, status.message());
  };
  return calls;
}

// A start whose earlier run stopped (a lost or stopped worker) begins again at iteration 0:
// the history says why its iterations repeat.
void NoteRunAgain(const store::StartTask& task, const store::Job& job,
                  const JobRunnerContext& context) {
  const std::string what =
      task.batch.empty() ? "start " + std::to_string(task.index + 1) : TaskName(task);
  RecordNote(job, what + " runs again (task attempt " + std::to_string(task.attempts) + ")",
             context);
}

// A task that did not finish: `why` (empty when it was stopped) into `error`, and the task left
// to its lease or handed back.
StartTaskOutcome ReleaseUnfinished(const store::StartTask& task, const std::string& worker_id,
                                   const JobRunnerContext& context,
                                   const std::atomic<bool>* outer_stop, const std::string& name,
                                   const std::string& why, std::string* error) {
  const auto& log = context.logger;
  if (error != nullptr) *error = why;
  // A task that could not run here is left to its lease rather than handed straight back: an
  // idle worker would take it again at once and fail the same way. The job's worker fails the
  // job once the task was claimed too often (RunAndAwaitTasks).
  if (!why.empty() && outer_stop == nullptr) {
    log->warn("{}: cannot run here, left to its lease: {}", name, why);
    return StartTaskOutcome::kReleased;
  }
  if (!why.empty()) log->warn("{}: cannot run: {}", name, why);
  if (Status released = context.jobs->ReleaseStartTask(task.job_id, task.index, worker_id);
      !released.ok()) {
    log->warn("{}: not released: {}", name, released.message());
  }
  return StartTaskOutcome::kReleased;
}

}  // namespace

Status CheckTaskAttempts(const std::vector<store::StartTask>& tasks,
                         const JobRunnerContext& context) {
  for (const store::StartTask& task : tasks) {
    if (task.state != store::StartTaskState::kDone && task.attempts > 2 * context.max_attempts) {
      return Status::FailedPrecondition(TaskName(task) + " did not finish in " +
                                        std::to_string(task.attempts) +
                                        " claims by workers (see their logs)");
    }
  }
  return Status::Ok();
}

const char* ToString(StartTaskOutcome outcome) {
  switch (outcome) {
    case StartTaskOutcome::kDone: return "done";
    case StartTaskOutcome::kReleased: return "released";
    case StartTaskOutcome::kLost: return "lost";
  }
  return "unknown";
}

StartTaskOutcome RunStartTask(const store::StartTask& task, const std::string& worker_id,
                              const JobRunnerContext& context, std::atomic<bool>& stop,
                              const std::atomic<bool>* outer_stop, std::string* error) {
  const auto& log = context.logger;
  const std::string name = "job " + task.job_id + " " + TaskName(task);
  log->info("{}: RUNNING on {} (task attempt {})", name, worker_id, task.attempts);
  std::string why;
  std::optional<nlohmann::json> finished;
  bool lost = false;
  {
    LeaseHeartbeat heartbeat(StartTaskLease(task, worker_id, context, outer_stop, name),
                             context.heartbeat_interval, stop);
    Result<TaskInputs> inputs = LoadTaskInputs(task, context);
    if (inputs.ok() && task.attempts > 1) NoteRunAgain(task, inputs->job, context);
    if (inputs.ok()) {
      finished = RunTask(task, *inputs, worker_id, context, stop, &why);
    } else {
      why = inputs.status().message();
    }
    lost = heartbeat.lost();
  }
  if (lost) return StartTaskOutcome::kLost;
  if (!finished) {
    return ReleaseUnfinished(task, worker_id, context, outer_stop, name, why, error);
  }
  if (Status completed =
          context.jobs->CompleteStartTask(task.job_id, task.index, worker_id, *finished);
      !completed.ok()) {
    log->warn("{}: result not recorded: {}", name, completed.message());
    return StartTaskOutcome::kLost;
  }
  context.events->Notify(task.job_id);
  log->info("{}: done", name);
  return StartTaskOutcome::kDone;
}

Result<std::vector<store::StartTask>> RunAndAwaitTasks(const store::Job& job,
                                                       const std::string& worker_id,
                                                       const JobRunnerContext& context,
                                                       std::atomic<bool>& cancel,
                                                       const std::string& batch) {
  while (true) {
    if (cancel.load()) return Status::Cancelled("the fit was cancelled");
    SOFTID_ASSIGN_OR_RETURN(std::optional<store::StartTask> own,
                            context.jobs->ClaimStartTask(worker_id, context.lease, job.id));
    if (own) {
      std::atomic<bool> stop{false};
      std::string error;
      const StartTaskOutcome outcome =
          RunStartTask(*own, worker_id, context, stop, &cancel, &error);
      if (outcome == StartTaskOutcome::kReleased && !error.empty() && !cancel.load()) {
        return Status::FailedPrecondition(TaskName(*own) + ": " + error);
      }
      continue;
    }
    SOFTID_ASSIGN_OR_RETURN(std::vector<store::StartTask> tasks,
                            context.jobs->ListStartTasks(job.id));
    std::erase_if(tasks, [&](const store::StartTask& t) { return t.batch != batch; });
    const bool all_done = std::all_of(tasks.begin(), tasks.end(), [](const store::StartTask& t) {
      return t.state == store::StartTaskState::kDone;
    });
    if (all_done) return tasks;
    SOFTID_RETURN_IF_ERROR(CheckTaskAttempts(tasks, context));
    std::this_thread::sleep_for(context.task_poll_interval);
  }
}

Result<inverse::FitResult> FitByStartTasks(
    const store::Job& job, const capture::Capture& capture, const inverse::JobConfig& config,
    const std::optional<inverse::FitCheckpoint>& earlier, const std::string& worker_id,
    const JobRunnerContext& context, std::atomic<bool>& cancel, std::vector<int>* kept_starts) {
  inverse::FitCheckpoint prepared;
  if (earlier) {
    prepared = *earlier;
  } else {
    SOFTID_ASSIGN_OR_RETURN(prepared, inverse::PrepareFit(capture, config, &cancel));
  }
  // The tasks start from the checkpoint, so it is saved before they exist.
  SOFTID_RETURN_IF_ERROR(context.jobs->SaveCheckpoint(job.id, inverse::ToJson(prepared)));
  SOFTID_RETURN_IF_ERROR(context.jobs->CreateStartTasks(job.id, worker_id, prepared.num_starts));
  context.logger->info("job {}: {} starts split into tasks", job.id, prepared.num_starts);
  if (context.wake_workers) context.wake_workers();
  if (job.attempts > 1) {
    SOFTID_ASSIGN_OR_RETURN(const std::vector<store::StartTask> existing,
                            context.jobs->ListStartTasks(job.id));
    std::vector<int> kept;
    for (const store::StartTask& task : existing) {
      if (task.batch.empty() && task.state == store::StartTaskState::kDone)
        kept.push_back(task.index);
    }
    NoteKeptStarts(job, kept.size(), prepared.num_starts, context);
    if (kept_starts != nullptr) *kept_starts = std::move(kept);
  }
  SOFTID_ASSIGN_OR_RETURN(const std::vector<store::StartTask> tasks,
                          RunAndAwaitTasks(job, worker_id, context, cancel, ""));
  inverse::FitCheckpoint all = prepared;
  all.finished.clear();
  for (const store::StartTask& task : tasks) {
    Result<inverse::StartResult> start = inverse::StartFromCheckpointJson(*task.result);
    if (!start.ok()) return start.status().WithContext("start task " + std::to_string(task.index));
    all.finished.push_back(std::move(start).value());
  }
  // Runs no start: picks the best and fills the result as the one-process fit does.
  inverse::FitOptions combine;
  combine.resume_from = &all;
  combine.cancel = &cancel;
  return inverse::Fit(capture, config, combine);
}

}  // namespace softid::server
