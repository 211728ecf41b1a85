#include "server/refit_tasks.h"

#include "core/inverse/fit_checkpoint.h"
#include "server/start_tasks.h"
#include "server/store/sha256.h"

namespace softid::server {
namespace {

// The batch's inputs and its name: a digest of the inputs tells a later attempt's batch apart
// from one made from other configs.
std::vector<nlohmann::json> BatchInputs(const std::vector<inverse::JobConfig>& configs) {
  std::vector<nlohmann::json> inputs;
  for (const inverse::JobConfig& config : configs) inputs.push_back({{"config", ToJson(config)}});
  return inputs;
}

std::string BatchName(int batch_number, const std::vector<nlohmann::json>& inputs) {
  const std::string digest = store::Sha256::Hex(nlohmann::json(inputs).dump());
  return "diagnosis " + std::to_string(batch_number) + " " + digest.substr(0, 16);
}

// A finished task's refit: rebuilt from its checkpoint as the one-process fit fills it (no
// start runs again), or the error it ended with.
Result<inverse::FitResult> RefitFromTask(const store::StartTask& task,
                                         const capture::Capture& capture,
                                         const inverse::JobConfig& config,
                                         std::atomic<bool>& cancel) {
  const std::string name = "refit task " + std::to_string(task.index);
  if (!task.result) return Status::Internal(name + " has no result");
  if (task.result->contains("error")) {
    const int code = task.result->value("code", static_cast<int>(StatusCode::kInternal));
    return Status(static_cast<StatusCode>(code), task.result->value("error", std::string()));
  }
  if (!task.result->contains("checkpoint")) return Status::Internal(name + ": no checkpoint");
  Result<inverse::FitCheckpoint> checkpoint =
      inverse::FitCheckpointFromJson(task.result->at("checkpoint"));
  if (!checkpoint.ok()) return checkpoint.status().WithContext(name);
  inverse::FitOptions combine;
  combine.resume_from = &*checkpoint;
  combine.cancel = &cancel;
  return inverse::Fit(capture, config, combine);
}

}  // namespace

std::optional<nlohmann::json> RunRefitTask(const store::StartTask& task,
                                           const capture::Capture& capture, std::atomic<bool>& stop,
                                           std::string* error) {
  if (!task.input || !task.input->contains("config")) {
    *error = "refit task " + std::to_string(task.index) + " has no config";
    return std::nullopt;
  }
  Result<inverse::JobConfig> config = inverse::JobConfigFromJson(task.input->at("config"));
  if (!config.ok()) {
    *error = config.status().WithContext("refit task config").message();
    return std::nullopt;
  }
  std::optional<inverse::FitCheckpoint> last;
  inverse::FitOptions options;
  options.cancel = &stop;
  options.on_checkpoint = [&](const inverse::FitCheckpoint& checkpoint) { last = checkpoint; };
  Result<inverse::FitResult> fit = inverse::Fit(capture, *config, options);
  if (stop.load() || (fit.ok() && fit->cancelled)) return std::nullopt;
  // A refit whose every start diverged failed, but finished: its checkpoint says so.
  if (last && static_cast<int>(last->finished.size()) == last->num_starts)
    return nlohmann::json{{"checkpoint", ToJson(*last)}};
  return nlohmann::json{
      {"error", fit.ok() ? "the refit finished no start" : fit.status().message()},
      {"code", static_cast<int>(fit.ok() ? StatusCode::kInternal : fit.status().code())}};
}

std::vector<Result<inverse::FitResult>> FitBatchByTasks(
    const store::Job& job, const capture::Capture& capture,
    const std::vector<inverse::JobConfig>& configs, int batch_number, const std::string& worker_id,
    const JobRunnerContext& context, std::atomic<bool>& cancel) {
  const std::vector<nlohmann::json> inputs = BatchInputs(configs);
  const std::string batch = BatchName(batch_number, inputs);
  auto all = [&](const Status& status) {
    return std::vector<Result<inverse::FitResult>>(configs.size(), status);
  };
  Result<int> first = context.jobs->CreateTaskBatch(job.id, worker_id, batch, inputs);
  if (!first.ok()) return all(first.status());
  context.logger->info("job {}: {} refits split into tasks ({})", job.id, configs.size(), batch);
  if (context.wake_workers) context.wake_workers();
  Result<std::vector<store::StartTask>> tasks =
      RunAndAwaitTasks(job, worker_id, context, cancel, batch);
  if (!tasks.ok()) return all(tasks.status());
  if (tasks->size() != configs.size()) {
    return all(Status::Internal("batch " + batch + " has " + std::to_string(tasks->size()) +
                                " tasks, not " + std::to_string(configs.size())));
  }
  std::vector<Result<inverse::FitResult>> results;
  for (size_t i = 0; i < configs.size(); ++i)
    results.push_back(RefitFromTask((*tasks)[i], capture, configs[i], cancel));
  return results;
}

}  // namespace softid::server
