#include "server/grpc_reconstruction_service.h"

#include "server/grpc_status.h"
#include "server/proto_conversion.h"

namespace softid::server {

grpc::Status GrpcReconstructionService::UploadCapture(
    grpc::ServerContext* context, grpc::ServerReader<v1::UploadCaptureRequest>* reader,
    v1::Capture* response) {
  v1::UploadCaptureRequest request;
  if (!reader->Read(&request)) {
    return ToGrpcStatus({ServiceCode::kInvalidArgument, "manifest: the upload stream was empty"});
  }
  if (!request.has_manifest()) {
    return ToGrpcStatus(
        {ServiceCode::kInvalidArgument, "manifest: the first message must carry the manifest"});
  }
  ServiceResult<std::unique_ptr<CaptureUpload>> upload =
      service_->BeginUpload(FromProto(request.manifest()));
  if (!upload.ok()) return ToGrpcStatus(upload.status());
  while (reader->Read(&request)) {
    if (!request.has_chunk()) {
      return ToGrpcStatus(
          {ServiceCode::kInvalidArgument, "manifest: sent twice; later messages carry chunks"});
    }
    const v1::FileChunk& chunk = request.chunk();
    ServiceStatus added = (*upload)->AddChunk(chunk.path(), chunk.offset_bytes(), chunk.data());
    if (!added.ok()) return ToGrpcStatus(added);
  }
  // A client that died mid-stream looks like an early end: FinishUpload reports the file that
  // came up short, and nothing is stored either way.
  if (context->IsCancelled()) {
    return ToGrpcStatus({ServiceCode::kCancelled, "the upload was cancelled"});
  }
  ServiceResult<store::Capture> capture = service_->FinishUpload(**upload);
  if (!capture.ok()) return ToGrpcStatus(capture.status());
  ToProto(*capture, response);
  return grpc::Status::OK;
}

grpc::Status GrpcReconstructionService::CreateJob(grpc::ServerContext* context,
                                                  const v1::CreateJobRequest* request,
                                                  v1::Job* response) {
  ServiceResult<store::Job> job =
      service_->CreateJob(request->capture_id(), request->config_json(), request->request_id());
  if (!job.ok()) return ToGrpcStatus(job.status());
  ToProto(*job, response);
  return grpc::Status::OK;
}

grpc::Status GrpcReconstructionService::GetJob(grpc::ServerContext* context,
                                               const v1::GetJobRequest* request,
                                               v1::Job* response) {
  ServiceResult<store::Job> job = service_->GetJob(request->job_id());
  if (!job.ok()) return ToGrpcStatus(job.status());
  ToProto(*job, response);
  return grpc::Status::OK;
}

grpc::Status GrpcReconstructionService::ListJobs(grpc::ServerContext* context,
                                                 const v1::ListJobsRequest* request,
                                                 v1::ListJobsResponse* response) {
  ServiceResult<std::optional<store::JobState>> state = StateFilterFromProto(request->state());
  if (!state.ok()) return ToGrpcStatus(state.status());
  store::ListJobsRequest list;
  list.state = *state;
  list.page_size = request->page_size();
  list.page_token = request->page_token();
  ServiceResult<store::JobPage> page = service_->ListJobs(list);
  if (!page.ok()) return ToGrpcStatus(page.status());
  for (const store::Job& job : page->jobs) ToProto(job, response->add_jobs());
  response->set_next_page_token(page->next_page_token);
  return grpc::Status::OK;
}

grpc::Status GrpcReconstructionService::CancelJob(grpc::ServerContext* context,
                                                  const v1::CancelJobRequest* request,
                                                  v1::Job* response) {
  ServiceResult<store::Job> job = service_->CancelJob(request->job_id());
  if (!job.ok()) return ToGrpcStatus(job.status());
  ToProto(*job, response);
  return grpc::Status::OK;
}

grpc::Status GrpcReconstructionService::DeleteJob(grpc::ServerContext* context,
                                                  const v1::DeleteJobRequest* request,
                                                  v1::DeleteJobResponse* response) {
  return ToGrpcStatus(service_->DeleteJob(request->job_id()));
}

grpc::Status GrpcReconstructionService::WatchJob(grpc::ServerContext* context,
                                                 const v1::WatchJobRequest* request,
                                                 grpc::ServerWriter<v1::JobEvent>* writer) {
  if (request->from_iteration() < 0) {
    return ToGrpcStatus({ServiceCode::kInvalidArgument,
                         "from_iteration = " + std::to_string(request->from_iteration()) +
                             ": must not be negative"});
  }
  return ToGrpcStatus(service_->WatchJob(
      request->job_id(), request->from_iteration(),
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
  ServiceResult<JobResult> result = service_->GetResult(request->job_id());
  if (!result.ok()) return ToGrpcStatus(result.status());
  response->set_job_id(result->job_id);
  response->set_result_json(result->result.dump());
  for (double cost : result->cost_history) response->add_cost_history(cost);
  return grpc::Status::OK;
}

}  // namespace softid::server
