#include "server/job_runner.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <condition_variable>
#include <functional>
#include <mutex>
#include <optional>
#include <system_error>
#include <thread>

#include "core/capture/capture.h"
#include "core/diagnosis/diagnose.h"
#include "core/diagnosis/fit_report.h"
#include "core/diagnosis/report.h"
#include "core/inverse/fit.h"
#include "core/inverse/fit_checkpoint.h"
#include "core/inverse/fit_uncertainty.h"
#include "core/inverse/grid_refinement.h"
#include "core/inverse/job_config.h"
#include "server/fit_progress.h"
#include "server/job_capture.h"
#include "server/lease_heartbeat.h"
#include "server/redact_paths.h"
#include "server/refit_tasks.h"
#include "server/start_tasks.h"
#include "server/work_folder.h"

namespace softid::server {
namespace {

namespace fs = std::filesystem;
using Stopwatch = std::chrono::steady_clock;

// Records a failure; the job's error is what a user sees, so it says what went wrong, naming
// files relative to the capture (the server's folders stay in the log).
JobOutcome Fail(const store::Job& job, const JobRunnerContext& context, const std::string& error) {
  context.logger->warn("job {}: FAILED: {}", job.id, error);
  const std::string shown =
      RedactPath(RedactPath(error, context.work_root / job.id), context.work_root, "<work>/");
  if (Status failed = context.jobs->FailJob(job.id, shown); !failed.ok()) {
    context.logger->error("job {}: cannot record the failure: {}", job.id, failed.message());
  }
  context.events->Notify(job.id);
  return JobOutcome::kFailed;
}

// The checkpoint an earlier attempt of the job saved (a worker lost or a server stopped midway),
// when there is one this attempt can resume from; one that cannot be read is logged and ignored
// (the fit then starts afresh, which is always correct).
std::optional<inverse::FitCheckpoint> EarlierCheckpoint(const store::Job& job,
                                                        const JobRunnerContext& context) {
  if (job.attempts <= 1) return std::nullopt;
  Result<std::optional<nlohmann::json>> stored = context.jobs->LoadCheckpoint(job.id);
  if (!stored.ok() || !stored->has_value()) return std::nullopt;
  Result<inverse::FitCheckpoint> checkpoint = inverse::FitCheckpointFromJson(**stored);
  if (!checkpoint.ok()) {
    context.logger->warn("job {}: checkpoint ignored: {}", job.id, checkpoint.status().message());
    return std::nullopt;
  }
  return std::move(checkpoint).value();
}

// The starts `checkpoint` finished, noted in the job's history as kept.
std::vector<int> FinishedStarts(const store::Job& job, const inverse::FitCheckpoint& checkpoint,
                                const JobRunnerContext& context) {
  std::vector<int> starts;
  for (const inverse::StartResult& start : checkpoint.finished) starts.push_back(start.index);
  NoteKeptStarts(job, starts.size(), checkpoint.num_starts, context);
  return starts;
}

// result.json's "resumed": the starts an earlier attempt finished, kept by this one.
nlohmann::json ResumedJson(const store::Job& job, std::vector<int> kept_starts) {
  std::sort(kept_starts.begin(), kept_starts.end());
  return {{"attempt", job.attempts}, {"finished_starts", kept_starts}};
}

// The job's lease, renewed while it runs; a cancel request stops it.
LeaseCalls JobLease(const store::Job& job, const std::string& worker_id,
                    const JobRunnerContext& context) {
  LeaseCalls calls;
  calls.renew = [&] { return context.jobs->RenewLease(job.id, worker_id, context.lease); };
  calls.stop_requested = [&] {
    Result<bool> requested = context.jobs->IsCancelRequested(job.id);
    return requested.ok() && *requested;
  };
  calls.on_lost = [&](const Status& why) {
    context.logger->warn("job {}: lease lost, stopping: {}", job.id, why.message());
  };
  return calls;
}

// A fit's progress into the job's history, each iteration; a cancel request seen between
// iterations stops the fit at once (and, with a heartbeat, tells it the stop was asked for).
std::function<void(const inverse::FitProgress&)> ProgressRecorder(
    const store::Job& job, const inverse::JobConfig& config, Stopwatch::time_point started,
    const JobRunnerContext& context, std::atomic<bool>& cancel, LeaseHeartbeat* heartbeat) {
  return [&job, &config, started, &context, &cancel, heartbeat](const inverse::FitProgress& p) {
    const double elapsed = std::chrono::duration<double>(Stopwatch::now() - started).count();
    RecordIteration(job, IterationEvent(p, config, elapsed), context);
    Result<bool> requested = context.jobs->IsCancelRequested(job.id);
    if (requested.ok() && *requested) {
      if (heartbeat != nullptr) heartbeat->set_stop_requested();
      cancel.store(true);
    }
  };
}

// The fit, every start in this worker: progress into the job's history (a cancel request seen
// between iterations stops it at once), a checkpoint saved after every start, and the starts an
// earlier attempt finished kept.
Result<inverse::FitResult> FitHere(const store::Job& job, const capture::Capture& capture,
                                   const inverse::JobConfig& config,
                                   const std::optional<inverse::FitCheckpoint>& resume_from,
                                   const JobRunnerContext& context,
                                   std::chrono::steady_clock::time_point started,
                                   std::atomic<bool>& cancel, LeaseHeartbeat& heartbeat) {
  inverse::FitOptions options;
  options.cancel = &cancel;
  options.on_progress = ProgressRecorder(job, config, started, context, cancel, &heartbeat);
  if (resume_from) options.resume_from = &*resume_from;
  options.on_checkpoint = [&](const inverse::FitCheckpoint& checkpoint) {
    if (Status saved = context.jobs->SaveCheckpoint(job.id, inverse::ToJson(checkpoint));
        !saved.ok()) {
      context.logger->warn("job {}: checkpoint not saved: {}", job.id, saved.message());
    }
  };
  return inverse::Fit(capture, config, options);
}

// The diagnosis of a finished fit ("diagnose": true): its stages are recorded as notes in the
// job's progress history, and its report goes into the result as "diagnosis". A diagnosis that
// fails leaves the fit's result standing, with {"error": ...} as its report. Its plots go into
// the job's report folder (report_dir/diagnosis).
// With fan-out, its refits run as tasks any worker can claim (refit_tasks.h).
nlohmann::json RunDiagnosis(const store::Job& job, const capture::Capture& capture,
                            const inverse::JobConfig& config, const inverse::FitResult& fit,
                            const std::string& worker_id, std::atomic<bool>& cancel,
                            const JobRunnerContext& context, const fs::path& report_dir) {
  diagnosis::DiagnoseOptions options;
  if (context.reports != nullptr) options.plot_directory = report_dir / "diagnosis";
  options.fit.cancel = &cancel;
  int batches = 0;
  if (context.fan_out_starts) {
    options.run_fits = [&](const std::vector<inverse::JobConfig>& configs) {
      return FitBatchByTasks(job, capture, configs, ++batches, worker_id, context, cancel);
    };
  }
  options.on_stage = [&](const std::string& stage) {
    RecordNote(job, "diagnosis: " + stage, context);
  };
  Result<diagnosis::DiagnosisReport> report = diagnosis::Diagnose(capture, config, options, &fit);
  if (!report.ok()) {
    context.logger->warn("job {}: diagnosis failed: {}", job.id, report.status().message());
    return {{"error", report.status().message()}};
  }
  context.logger->info("job {}: diagnosis: {}", job.id, report->decision);
  nlohmann::json json = diagnosis::ToJson(*report);
  // Plots by their names in the job's report (DownloadArtifact), not the worker's folder.
  for (nlohmann::json& plot : json["plots"]) {
    if (plot.is_string())
      plot = fs::path(plot.get<std::string>()).lexically_relative(report_dir).generic_string();
  }
  return json;
}

// The fit's pictures into `dir` (core/diagnosis/fit_report.h); what result.json records of them,
// or {"error": ...} when they could not be drawn (the fitted values stand).
nlohmann::json DrawReport(const store::Job& job, const capture::Capture& capture,
                          const inverse::JobConfig& config, const inverse::FitResult& fit,
                          std::atomic<bool>& cancel, const JobRunnerContext& context,
                          const fs::path& dir) {
  diagnosis::FitReportOptions options;
  options.cancel = &cancel;
  Result<diagnosis::FitReport> report =
      diagnosis::WriteFitReport(capture, config, fit, dir, options);
  if (!report.ok()) {
    context.logger->warn("job {}: no report: {}", job.id, report.status().message());
    return {{"error", report.status().message()}};
  }
  context.logger->info("job {}: report drawn in {:.1f} s", job.id, report->seconds);
  return diagnosis::ToJson(*report);
}

// Moves the report folder (when anything was drawn) to the job's kept report, before the job is
// marked SUCCEEDED so that a client who sees the result can download its files.
void KeepReport(const store::Job& job, const fs::path& dir, const JobRunnerContext& context,
                nlohmann::json* result_json) {
  std::error_code ignored;
  if (context.reports == nullptr || !fs::exists(dir, ignored)) return;
  if (Status kept = context.reports->Keep(job.id, dir); !kept.ok()) {
    context.logger->warn("job {}: report not kept: {}", job.id, kept.message());
    (*result_json)["report"] = {{"error", "the report could not be stored"}};
  }
}

// One attempt at a claimed job: what the stages of RunClaimedJob share.
struct JobAttempt {
  const store::Job& job;
  const std::string& worker_id;
  const JobRunnerContext& context;
  const inverse::JobConfig& config;
  std::atomic<bool>& cancel;
  Stopwatch::time_point started;
  fs::path report_dir;  // the pictures, in the job's work folder
};

// What an attempt produced while its lease was renewed, for the outcome to record.
struct AttemptResults {
  bool lost = false;
  bool cancel_requested = false;
  Result<inverse::FitResult> fit = Status::Internal("the fit did not run");
  nlohmann::json ingest_json;                          // a job on a recording only
  nlohmann::json diagnosis_json;                       // "diagnose": true only
  nlohmann::json report_json;                          // the pictures (core/diagnosis/fit_report.h)
  std::optional<inverse::FitUncertainty> uncertainty;  // "uncertainty": true (the default)
  std::string uncertainty_error;
  nlohmann::json refinement_json;  // "refine_grid": true only
  nlohmann::json resumed_json;     // when an earlier attempt's starts were kept
  Status prepared;                 // the capture laid out (a recording ingested)
};

// "refine_grid": the refit on a finer grid where the grid moves a fitted value
// (core/inverse/grid_refinement.h), its iterations in the job's history; the refit and its
// analysis replace the fit's in `out`, and *config becomes what the refit was computed with.
void RefineGrid(const JobAttempt& attempt, const capture::Capture& capture,
                inverse::JobConfig* config, AttemptResults* out) {
  const store::Job& job = attempt.job;
  const JobRunnerContext& context = attempt.context;
  inverse::FitOptions options;
  options.cancel = &attempt.cancel;
  options.on_progress =
      ProgressRecorder(job, *config, attempt.started, context, attempt.cancel, nullptr);
  inverse::ControlledFit controlled = inverse::ControlGrid(
      capture, *config, std::move(out->fit).value(), std::move(*out->uncertainty), options);
  RecordNote(job, "grid refinement: " + controlled.refinement.decision.reason, context);
  out->fit = std::move(controlled.fit);
  out->uncertainty = std::move(controlled.uncertainty);
  out->uncertainty_error = controlled.uncertainty_error;
  out->refinement_json = inverse::ToJson(controlled.refinement);
  *config = std::move(controlled.config);
}

// What is derived from a fit that ran to its end: its uncertainty, diagnosis and pictures, as
// the config asks.
void DeriveFromFit(const JobAttempt& attempt, const Result<capture::Capture>& capture,
                   AttemptResults* out) {
  const store::Job& job = attempt.job;
  const JobRunnerContext& context = attempt.context;
  std::atomic<bool>& cancel = attempt.cancel;
  Result<inverse::FitResult>& result = out->fit;
  // What the fit was computed with: the job's config, on the finer grid after a refinement.
  inverse::JobConfig config = attempt.config;
  if (result.ok() && !result->cancelled && config.uncertainty) {
    Result<inverse::FitUncertainty> estimated =
        inverse::EstimateFitUncertainty(*capture, config, *result);
    if (estimated.ok()) {
      out->uncertainty = std::move(estimated).value();
    } else {
      out->uncertainty_error = estimated.status().message();
      context.logger->warn("job {}: no uncertainty: {}", job.id, out->uncertainty_error);
    }
  }
  if (result.ok() && !result->cancelled && config.refine_grid && out->uncertainty &&
      !cancel.load()) {
    RefineGrid(attempt, *capture, &config, out);
  }
  if (result.ok() && !result->cancelled && config.diagnose) {
    out->diagnosis_json = RunDiagnosis(job, *capture, config, *result, attempt.worker_id, cancel,
                                       context, attempt.report_dir);
  }
  if (result.ok() && !result->cancelled && !cancel.load() && context.reports != nullptr) {
    out->report_json =
        DrawReport(job, *capture, config, *result, cancel, context, attempt.report_dir);
  }
}

// The attempt's work while its lease is renewed: the capture laid out in `work_dir` (a recording
// ingested), the fit, and what is derived from it.
// The heartbeat stops before the outcome is written, so it never renews a lease that the
// outcome just gave up (which would look like a lost lease). It runs during an ingest too,
// which can take minutes on a long recording.
AttemptResults RunUnderLease(const JobAttempt& attempt, const store::Capture& stored,
                             const std::optional<inverse::FitCheckpoint>& resume_from,
                             const fs::path& work_dir) {
  const store::Job& job = attempt.job;
  const std::string& worker_id = attempt.worker_id;
  const JobRunnerContext& context = attempt.context;
  std::atomic<bool>& cancel = attempt.cancel;
  AttemptResults out;
  LeaseHeartbeat heartbeat(JobLease(job, worker_id, context), context.heartbeat_interval, cancel);
  Result<capture::Capture> capture =
      PrepareCapture(job, stored, worker_id, context, work_dir, cancel, &out.ingest_json);
  if (!capture.ok()) out.prepared = capture.status();
  std::vector<int> kept_starts;  // finished on an earlier attempt
  if (capture.ok() && !cancel.load()) {
    if (context.fan_out_starts) {
      out.fit = FitByStartTasks(job, *capture, attempt.config, resume_from, worker_id, context,
                                cancel, &kept_starts);
    } else {
      if (resume_from) kept_starts = FinishedStarts(job, *resume_from, context);
      out.fit = FitHere(job, *capture, attempt.config, resume_from, context, attempt.started,
                        cancel, heartbeat);
    }
  }
  if (!kept_starts.empty()) out.resumed_json = ResumedJson(job, kept_starts);
  DeriveFromFit(attempt, capture, &out);
  out.lost = heartbeat.lost();
  out.cancel_requested = heartbeat.stop_requested();
  return out;
}

// A fit that stopped early: handed back to the queue when a shutdown stopped it, else CANCELLED.
JobOutcome RecordStoppedEarly(const store::Job& job, const std::string& worker_id,
                              const JobRunnerContext& context, bool cancel_requested,
                              const std::atomic<bool>& shutdown) {
  const auto& log = context.logger;
  if (!cancel_requested && shutdown.load()) {
    // Handed back at once, so a clean shutdown leaves nothing RUNNING, and the attempt is not
    // held against max_attempts: the job did nothing wrong.
    if (Status released = context.jobs->ReleaseJob(job.id, worker_id, "the server shut down");
        !released.ok()) {
      log->warn("job {}: not released ({}); the next start requeues it", job.id,
                released.message());
    } else {
      log->info("job {}: interrupted by shutdown; QUEUED again", job.id);
    }
    context.events->Notify(job.id);
    return JobOutcome::kInterrupted;
  }
  if (Status marked = context.jobs->MarkCancelled(job.id); !marked.ok()) {
    log->error("job {}: cannot mark CANCELLED: {}", job.id, marked.message());
  }
  context.events->Notify(job.id);
  log->info("job {}: CANCELLED", job.id);
  return JobOutcome::kCancelled;
}

// Records the fit's result, with what was derived from it, and keeps its report.
JobOutcome RecordSuccess(const JobAttempt& attempt, AttemptResults& results) {
  const store::Job& job = attempt.job;
  const JobRunnerContext& context = attempt.context;
  const auto& log = context.logger;
  const Result<inverse::FitResult>& result = results.fit;
  nlohmann::json result_json = inverse::ToJson(
      *result, results.uncertainty ? &*results.uncertainty : nullptr, results.uncertainty_error);
  if (!results.diagnosis_json.is_null()) {
    result_json["diagnosis"] = std::move(results.diagnosis_json);
  }
  if (!results.ingest_json.is_null()) result_json["ingest"] = std::move(results.ingest_json);
  if (!results.report_json.is_null()) result_json["report"] = std::move(results.report_json);
  if (!results.resumed_json.is_null()) result_json["resumed"] = std::move(results.resumed_json);
  if (!results.refinement_json.is_null())
    result_json["grid_refinement"] = std::move(results.refinement_json);
  KeepReport(job, attempt.report_dir, context, &result_json);
  if (Status completed = context.jobs->CompleteJob(job.id, result_json); !completed.ok()) {
    log->error("job {}: cannot record the result: {}", job.id, completed.message());
    if (context.reports != nullptr) context.reports->Remove(job.id);
    context.events->Notify(job.id);
    return JobOutcome::kFailed;
  }
  context.events->Notify(job.id);
  log->info("job {}: SUCCEEDED in {:.1f} s (final cost {:.4e})", job.id,
            std::chrono::duration<double>(Stopwatch::now() - attempt.started).count(),
            result->Best().final_cost);
  return JobOutcome::kSucceeded;
}

}  // namespace

const char* ToString(JobOutcome outcome) {
  switch (outcome) {
    case JobOutcome::kSucceeded: return "succeeded";
    case JobOutcome::kFailed: return "failed";
    case JobOutcome::kCancelled: return "cancelled";
    case JobOutcome::kInterrupted: return "interrupted";
    case JobOutcome::kLost: return "lost";
  }
  return "unknown";
}

JobOutcome RunClaimedJob(const store::Job& job, const std::string& worker_id,
                         const JobRunnerContext& context, std::atomic<bool>& cancel,
                         const std::atomic<bool>& shutdown) {
  const auto& log = context.logger;
  const Stopwatch::time_point started = Stopwatch::now();
  log->info("job {}: RUNNING on {} (attempt {})", job.id, worker_id, job.attempts);

  // The config was validated at CreateJob; parsing again guards against a store edited by hand.
  Result<inverse::JobConfig> config = inverse::JobConfigFromJson(job.config);
  if (!config.ok()) return Fail(job, context, "config: " + config.status().message());
  if (config->solver.threads == 0 && context.cores_per_job > 0)
    config->solver.threads = context.cores_per_job;
  Result<store::Capture> stored = context.jobs->GetCapture(job.capture_id);
  if (!stored.ok()) return Fail(job, context, stored.status().message());

  WorkFolder folder(context.work_root / job.id);
  const JobAttempt attempt{.job = job,
                           .worker_id = worker_id,
                           .context = context,
                           .config = *config,
                           .cancel = cancel,
                           .started = started,
                           .report_dir = folder.path / "report"};
  const std::optional<inverse::FitCheckpoint> resume_from = EarlierCheckpoint(job, context);
  AttemptResults results = RunUnderLease(attempt, *stored, resume_from, folder.path);

  if (results.lost) return JobOutcome::kLost;
  // An ingest stopped by a cancel or a shutdown is handled as a stopped fit below.
  const bool ingest_stopped = results.prepared.code() == StatusCode::kCancelled && cancel.load();
  if (!results.prepared.ok() && !ingest_stopped) {
    return Fail(job, context, results.prepared.message());
  }
  // A fit that ran to its end is recorded whatever was asked meanwhile; only one that stopped
  // early (or whose diagnosis or grid refinement did) is a cancel or an interruption: a shutdown
  // then resumes from the fit's checkpoint.
  const Result<inverse::FitResult>& result = results.fit;
  const bool stopped_early =
      result.ok()
          ? result->cancelled || ((config->diagnose || config->refine_grid) && cancel.load())
          : cancel.load();
  if (stopped_early) {
    return RecordStoppedEarly(job, worker_id, context, results.cancel_requested, shutdown);
  }
  if (!result.ok()) return Fail(job, context, result.status().message());
  return RecordSuccess(attempt, results);
}

}  // namespace softid::server
