// The diagnosis' refits as tasks any worker can claim (core/diagnosis/fit_batch.h): with fan-out
// on, the job's worker hands each batch of refits to the store as a task batch
// (JobStore::CreateTaskBatch, one task per refit with its config as input), runs tasks of its
// own job while any is left, waits for those running elsewhere and reads each refit's result.
// A refit runs where it is claimed exactly as it would in the job's worker (same config, same
// threads), and the job's worker rebuilds its FitResult from the refit's checkpoint, so the
// diagnosis is the one the job's worker would have made alone.
//
// A batch is named after its position in the diagnosis and a digest of its configs: a requeued
// job's next attempt finds the batches its diagnosis had made and keeps their finished refits.
#pragma once

#include <atomic>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/capture/capture.h"
#include "core/common/status.h"
#include "core/inverse/fit.h"
#include "core/inverse/job_config.h"
#include "server/job_runner.h"
#include "server/store/job.h"
#include "server/store/start_task.h"

namespace softid::server {

// The refit of a claimed batch task (task.input {"config": ...}) on `capture`: its result to
// complete the task with, {"checkpoint": ...} or {"error": ..., "code": ...} (a refit that fails
// fails wherever it runs); nullopt when stopped, or when the input cannot be read (then `error`
// says why).
std::optional<nlohmann::json> RunRefitTask(const store::StartTask& task,
                                           const capture::Capture& capture, std::atomic<bool>& stop,
                                           std::string* error);

// The fits of `configs` as the task batch "diagnosis <batch_number> <digest>" of `job` (claimed
// by `worker_id`), in the configs' order. After a cancel, or when the tasks cannot run (a task
// claimed too often), every result is that error.
std::vector<Result<inverse::FitResult>> FitBatchByTasks(
    const store::Job& job, const capture::Capture& capture,
    const std::vector<inverse::JobConfig>& configs, int batch_number, const std::string& worker_id,
    const JobRunnerContext& context, std::atomic<bool>& cancel);

}  // namespace softid::server
