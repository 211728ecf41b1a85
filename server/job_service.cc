#include "server/job_service.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <fstream>
#include <unordered_set>

#include "core/common/untrusted_json.h"
#include "core/inverse/job_config.h"
#include "server/capture_extent.h"
#include "server/store/resource_id.h"

namespace softid::server {
namespace {

// A job config is a few hundred bytes; a stiffness field may list a few thousand values.
constexpr json::UntrustedJsonLimits kConfigJsonLimits{.max_bytes = 1u << 20, .max_depth = 16};

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
      logger_(logger ? std::move(logger) : spdlog::default_logger()),
      rate_limiter_(options_.quotas.requests_per_second, options_.quotas.request_burst),
      blob_puts_(options_.blob_puts != nullptr ? *options_.blob_puts : own_blob_puts_) {}

JobService::StationState& JobService::Station(const std::string& station) {
  std::lock_guard lock(stations_mutex_);
  std::unique_ptr<StationState>& state = stations_[station];
  if (!state) state = std::make_unique<StationState>();
  return *state;
}

ServiceStatus JobService::Admit(const Caller& caller) {
  if (caller.admin || rate_limiter_.Admit(caller.station)) return ServiceStatus::Ok();
  return ServiceStatus(
      ServiceCode::kResourceExhausted,
      fmt::format("station \"{}\": more than {:g} calls per second (bursts of {:g}); retry later",
                  caller.station, options_.quotas.requests_per_second,
                  options_.quotas.request_burst));
}

// ResourceExhausted when `adding` more bytes would take the station past its stored-bytes quota.
ServiceStatus JobService::CheckStoredBytes(const Caller& caller, int64_t adding) {
  if (caller.admin) return ServiceStatus::Ok();
  Result<int64_t> stored = jobs_->StoredBytes(caller.station);
  if (!stored.ok()) return stored.status();
  const int64_t quota = options_.quotas.max_stored_bytes;
  if (*stored + adding <= quota) return ServiceStatus::Ok();
  return ServiceStatus(ServiceCode::kResourceExhausted,
                       fmt::format("station \"{}\" stores {} bytes of captures; {} more would "
                                   "exceed its quota of {} bytes: delete captures first",
                                   caller.station, *stored, adding, quota));
}

ServiceResult<std::unique_ptr<CaptureUpload>> JobService::BeginUpload(const Caller& caller,
                                                                      UploadManifest manifest) {
  if (draining()) return ServiceStatus(ServiceCode::kUnavailable, "the server is shutting down");
  if (Status valid = store::CheckRequestId(manifest.request_id); !valid.ok()) return valid;
  StationState& station = Station(caller.station);
  {
    std::lock_guard lock(stations_mutex_);
    if (!caller.admin && station.uploads >= options_.quotas.max_concurrent_uploads) {
      return ServiceStatus(ServiceCode::kResourceExhausted,
                           fmt::format("station \"{}\": {} uploads in progress, its quota; "
                                       "retry when one has finished",
                                       caller.station, station.uploads));
    }
    ++station.uploads;
  }
  const int limit = options_.upload_limits.max_concurrent;
  if (uploads_in_progress_.fetch_add(1) >= limit) {
    uploads_in_progress_.fetch_sub(1);
    std::lock_guard lock(stations_mutex_);
    --station.uploads;
    return ServiceStatus(ServiceCode::kResourceExhausted,
                         "uploads: " + std::to_string(limit) +
                             " are in progress, the most accepted at once; retry later");
  }
  std::shared_ptr<void> slot(nullptr, [this, &station](void*) {
    uploads_in_progress_.fetch_sub(1);
    std::lock_guard lock(stations_mutex_);
    --station.uploads;
  });
  ServiceResult<std::unique_ptr<CaptureUpload>> upload =
      CaptureUpload::Begin(std::move(manifest), options_.staging_root, options_.upload_limits);
  if (!upload.ok()) return upload;
  (*upload)->HoldSlot(std::move(slot));
  // After Begin, which bounds every declared size and their sum (summing a client's sizes first
  // could overflow): a station out of room learns it before sending any file.
  if (ServiceStatus room = CheckStoredBytes(caller, (*upload)->declared_bytes()); !room.ok()) {
    return room;
  }
  return upload;
}

ServiceResult<std::vector<std::string>> JobService::FindCaptureFiles(
    const Caller& caller, const std::vector<std::string>& sha256s) {
  if (static_cast<int64_t>(sha256s.size()) > options_.upload_limits.max_files) {
    return ServiceStatus(ServiceCode::kInvalidArgument,
                         fmt::format("sha256: {} hashes (at most {})", sha256s.size(),
                                     options_.upload_limits.max_files));
  }
  ServiceResult<std::unordered_set<std::string>> held = HeldFiles(caller);
  if (!held.ok()) return held.status();
  std::vector<std::string> out;
  for (const std::string& sha256 : sha256s)
    if (held->count(sha256) > 0) out.push_back(sha256);
  return out;
}

ServiceResult<std::unordered_set<std::string>> JobService::HeldFiles(const Caller& caller) {
  std::unordered_set<std::string> held;
  store::ListCapturesRequest request;
  request.page_size = store::ListJobsRequest::kMaxPageSize;  // the same bound for captures
  do {
    ServiceResult<store::CapturePage> page = ListCaptures(caller, request);
    if (!page.ok()) return page.status();
    for (const store::CaptureListing& listing : page->captures) {
      for (const store::ManifestEntry& entry : listing.capture.manifest) held.insert(entry.sha256);
    }
    request.page_token = page->next_page_token;
  } while (!request.page_token.empty());
  return held;
}

ServiceStatus JobService::AddHeldFiles(const Caller& caller, CaptureUpload& upload) {
  const std::vector<store::ManifestEntry> missing = upload.FilesNotStarted();
  if (missing.empty()) return ServiceStatus::Ok();
  ServiceResult<std::unordered_set<std::string>> held = HeldFiles(caller);
  if (!held.ok()) return held.status();
  std::string buffer(static_cast<size_t>(options_.upload_limits.max_chunk_bytes), '\0');
  int added = 0;
  for (const store::ManifestEntry& entry : missing) {
    if (held->count(entry.sha256) == 0) continue;  // Finish names it as incomplete
    Result<std::ifstream> in = blobs_->OpenBlob(entry.sha256);
    if (!in.ok()) continue;
    int64_t offset = 0;
    while (*in) {
      in->read(buffer.data(), static_cast<std::streamsize>(buffer.size()));
      const std::string_view data(buffer.data(), static_cast<size_t>(in->gcount()));
      if (data.empty()) break;
      if (ServiceStatus fed = upload.AddChunk(entry.path, offset, data); !fed.ok()) return fed;
      offset += static_cast<int64_t>(data.size());
    }
    ++added;
  }
  if (added > 0) logger_->info("upload: {} file(s) taken from the server's copies", added);
  return ServiceStatus::Ok();
}

ServiceResult<store::Capture> JobService::FinishUpload(const Caller& caller,
                                                       CaptureUpload& upload) {
  {
    // Shared: a capture's removal cannot take the blobs away while they are read.
    std::shared_lock puts(blob_puts_);
    if (ServiceStatus added = AddHeldFiles(caller, upload); !added.ok()) return added;
  }
  ServiceResult<std::vector<store::ManifestEntry>> manifest = upload.Finish();
  if (!manifest.ok()) return manifest.status();
  // Blobs before the row: a committed capture never points at a missing blob. Blobs this upload
  // added are removed again if it fails before its row is committed (disk full part way, a
  // request_id reused for other files), unless another capture refers to them by then.
  std::vector<std::string> added;
  // The station's quota is checked again with its commits ordered, so two of its uploads cannot
  // both fit the last of its room.
  std::lock_guard quota(Station(caller.station).quota);
  int64_t bytes = 0;
  for (const store::ManifestEntry& entry : *manifest) bytes += entry.size_bytes;
  if (ServiceStatus room = CheckStoredBytes(caller, bytes); !room.ok()) return room;
  ServiceResult<store::Capture> capture = [&]() -> ServiceResult<store::Capture> {
    std::shared_lock puts(blob_puts_);
    for (const store::ManifestEntry& entry : *manifest) {
      std::ifstream in(upload.staging_dir() / entry.path, std::ios::binary);
      if (!in) {
        return ServiceStatus(ServiceCode::kInternal, "cannot reopen staged file " + entry.path);
      }
      const bool existed = blobs_->Has(entry.sha256);
      Result<std::string> put = blobs_->Put(
          in, store::PutOptions{.expected_sha256 = entry.sha256, .source_name = entry.path});
      if (!put.ok()) return put.status();
      if (!existed) added.push_back(entry.sha256);
    }
    Result<store::Capture> created =
        jobs_->CreateCapture(*manifest, upload.request_id(), caller.station, upload.format());
    if (!created.ok()) return FromStoreCreate(created.status());
    return *created;
  }();
  if (!capture.ok()) {
    RemoveUnreferencedBlobs(added);
    if (options_.metrics != nullptr) options_.metrics->CountUpload(false, 0);
    return capture.status();
  }
  if (options_.metrics != nullptr) options_.metrics->CountUpload(true, bytes);
  logger_->info("capture {}: stored {} files, {} (request_id '{}')", capture->id,
                capture->manifest.size(), capture->format, capture->request_id);
  return capture;
}

void JobService::RemoveUnreferencedBlobs(const std::vector<std::string>& sha256s) {
  if (sha256s.empty()) return;
  // Exclusive: every other upload is either before its first put or past its commit, so a blob
  // that no committed capture lists now is not about to be listed by one.
  std::unique_lock puts(blob_puts_);
  int removed = 0;
  for (const std::string& sha256 : sha256s) {
    Result<bool> referenced = jobs_->IsBlobReferenced(sha256);
    if (!referenced.ok()) {
      logger_->warn("blob {}: kept: {}", sha256, referenced.status().message());
      continue;
    }
    if (*referenced) continue;
    if (Status gone = blobs_->Remove(sha256); !gone.ok()) {
      logger_->warn("blob {}: {}", sha256, gone.message());
      continue;
    }
    ++removed;
  }
  logger_->info("removed {} of {} blob(s) no capture lists any more", removed, sha256s.size());
}

ServiceResult<store::Job> JobService::CreateJob(const Caller& caller, const std::string& capture_id,
                                                const std::string& config_json,
                                                const std::string& request_id) {
  if (draining()) return ServiceStatus(ServiceCode::kUnavailable, "the server is shutting down");
  if (Status valid = store::CheckRequestId(request_id); !valid.ok()) return valid;
  Result<nlohmann::json> parsed_json = json::ParseUntrustedJson(
      config_json.empty() ? "{}" : config_json, "config_json", kConfigJsonLimits);
  if (!parsed_json.ok()) return parsed_json.status();
  const nlohmann::json& config = *parsed_json;
  Result<inverse::JobConfig> parsed = inverse::JobConfigFromJson(config);
  if (!parsed.ok()) {
    return ServiceStatus(ServiceCode::kInvalidArgument,
                         "config_json: " + parsed.status().message());
  }
  if (ServiceStatus fits = CheckJobFitsCapture(caller, *parsed, capture_id, request_id);
      !fits.ok()) {
    return fits;
  }
  // The station's quota: checked with its creates ordered; a repeated request_id still gets its
  // job back (the store returns it) when the station is at its quota.
  std::lock_guard quota(Station(caller.station).quota);
  Result<int64_t> queued = jobs_->CountJobs(store::JobState::kQueued, caller.station);
  if (!queued.ok()) return queued.status();
  if (!caller.admin && *queued >= options_.quotas.max_queued_jobs) {
    Result<bool> repeat = jobs_->HasJobWithRequestId(request_id, caller.station);
    if (!repeat.ok()) return repeat.status();
    if (!*repeat) {
      return ServiceStatus(ServiceCode::kResourceExhausted,
                           fmt::format("station \"{}\" has {} jobs QUEUED, its quota; retry when "
                                       "some have started",
                                       caller.station, *queued));
    }
  }
  // The store checks the bound in the transaction that inserts, so concurrent creates cannot
  // overshoot it, and a repeated request_id gets its job back even when the queue is full.
  Result<std::optional<store::Job>> job = jobs_->CreateJobBounded(
      capture_id, config, request_id, options_.max_queued_jobs, caller.station);
  if (!job.ok()) return FromStoreCreate(job.status());
  if (!job->has_value()) {
    return ServiceStatus(
        ServiceCode::kResourceExhausted,
        "the queue is full: max_queued = " + std::to_string(options_.max_queued_jobs) +
            " jobs are QUEUED already; retry later");
  }
  const store::Job& created = **job;
  logger_->info("job {}: {} for capture {} (request_id '{}')", created.id,
                store::ToString(created.state), capture_id, request_id);
  events_->Notify(created.id);
  if (options_.on_job_queued) options_.on_job_queued();
  return created;
}

ServiceStatus JobService::CheckJobFitsCapture(const Caller& caller,
                                              const inverse::JobConfig& config,
                                              const std::string& capture_id,
                                              const std::string& request_id) {
  Result<store::Capture> capture = jobs_->GetCapture(capture_id);
  if (!capture.ok()) {
    // A repeated request whose capture was deleted since still gets its job back from the store.
    if (!request_id.empty() && capture.status().code() == StatusCode::kNotFound) {
      return ServiceStatus::Ok();
    }
    return capture.status();
  }
  if (!caller.Sees(capture->owner)) {
    return ServiceStatus(ServiceCode::kNotFound, "capture " + capture_id + " not found");
  }
  const bool auto_cells =
      config.solver.cell_size_m <= 0.0 && config.solver.cells == inverse::kAutoCells;
  ServiceResult<inverse::CaptureExtent> extent =
      ReadCaptureExtent(*capture, *blobs_, options_.scratch_root, auto_cells);
  if (!extent.ok()) return extent.status();
  Result<inverse::JobResourceEstimate> estimate =
      inverse::EstimateJobResources(config, *extent, options_.job_limits);
  if (!estimate.ok()) {
    return ServiceStatus(ServiceCode::kInvalidArgument,
                         "config_json: " + estimate.status().message());
  }
  logger_->info("capture {}: a job estimated at {:.2g} GiB and at most {:.3g} min accepted",
                capture_id, estimate->memory_bytes / (1ull << 30), estimate->wall_seconds / 60.0);
  return ServiceStatus::Ok();
}

ServiceStatus JobService::DeleteCapture(const Caller& caller, const std::string& capture_id) {
  Result<store::Capture> capture = jobs_->GetCapture(capture_id);
  if (!capture.ok()) return capture.status();
  if (!caller.Sees(capture->owner)) {
    return ServiceStatus(ServiceCode::kNotFound, "capture " + capture_id + " not found");
  }
  Result<store::Capture> deleted = jobs_->DeleteCapture(capture_id);
  if (!deleted.ok()) return deleted.status();
  std::vector<std::string> sha256s;
  for (const store::ManifestEntry& entry : deleted->manifest) sha256s.push_back(entry.sha256);
  RemoveUnreferencedBlobs(sha256s);
  logger_->info("capture {}: deleted", capture_id);
  return ServiceStatus::Ok();
}

namespace {

// Sends the rest of `in` as chunks of `path` of at most buffer.size() bytes (an empty file as one
// empty chunk, so the receiver creates it); *sent counts the bytes. False when `send` does.
bool SendChunks(std::istream& in, const std::string& path, std::string& buffer,
                const JobService::ChunkSink& send, int64_t* sent) {
  do {
    in.read(buffer.data(), static_cast<std::streamsize>(buffer.size()));
    const std::string_view data(buffer.data(), static_cast<size_t>(in.gcount()));
    if (data.empty() && *sent > 0) break;
    if (!send(path, *sent, data)) return false;
    *sent += static_cast<int64_t>(data.size());
  } while (in);
  return true;
}

}  // namespace

ServiceStatus JobService::DownloadCapture(const Caller& caller, const std::string& capture_id,
                                          const CaptureSink& send_capture,
                                          const ChunkSink& send_chunk) {
  Result<store::Capture> capture = jobs_->GetCapture(capture_id);
  if (!capture.ok()) return capture.status();
  if (!caller.Sees(capture->owner)) {
    return ServiceStatus(ServiceCode::kNotFound, "capture " + capture_id + " not found");
  }
  if (!send_capture(*capture)) return ServiceStatus(ServiceCode::kCancelled, "the caller left");
  std::string buffer(static_cast<size_t>(options_.upload_limits.max_chunk_bytes), '\0');
  for (const store::ManifestEntry& entry : capture->manifest) {
    Result<std::ifstream> in = blobs_->OpenBlob(entry.sha256);
    if (!in.ok()) {
      return ServiceStatus(ServiceCode::kInternal, "capture " + capture_id + ": \"" + entry.path +
                                                       "\": " + in.status().message());
    }
    int64_t offset = 0;
    if (!SendChunks(*in, entry.path, buffer, send_chunk, &offset)) {
      return ServiceStatus(ServiceCode::kCancelled, "the caller left");
    }
    if (offset != entry.size_bytes) {
      return ServiceStatus(ServiceCode::kInternal,
                           fmt::format("capture {}: \"{}\": the blob has {} bytes, not {}",
                                       capture_id, entry.path, offset, entry.size_bytes));
    }
  }
  return ServiceStatus::Ok();
}

ServiceStatus JobService::DownloadArtifact(const Caller& caller, const std::string& job_id,
                                           const std::string& name, const ChunkSink& send_chunk) {
  ServiceResult<JobResult> result = GetResult(caller, job_id);
  if (!result.ok()) return result.status();
  if (options_.reports == nullptr) {
    return ServiceStatus(ServiceCode::kNotFound, "job " + job_id + " has no report");
  }
  Result<std::ifstream> in = options_.reports->Open(job_id, name);
  if (!in.ok()) return in.status();
  std::string buffer(static_cast<size_t>(options_.upload_limits.max_chunk_bytes), '\0');
  int64_t sent = 0;
  if (!SendChunks(*in, name, buffer, send_chunk, &sent)) {
    return ServiceStatus(ServiceCode::kCancelled, "the caller left");
  }
  return ServiceStatus::Ok();
}

ServiceResult<std::pair<int, int>> JobService::RemoveOlderThan(std::chrono::seconds age) {
  const store::Timestamp cutoff = store::ToTimestamp(std::chrono::system_clock::now() - age);
  const Caller operator_caller = Caller::Operator();
  Result<std::vector<std::string>> jobs = jobs_->ListEndedJobs(cutoff);
  if (!jobs.ok()) return jobs.status();
  int jobs_removed = 0, captures_removed = 0;
  for (const std::string& id : *jobs) {
    if (DeleteJob(operator_caller, id).ok()) ++jobs_removed;
  }
  Result<std::vector<std::string>> captures = jobs_->ListUnusedCaptures(cutoff);
  if (!captures.ok()) return captures.status();
  for (const std::string& id : *captures) {
    if (DeleteCapture(operator_caller, id).ok()) ++captures_removed;
  }
  if (jobs_removed + captures_removed > 0) {
    logger_->info("retention: removed {} job(s) and {} capture(s) older than {} s", jobs_removed,
                  captures_removed, age.count());
  }
  return std::make_pair(jobs_removed, captures_removed);
}

ServiceResult<store::Job> JobService::VisibleJob(const Caller& caller, const std::string& job_id) {
  Result<store::Job> job = jobs_->GetJob(job_id);
  if (!job.ok()) return job.status();
  if (!caller.Sees(job->owner)) {
    return ServiceStatus(ServiceCode::kNotFound, "job " + job_id + " not found");
  }
  return *job;
}

ServiceResult<store::Job> JobService::GetJob(const Caller& caller, const std::string& job_id) {
  return VisibleJob(caller, job_id);
}

ServiceResult<store::JobPage> JobService::ListJobs(const Caller& caller,
                                                   store::ListJobsRequest request) {
  if (!caller.admin) request.owner = caller.station;
  Result<store::JobPage> page = jobs_->ListJobs(request);
  if (!page.ok()) return page.status();
  return *page;
}

ServiceResult<store::CapturePage> JobService::ListCaptures(const Caller& caller,
                                                           store::ListCapturesRequest request) {
  if (!caller.admin) request.owner = caller.station;
  Result<store::CapturePage> page = jobs_->ListCaptures(request);
  if (!page.ok()) return page.status();
  return *page;
}

ServiceResult<store::Job> JobService::CancelJob(const Caller& caller, const std::string& job_id) {
  if (ServiceResult<store::Job> visible = VisibleJob(caller, job_id); !visible.ok()) {
    return visible.status();
  }
  Result<store::Job> job = jobs_->RequestCancel(job_id);
  if (!job.ok()) return job.status();
  events_->Notify(job_id);
  logger_->info("job {}: cancel requested ({})", job_id, store::ToString(job->state));
  return *job;
}

ServiceStatus JobService::DeleteJob(const Caller& caller, const std::string& job_id) {
  if (ServiceResult<store::Job> visible = VisibleJob(caller, job_id); !visible.ok()) {
    return visible.status();
  }
  if (Status deleted = jobs_->DeleteJob(job_id); !deleted.ok()) return deleted;
  if (options_.reports != nullptr) options_.reports->Remove(job_id);
  events_->Notify(job_id);
  logger_->info("job {}: deleted", job_id);
  return ServiceStatus::Ok();
}

ServiceResult<JobResult> JobService::GetResult(const Caller& caller, const std::string& job_id) {
  ServiceResult<store::Job> job = VisibleJob(caller, job_id);
  if (!job.ok()) return job.status();
  if (job->state != store::JobState::kSucceeded || !job->result.has_value()) {
    return ServiceStatus(ServiceCode::kFailedPrecondition,
                         "job " + job_id + " is " + store::ToString(job->state) +
                             ": a result exists once it SUCCEEDED");
  }
  JobResult out{job_id, *job->result, {}, {}, {}, {}};
  if (options_.reports != nullptr) out.artifacts = options_.reports->List(job_id);
  if (auto it = job->result->find("ingest"); it != job->result->end()) out.ingest = *it;
  if (auto it = job->result->find("cost_history"); it != job->result->end() && it->is_array()) {
    for (const nlohmann::json& cost : *it) {
      if (cost.is_number()) out.cost_history.push_back(cost.get<double>());
    }
  }
  if (auto it = job->result->find("cost_history_last_frame");
      it != job->result->end() && it->is_array()) {
    for (const nlohmann::json& frame : *it) {
      if (frame.is_number_integer()) out.cost_history_last_frame.push_back(frame.get<int>());
    }
  }
  return out;
}

ServiceStatus JobService::WatchJob(const Caller& caller, const std::string& job_id,
                                   int from_iteration, const EventSink& send,
                                   const std::function<bool()>& stop) {
  if (ServiceResult<store::Job> visible = VisibleJob(caller, job_id); !visible.ok()) {
    return visible.status();
  }
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
