#include "server/job_service.h"

#include <spdlog/spdlog.h>

#include <fstream>

#include "core/inverse/job_config.h"

namespace softid::server {
namespace {

// The store reports a request_id reused with other arguments as FailedPrecondition whose message
// starts with the key (job_store.h: the API layer reports it as ALREADY_EXISTS).
ServiceStatus FromStoreCreate(const Status& status) {
  if (status.code() == StatusCode::kFailedPrecondition &&
      status.message().rfind("request_id '", 0) == 0) {
    return ServiceStatus(ServiceCode::kAlreadyExists, status.message());
  }
  return status;
}

}  // namespace

JobService::JobService(store::JobStore* jobs, const store::BlobStore* blobs, JobEvents* events,
                       JobServiceOptions options, std::shared_ptr<spdlog::logger> logger)
    : jobs_(jobs),
      blobs_(blobs),
      events_(events),
      options_(std::move(options)),
      logger_(logger ? std::move(logger) : spdlog::default_logger()) {}

ServiceResult<std::unique_ptr<CaptureUpload>> JobService::BeginUpload(UploadManifest manifest) {
  if (draining()) return ServiceStatus(ServiceCode::kUnavailable, "the server is shutting down");
  return CaptureUpload::Begin(std::move(manifest), options_.staging_root, options_.upload_limits);
}

ServiceResult<store::Capture> JobService::FinishUpload(CaptureUpload& upload) {
  ServiceResult<std::vector<store::ManifestEntry>> manifest = upload.Finish();
  if (!manifest.ok()) return manifest.status();
  // Blobs before the row: a committed capture never points at a missing blob. A failure part way
  // leaves only unreferenced content-addressed files, which no capture can see.
  for (const store::ManifestEntry& entry : *manifest) {
    std::ifstream in(upload.staging_dir() / entry.path, std::ios::binary);
    if (!in) {
      return ServiceStatus(ServiceCode::kInternal, "cannot reopen staged file " + entry.path);
    }
    Result<std::string> put = blobs_->Put(
        in, store::PutOptions{.expected_sha256 = entry.sha256, .source_name = entry.path});
    if (!put.ok()) return put.status();
  }
  Result<store::Capture> capture = jobs_->CreateCapture(*manifest, upload.request_id());
  if (!capture.ok()) return FromStoreCreate(capture.status());
  logger_->info("capture {}: stored {} files (request_id '{}')", capture->id,
                capture->manifest.size(), capture->request_id);
  return *capture;
}

ServiceResult<store::Job> JobService::CreateJob(const std::string& capture_id,
                                                const std::string& config_json,
                                                const std::string& request_id) {
  if (draining()) return ServiceStatus(ServiceCode::kUnavailable, "the server is shutting down");
  const nlohmann::json config = nlohmann::json::parse(config_json.empty() ? "{}" : config_json,
                                                      nullptr, /*allow_exceptions=*/false);
  if (config.is_discarded()) {
    return ServiceStatus(ServiceCode::kInvalidArgument, "config_json: invalid JSON");
  }
  if (Result<inverse::JobConfig> parsed = inverse::JobConfigFromJson(config); !parsed.ok()) {
    return ServiceStatus(ServiceCode::kInvalidArgument,
                         "config_json: " + parsed.status().message());
  }
  // Before counting the queue: an unknown capture is NOT_FOUND even when the queue is full.
  if (Result<store::Capture> capture = jobs_->GetCapture(capture_id); !capture.ok()) {
    return capture.status();
  }
  Result<int64_t> queued = jobs_->CountJobs(store::JobState::kQueued);
  if (!queued.ok()) return queued.status();
  if (*queued >= options_.max_queued_jobs) {
    return ServiceStatus(ServiceCode::kResourceExhausted,
                         "the queue is full: " + std::to_string(*queued) +
                             " jobs are QUEUED (max_queued " +
                             std::to_string(options_.max_queued_jobs) + "); retry later");
  }
  Result<store::Job> job = jobs_->CreateJob(capture_id, config, request_id);
  if (!job.ok()) return FromStoreCreate(job.status());
  logger_->info("job {}: QUEUED for capture {} (request_id '{}')", job->id, capture_id, request_id);
  events_->Notify(job->id);
  if (options_.on_job_queued) options_.on_job_queued();
  return *job;
}

ServiceResult<store::Job> JobService::GetJob(const std::string& job_id) {
  Result<store::Job> job = jobs_->GetJob(job_id);
  if (!job.ok()) return job.status();
  return *job;
}

ServiceResult<store::JobPage> JobService::ListJobs(const store::ListJobsRequest& request) {
  Result<store::JobPage> page = jobs_->ListJobs(request);
  if (!page.ok()) return page.status();
  return *page;
}

ServiceResult<store::Job> JobService::CancelJob(const std::string& job_id) {
  Result<store::Job> job = jobs_->RequestCancel(job_id);
  if (!job.ok()) return job.status();
  events_->Notify(job_id);
  logger_->info("job {}: cancel requested ({})", job_id, store::ToString(job->state));
  return *job;
}

ServiceStatus JobService::DeleteJob(const std::string& job_id) {
  if (Status deleted = jobs_->DeleteJob(job_id); !deleted.ok()) return deleted;
  events_->Notify(job_id);
  logger_->info("job {}: deleted", job_id);
  return ServiceStatus::Ok();
}

ServiceResult<JobResult> JobService::GetResult(const std::string& job_id) {
  Result<store::Job> job = jobs_->GetJob(job_id);
  if (!job.ok()) return job.status();
  if (job->state != store::JobState::kSucceeded || !job->result.has_value()) {
    return ServiceStatus(ServiceCode::kFailedPrecondition,
                         "job " + job_id + " is " + store::ToString(job->state) +
                             ": a result exists once it SUCCEEDED");
  }
  JobResult out{job_id, *job->result, {}};
  if (auto it = job->result->find("cost_history"); it != job->result->end() && it->is_array()) {
    for (const nlohmann::json& cost : *it) {
      if (cost.is_number()) out.cost_history.push_back(cost.get<double>());
    }
  }
  return out;
}

ServiceStatus JobService::WatchJob(const std::string& job_id, int from_iteration,
                                   const EventSink& send, const std::function<bool()>& stop) {
  int64_t last_seq = 0;
  uint64_t version = events_->Version(job_id);
  while (true) {
    // The job before its history: if it is terminal now, its final event is already listed.
    Result<store::Job> job = jobs_->GetJob(job_id);
    if (!job.ok()) return job.status();
    Result<std::vector<store::ProgressEvent>> events = jobs_->ListProgress(job_id, from_iteration);
    if (!events.ok()) return events.status();
    for (const store::ProgressEvent& event : *events) {
      if (event.seq <= last_seq) continue;
      if (!send(event, *job)) return ServiceStatus(ServiceCode::kCancelled, "the watcher left");
      last_seq = event.seq;
    }
    if (store::IsTerminal(job->state)) return ServiceStatus::Ok();
    if (stop && stop()) return ServiceStatus(ServiceCode::kCancelled, "the watcher left");
    if (draining()) {
      return ServiceStatus(
          ServiceCode::kUnavailable,
          "the server is shutting down; resume the watch from iteration " +
              std::to_string(events->empty() ? from_iteration : events->back().iteration));
    }
    version = events_->WaitForChange(job_id, version, options_.watch_poll_interval);
  }
}

void JobService::StartDraining() {
  draining_.store(true);
  events_->NotifyAll();
}

}  // namespace softid::server
