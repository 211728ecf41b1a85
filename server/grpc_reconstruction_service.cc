#include "server/grpc_reconstruction_service.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>

#include "server/grpc_status.h"
#include "server/proto_conversion.h"
#include "server/redact_paths.h"

namespace softid::server {

GrpcReconstructionService::GrpcReconstructionService(JobService* service,
                                                     const Authenticator* authenticator,
                                                     Metrics* metrics,
                                                     std::filesystem::path data_dir,
                                                     std::chrono::milliseconds upload_idle_timeout,
                                                     std::shared_ptr<spdlog::logger> logger)
    : service_(service),
      authenticator_(authenticator),
      metrics_(metrics),
      data_dir_(std::move(data_dir)),
      logger_(logger ? std::move(logger) : spdlog::default_logger()),
      upload_watchdog_(upload_idle_timeout,
                       std::clamp(upload_idle_timeout / 4, std::chrono::milliseconds(10),
                                  std::chrono::milliseconds(1000))) {}

ServiceResult<Caller> GrpcReconstructionService::Authenticate(
    const grpc::ServerContext* context) const {
  const auto& metadata = context->client_metadata();
  const auto it = metadata.find("authorization");
  std::optional<std::string_view> value;
  if (it != metadata.end()) value = std::string_view(it->second.data(), it->second.size());
  ServiceResult<Caller> caller = authenticator_->Authenticate(value);
  if (!caller.ok()) return caller;
  if (ServiceStatus admitted = service_->Admit(*caller); !admitted.ok()) return admitted;
  return caller;
}

grpc::Status GrpcReconstructionService::IdledOut() const {
  const auto seconds = std::chrono::duration<double>(upload_watchdog_.idle_timeout()).count();
  return Reply("UploadCapture",
               {ServiceCode::kCancelled, fmt::format("the upload sent nothing for {:g} s and was "
                                                     "cancelled; nothing of it was kept",
                                                     seconds)});
}

grpc::Status GrpcReconstructionService::Reply(std::string_view method,
                                              const ServiceStatus& status) const {
  if (status.ok()) return grpc::Status::OK;
  if (metrics_ != nullptr && status.code() != ServiceCode::kCancelled) {
    metrics_->CountRefused(method, ToString(status.code()));
  }
  // Cancelled calls are the caller leaving; everything else is a refusal worth a line.
  if (status.code() == ServiceCode::kInternal) {
    logger_->error("{}: {}", method, status.ToString());
  } else if (status.code() != ServiceCode::kCancelled) {
    logger_->info("{} refused: {}", method, status.ToString());
  }
  return ToGrpcStatus(
      ServiceStatus(status.code(), RedactPath(status.message(), data_dir_, "<data>/")));
}

grpc::Status GrpcReconstructionService::UploadCapture(
    grpc::ServerContext* context, grpc::ServerReader<v1::UploadCaptureRequest>* reader,
    v1::Capture* response) {
  ServiceResult<Caller> caller = Authenticate(context);
  if (!caller.ok()) return Reply("UploadCapture", caller.status());
  std::atomic<bool> idled_out{false};
  const std::unique_ptr<IdleStreamWatchdog::Watch> watch = upload_watchdog_.Start([&] {
    idled_out.store(true);
    context->TryCancel();
  });
  // The idle clock runs only while the handler waits for the client.
  const auto read = [&](v1::UploadCaptureRequest* message) {
    watch->BeginWait();
    const bool received = reader->Read(message);
    watch->EndWait();
    return received;
  };
  v1::UploadCaptureRequest request;
  if (!read(&request)) {
    if (idled_out.load()) return IdledOut();
    return Reply("UploadCapture",
                 {ServiceCode::kInvalidArgument, "manifest: the upload stream was empty"});
  }
  if (!request.has_manifest()) {
    return Reply("UploadCapture", {ServiceCode::kInvalidArgument,
                                   "manifest: the first message must carry the manifest"});
  }
  ServiceResult<std::unique_ptr<CaptureUpload>> upload =
      service_->BeginUpload(*caller, FromProto(request.manifest()));
  if (!upload.ok()) return Reply("UploadCapture", upload.status());
  while (read(&request)) {
    if (!request.has_chunk()) {
      return Reply("UploadCapture", {ServiceCode::kInvalidArgument,
                                     "manifest: sent twice; later messages carry chunks"});
    }
    const v1::FileChunk& chunk = request.chunk();
    ServiceStatus added = (*upload)->AddChunk(chunk.path(), chunk.offset_bytes(), chunk.data());
    if (!added.ok()) return Reply("UploadCapture", added);
  }
  // A client that died mid-stream looks like an early end: FinishUpload reports the file that
  // came up short, and nothing is stored either way.
  if (idled_out.load()) return IdledOut();
  if (context->IsCancelled()) {
    return Reply("UploadCapture", {ServiceCode::kCancelled, "the upload was cancelled"});
  }
  ServiceResult<store::Capture> capture = service_->FinishUpload(*caller, **upload);
  if (!capture.ok()) return Reply("UploadCapture", capture.status());
  ToProto(*capture, response);
  return grpc::Status::OK;
}

grpc::Status GrpcReconstructionService::FindCaptureFiles(grpc::ServerContext* context,
                                                         const v1::FindCaptureFilesRequest* request,
                                                         v1::FindCaptureFilesResponse* response) {
  ServiceResult<Caller> caller = Authenticate(context);
  if (!caller.ok()) return Reply("FindCaptureFiles", caller.status());
  const std::vector<std::string> asked(request->sha256().begin(), request->sha256().end());
  ServiceResult<std::vector<std::string>> held = service_->FindCaptureFiles(*caller, asked);
  if (!held.ok()) return Reply("FindCaptureFiles", held.status());
  for (const std::string& sha256 : *held) response->add_sha256(sha256);
  return grpc::Status::OK;
}

grpc::Status GrpcReconstructionService::DownloadCapture(
    grpc::ServerContext* context, const v1::DownloadCaptureRequest* request,
    grpc::ServerWriter<v1::DownloadCaptureResponse>* writer) {
  ServiceResult<Caller> caller = Authenticate(context);
  if (!caller.ok()) return Reply("DownloadCapture", caller.status());
  v1::DownloadCaptureResponse message;
  return Reply("DownloadCapture",
               service_->DownloadCapture(
                   *caller, request->capture_id(),
                   [&](const store::Capture& capture) {
                     ToProto(capture, message.mutable_capture());
                     return !context->IsCancelled() && writer->Write(message);
                   },
                   [&](const std::string& path, int64_t offset_bytes, std::string_view data) {
                     v1::FileChunk* chunk = message.mutable_chunk();
                     chunk->set_path(path);
                     chunk->set_offset_bytes(offset_bytes);
                     chunk->set_data(data.data(), data.size());
                     return !context->IsCancelled() && writer->Write(message);
                   }));
}

grpc::Status GrpcReconstructionService::DeleteCapture(grpc::ServerContext* context,
                                                      const v1::DeleteCaptureRequest* request,
                                                      v1::DeleteCaptureResponse* response) {
  ServiceResult<Caller> caller = Authenticate(context);
  if (!caller.ok()) return Reply("DeleteCapture", caller.status());
  return Reply("DeleteCapture", service_->DeleteCapture(*caller, request->capture_id()));
}

grpc::Status GrpcReconstructionService::CreateJob(grpc::ServerContext* context,
                                                  const v1::CreateJobRequest* request,
                                                  v1::Job* response) {
  ServiceResult<Caller> caller = Authenticate(context);
  if (!caller.ok()) return Reply("CreateJob", caller.status());
  ServiceResult<store::Job> job = service_->CreateJob(
      *caller, request->capture_id(), request->config_json(), request->request_id());
  if (!job.ok()) return Reply("CreateJob", job.status());
  ToProto(*job, response);
  return grpc::Status::OK;
}

grpc::Status GrpcReconstructionService::GetJob(grpc::ServerContext* context,
                                               const v1::GetJobRequest* request,
                                               v1::Job* response) {
  ServiceResult<Caller> caller = Authenticate(context);
  if (!caller.ok()) return Reply("GetJob", caller.status());
  ServiceResult<store::Job> job = service_->GetJob(*caller, request->job_id());
  if (!job.ok()) return Reply("GetJob", job.status());
  ToProto(*job, response);
  return grpc::Status::OK;
}

grpc::Status GrpcReconstructionService::ListJobs(grpc::ServerContext* context,
                                                 const v1::ListJobsRequest* request,
                                                 v1::ListJobsResponse* response) {
  ServiceResult<Caller> caller = Authenticate(context);
  if (!caller.ok()) return Reply("ListJobs", caller.status());
  ServiceResult<std::optional<store::JobState>> state = StateFilterFromProto(request->state());
  if (!state.ok()) return Reply("ListJobs", state.status());
  store::ListJobsRequest list;
  list.state = *state;
  list.page_size = request->page_size();
  list.page_token = request->page_token();
  ServiceResult<store::JobPage> page = service_->ListJobs(*caller, list);
  if (!page.ok()) return Reply("ListJobs", page.status());
  for (const store::Job& job : page->jobs) ToProto(job, response->add_jobs());
  response->set_next_page_token(page->next_page_token);
  return grpc::Status::OK;
}

grpc::Status GrpcReconstructionService::ListCaptures(grpc::ServerContext* context,
                                                     const v1::ListCapturesRequest* request,
                                                     v1::ListCapturesResponse* response) {
  ServiceResult<Caller> caller = Authenticate(context);
  if (!caller.ok()) return Reply("ListCaptures", caller.status());
  store::ListCapturesRequest list;
  list.page_size = request->page_size();
  list.page_token = request->page_token();
  ServiceResult<store::CapturePage> page = service_->ListCaptures(*caller, list);
  if (!page.ok()) return Reply("ListCaptures", page.status());
  for (const store::CaptureListing& listing : page->captures) {
    ToProto(listing, response->add_captures());
  }
  response->set_next_page_token(page->next_page_token);
  return grpc::Status::OK;
}

grpc::Status GrpcReconstructionService::CancelJob(grpc::ServerContext* context,
                                                  const v1::CancelJobRequest* request,
                                                  v1::Job* response) {
  ServiceResult<Caller> caller = Authenticate(context);
  if (!caller.ok()) return Reply("CancelJob", caller.status());
  ServiceResult<store::Job> job = service_->CancelJob(*caller, request->job_id());
  if (!job.ok()) return Reply("CancelJob", job.status());
  ToProto(*job, response);
  return grpc::Status::OK;
}

grpc::Status GrpcReconstructionService::DeleteJob(grpc::ServerContext* context,
                                                  const v1::DeleteJobRequest* request,
                                                  v1::DeleteJobResponse* response) {
  ServiceResult<Caller> caller = Authenticate(context);
  if (!caller.ok()) return Reply("DeleteJob", caller.status());
  return Reply("DeleteJob", service_->DeleteJob(*caller, request->job_id()));
}

grpc::Status GrpcReconstructionService::WatchJob(grpc::ServerContext* context,
                                                 const v1::WatchJobRequest* request,
                                                 grpc::ServerWriter<v1::JobEvent>* writer) {
  ServiceResult<Caller> caller = Authenticate(context);
  if (!caller.ok()) return Reply("WatchJob", caller.status());
  if (request->from_iteration() < 0) {
    return Reply("WatchJob", {ServiceCode::kInvalidArgument,
                              "from_iteration = " + std::to_string(request->from_iteration()) +
                                  ": must not be negative"});
  }
  return Reply("WatchJob", service_->WatchJob(
                               *caller, request->job_id(), request->from_iteration(),
                               [&](const store::ProgressEvent& event, const store::Job& job) {
                                 v1::JobEvent message;
                                 ToProto(event, job, &message);
                                 return writer->Write(message);
                               },
                               [&] { return context->IsCancelled(); }));
}

grpc::Status GrpcReconstructionService::GetResult(grpc::ServerContext* context,
                                                  const v1::GetResultRequest* request,
                                                  v1::Result* response) {
  ServiceResult<Caller> caller = Authenticate(context);
  if (!caller.ok()) return Reply("GetResult", caller.status());

  ServiceResult<JobResult> result = service_->GetResult(*caller, request->job_id());
  if (!result.ok()) return Reply("GetResult", result.status());
  response->set_job_id(result->job_id);
  response->set_result_json(result->result.dump());
  for (double cost : result->cost_history) response->add_cost_history(cost);
  for (int frame : result->cost_history_last_frame) response->add_cost_history_last_frame(frame);
  FittedParametersToProto(result->result, response);
  if (!result->ingest.is_null()) response->set_ingest_json(result->ingest.dump());
  for (const ReportFile& file : result->artifacts) {
    v1::Artifact* artifact = response->add_artifacts();
    artifact->set_name(file.name);
    artifact->set_media_type(file.media_type);
    artifact->set_size_bytes(file.size_bytes);
  }
  return grpc::Status::OK;
}

grpc::Status GrpcReconstructionService::DownloadArtifact(
    grpc::ServerContext* context, const v1::DownloadArtifactRequest* request,
    grpc::ServerWriter<v1::FileChunk>* writer) {
  ServiceResult<Caller> caller = Authenticate(context);
  if (!caller.ok()) return Reply("DownloadArtifact", caller.status());
  v1::FileChunk chunk;
  return Reply("DownloadArtifact",
               service_->DownloadArtifact(
                   *caller, request->job_id(), request->name(),
                   [&](const std::string& path, int64_t offset_bytes, std::string_view data) {
                     chunk.set_path(path);
                     chunk.set_offset_bytes(offset_bytes);
                     chunk.set_data(data.data(), data.size());
                     return !context->IsCancelled() && writer->Write(chunk);
                   }));
}

}  // namespace softid::server
