#include "server/fit_progress.h"

#include <string>

namespace softid::server {
namespace {

nlohmann::json FittedParametersJson(const inverse::JobConfig& config,
                                    const fem::PhysicalParameters& parameters) {
  nlohmann::json out = nlohmann::json::object();
  for (const std::string& name : config.fit)
    out[name] = inverse::ParameterValueJson(parameters, name);
  return out;
}

// "start 2/8, frames 0-14 (stage 1/3), 3 of 900 steps unconverged", the parts that apply.
std::string IterationMessage(const inverse::FitProgress& p) {
  std::string message;
  auto add = [&](const std::string& part) { message += (message.empty() ? "" : ", ") + part; };
  if (p.num_starts > 1)
    add("start " + std::to_string(p.start + 1) + "/" + std::to_string(p.num_starts));
  // The cost of a continuation stage is over a prefix of the frames.
  if (p.num_stages > 1) {
    add("frames 0-" + std::to_string(p.horizon_frame) + " (stage " + std::to_string(p.stage + 1) +
        "/" + std::to_string(p.num_stages) + ")");
  }
  if (p.unconverged_steps > 0) {
    add(std::to_string(p.unconverged_steps) + " of " + std::to_string(p.simulation_steps) +
        " steps unconverged");
  }
  return message;
}

}  // namespace

store::ProgressEvent IterationEvent(const inverse::FitProgress& p, const inverse::JobConfig& config,
                                    double elapsed_s) {
  store::ProgressEvent event;
  event.kind = store::ProgressKind::kIteration;
  event.iteration = p.iteration;
  event.cost = p.cost;
  event.gradient_norm = p.gradient_norm;
  event.parameters = FittedParametersJson(config, p.parameters);
  event.elapsed_s = elapsed_s;
  event.start = p.start;
  event.num_starts = p.num_starts;
  event.remaining_s = p.remaining_seconds;
  event.message = IterationMessage(p);
  return event;
}

void RecordIteration(const store::Job& job, const store::ProgressEvent& event,
                     const JobRunnerContext& context) {
  if (Result<int64_t> seq = context.jobs->AppendProgress(job.id, event); !seq.ok()) {
    context.logger->warn("job {}: progress of iteration {} not recorded: {}", job.id,
                         event.iteration, seq.status().message());
  }
  context.events->Notify(job.id);
  if (context.metrics != nullptr && event.iteration > 0) context.metrics->CountIteration();
  context.logger->debug("job {}: start {} iteration {} cost {:.4e}", job.id, event.start,
                        event.iteration, event.cost);
}

void RecordNote(const store::Job& job, const std::string& note, const JobRunnerContext& context) {
  store::ProgressEvent event;
  event.kind = store::ProgressKind::kState;
  event.message = note;
  if (Result<int64_t> seq = context.jobs->AppendProgress(job.id, event); !seq.ok()) {
    context.logger->warn("job {}: note not recorded: {}", job.id, seq.status().message());
  }
  context.events->Notify(job.id);
}

void NoteKeptStarts(const store::Job& job, size_t kept, int num_starts,
                    const JobRunnerContext& context) {
  if (kept == 0) return;
  RecordNote(job,
             "resumed from a checkpoint: " + std::to_string(kept) + " of " +
                 std::to_string(num_starts) + " starts finished on an earlier attempt",
             context);
}

}  // namespace softid::server
