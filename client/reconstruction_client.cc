#include "client/reconstruction_client.h"

#include <grpcpp/client_context.h>
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/support/byte_buffer.h>

#include <algorithm>
#include <fstream>
#include <future>
#include <thread>
#include <vector>

#include "client/capture_download.h"

namespace softid::client {
namespace {

using Clock = std::chrono::steady_clock;

void SetDeadline(grpc::ClientContext* context, std::chrono::milliseconds timeout) {
  context->set_deadline(std::chrono::system_clock::now() + timeout);
}

// grpc.health.v1 messages by hand (Debian ships no health.proto): HealthCheckRequest is
// {string service = 1}, HealthCheckResponse is {enum status = 1}.
grpc::ByteBuffer HealthRequest(const std::string& service) {
  std::string bytes;
  if (!service.empty()) {
    bytes.push_back(0x0a);  // field 1, length-delimited
    size_t n = service.size();
    while (n >= 0x80) {
      bytes.push_back(static_cast<char>((n & 0x7f) | 0x80));
      n >>= 7;
    }
    bytes.push_back(static_cast<char>(n));
    bytes += service;
  }
  grpc::Slice slice(bytes);
  return grpc::ByteBuffer(&slice, 1);
}

ServingStatus ParseHealthResponse(const grpc::ByteBuffer& buffer) {
  std::vector<grpc::Slice> slices;
  if (!buffer.Dump(&slices).ok()) return ServingStatus::kUnknown;
  std::string bytes;
  for (const grpc::Slice& slice : slices) {
    bytes.append(reinterpret_cast<const char*>(slice.begin()), slice.size());
  }
  if (bytes.size() >= 2 && bytes[0] == 0x08 && bytes[1] >= 0 && bytes[1] <= 3) {
    return static_cast<ServingStatus>(bytes[1]);
  }
  return ServingStatus::kUnknown;  // status 0 is encoded as an empty message
}

}  // namespace

const char* ToString(ServingStatus status) {
  switch (status) {
    case ServingStatus::kUnknown: return "UNKNOWN";
    case ServingStatus::kServing: return "SERVING";
    case ServingStatus::kNotServing: return "NOT_SERVING";
    case ServingStatus::kServiceUnknown: return "SERVICE_UNKNOWN";
  }
  return "UNKNOWN";
}

ReconstructionClient::ReconstructionClient(std::shared_ptr<grpc::Channel> channel,
                                           ClientOptions options)
    : channel_(std::move(channel)),
      stub_(v1::Reconstruction::NewStub(channel_)),
      options_(options) {}

void ReconstructionClient::Prepare(grpc::ClientContext* context,
                                   std::chrono::milliseconds timeout) const {
  SetDeadline(context, timeout);
  if (!options_.token.empty()) context->AddMetadata("authorization", "Bearer " + options_.token);
}

grpc::Status ReconstructionClient::WithRetry(
    std::chrono::milliseconds timeout,
    const std::function<grpc::Status(grpc::ClientContext*)>& call) {
  const Clock::time_point give_up = Clock::now() + options_.retry_budget;
  std::chrono::milliseconds backoff = options_.initial_backoff;
  while (true) {
    grpc::ClientContext context;
    Prepare(&context, timeout);
    grpc::Status status = call(&context);
    if (status.error_code() != grpc::StatusCode::UNAVAILABLE || Clock::now() + backoff > give_up) {
      return status;
    }
    std::this_thread::sleep_for(backoff);
    backoff = std::min(backoff * 2, options_.max_backoff);
  }
}

grpc::Status ReconstructionClient::FindCaptureFiles(const CaptureFiles& capture,
                                                    std::set<std::string>* out) {
  v1::FindCaptureFilesRequest request;
  for (const v1::CaptureFile& file : capture.files) request.add_sha256(file.sha256());
  v1::FindCaptureFilesResponse response;
  const grpc::Status status = WithRetry(options_.call_timeout, [&](grpc::ClientContext* context) {
    return stub_->FindCaptureFiles(context, request, &response);
  });
  out->clear();
  out->insert(response.sha256().begin(), response.sha256().end());
  return status;
}

grpc::Status ReconstructionClient::UploadCapture(const CaptureFiles& capture,
                                                 const std::string& request_id, v1::Capture* out,
                                                 int* skipped) {
  std::set<std::string> held;
  const grpc::Status found = FindCaptureFiles(capture, &held);
  // A server from before FindCaptureFiles: send everything.
  if (!found.ok() && found.error_code() != grpc::StatusCode::UNIMPLEMENTED) return found;
  return WithRetry(options_.upload_timeout, [&](grpc::ClientContext* context) {
    if (skipped != nullptr) *skipped = 0;
    std::unique_ptr<grpc::ClientWriter<v1::UploadCaptureRequest>> writer =
        stub_->UploadCapture(context, out);
    v1::UploadCaptureRequest request;
    v1::CaptureManifest* manifest = request.mutable_manifest();
    manifest->set_request_id(request_id);
    // Exactly one is non-empty: the server refuses both or neither.
    if (!capture.capture_json.empty()) manifest->set_capture_json(capture.capture_json);
    if (!capture.recording_json.empty()) manifest->set_recording_json(capture.recording_json);
    for (const v1::CaptureFile& file : capture.files) *manifest->add_files() = file;
    bool open = writer->Write(request);
    std::vector<char> buffer(static_cast<size_t>(options_.chunk_bytes));
    for (size_t i = 0; open && i < capture.files.size(); ++i) {
      const v1::CaptureFile& file = capture.files[i];
      if (held.count(file.sha256()) > 0) {
        if (skipped != nullptr) ++*skipped;
        continue;
      }
      std::ifstream in(capture.directory / file.path(), std::ios::binary);
      int64_t offset = 0;
      while (open && in) {
        in.read(buffer.data(), static_cast<std::streamsize>(buffer.size()));
        const std::streamsize got = in.gcount();
        if (got <= 0) break;
        v1::UploadCaptureRequest chunk_request;
        v1::FileChunk* chunk = chunk_request.mutable_chunk();
        chunk->set_path(file.path());
        chunk->set_offset_bytes(offset);
        chunk->set_data(buffer.data(), static_cast<size_t>(got));
        open = writer->Write(chunk_request);
        offset += got;
      }
    }
    // A failed Write means the server ended the call early; Finish says why.
    writer->WritesDone();
    return writer->Finish();
  });
}

grpc::Status ReconstructionClient::DownloadCapture(const std::string& capture_id,
                                                   const std::filesystem::path& directory,
                                                   v1::Capture* out) {
  std::string error;
  if (!IsEmptyTarget(directory, &error)) {
    return grpc::Status(grpc::StatusCode::FAILED_PRECONDITION, error);
  }
  v1::DownloadCaptureRequest request;
  request.set_capture_id(capture_id);
  // Each attempt starts afresh: a retry after a cut writes every file again.
  return WithRetry(options_.upload_timeout, [&](grpc::ClientContext* context) {
    CaptureDownload download(directory);
    std::unique_ptr<grpc::ClientReader<v1::DownloadCaptureResponse>> reader =
        stub_->DownloadCapture(context, request);
    v1::DownloadCaptureResponse message;
    bool began = false, ok = true;
    while (ok && reader->Read(&message)) {
      if (!began) {
        ok = message.has_capture() && download.Begin(message.capture(), &error);
        if (!message.has_capture()) error = "the server sent a chunk before the capture";
        if (ok) *out = message.capture();
        began = true;
      } else {
        ok = message.has_chunk() && download.AddChunk(message.chunk(), &error);
        if (!message.has_chunk()) error = "the server sent the capture twice";
      }
    }
    if (!ok) {
      context->TryCancel();
      (void)reader->Finish();
      download.Discard();
      return grpc::Status(grpc::StatusCode::DATA_LOSS, error);
    }
    grpc::Status status = reader->Finish();
    if (status.ok() && !began) {
      status = grpc::Status(grpc::StatusCode::DATA_LOSS, "the server sent no capture");
    } else if (status.ok() && !download.Finish(&error)) {
      status = grpc::Status(grpc::StatusCode::DATA_LOSS, error);
    }
    if (!status.ok()) download.Discard();
    return status;
  });
}

grpc::Status ReconstructionClient::DownloadReport(const v1::Result& result,
                                                  const std::filesystem::path& directory) {
  std::vector<ExpectedFile> files;
  for (const v1::Artifact& artifact : result.artifacts()) {
    files.push_back({artifact.name(), artifact.size_bytes(), ""});
  }
  std::string error;
  CaptureDownload download(directory);
  if (!download.Begin(files, &error)) {
    return grpc::Status(grpc::StatusCode::FAILED_PRECONDITION, error);
  }
  for (const v1::Artifact& artifact : result.artifacts()) {
    v1::DownloadArtifactRequest request;
    request.set_job_id(result.job_id());
    request.set_name(artifact.name());
    // One attempt per file: a retry after a cut would append to what arrived.
    grpc::ClientContext context;
    Prepare(&context, options_.upload_timeout);
    std::unique_ptr<grpc::ClientReader<v1::FileChunk>> reader =
        stub_->DownloadArtifact(&context, request);
    v1::FileChunk chunk;
    bool ok = true;
    while (ok && reader->Read(&chunk)) ok = download.AddChunk(chunk, &error);
    if (!ok) context.TryCancel();
    const grpc::Status status = reader->Finish();
    if (!ok || !status.ok()) {
      download.Discard();
      return ok ? status : grpc::Status(grpc::StatusCode::DATA_LOSS, error);
    }
  }
  if (!download.Finish(&error)) {
    download.Discard();
    return grpc::Status(grpc::StatusCode::DATA_LOSS, error);
  }
  return grpc::Status::OK;
}

grpc::Status ReconstructionClient::CreateJob(const v1::CreateJobRequest& request, v1::Job* out) {
  return WithRetry(options_.call_timeout, [&](grpc::ClientContext* context) {
    return stub_->CreateJob(context, request, out);
  });
}

grpc::Status ReconstructionClient::GetJob(const std::string& job_id, v1::Job* out) {
  v1::GetJobRequest request;
  request.set_job_id(job_id);
  return WithRetry(options_.call_timeout, [&](grpc::ClientContext* context) {
    return stub_->GetJob(context, request, out);
  });
}

grpc::Status ReconstructionClient::ListJobs(const v1::ListJobsRequest& request,
                                            v1::ListJobsResponse* out) {
  return WithRetry(options_.call_timeout, [&](grpc::ClientContext* context) {
    return stub_->ListJobs(context, request, out);
  });
}

grpc::Status ReconstructionClient::ListCaptures(const v1::ListCapturesRequest& request,
                                                v1::ListCapturesResponse* out) {
  return WithRetry(options_.call_timeout, [&](grpc::ClientContext* context) {
    return stub_->ListCaptures(context, request, out);
  });
}

grpc::Status ReconstructionClient::CancelJob(const std::string& job_id, v1::Job* out) {
  v1::CancelJobRequest request;
  request.set_job_id(job_id);
  return WithRetry(options_.call_timeout, [&](grpc::ClientContext* context) {
    return stub_->CancelJob(context, request, out);
  });
}

grpc::Status ReconstructionClient::DeleteCapture(const std::string& capture_id) {
  v1::DeleteCaptureRequest request;
  request.set_capture_id(capture_id);
  v1::DeleteCaptureResponse response;
  return WithRetry(options_.call_timeout, [&](grpc::ClientContext* context) {
    return stub_->DeleteCapture(context, request, &response);
  });
}

grpc::Status ReconstructionClient::DeleteJob(const std::string& job_id) {
  v1::DeleteJobRequest request;
  request.set_job_id(job_id);
  v1::DeleteJobResponse response;
  return WithRetry(options_.call_timeout, [&](grpc::ClientContext* context) {
    return stub_->DeleteJob(context, request, &response);
  });
}

grpc::Status ReconstructionClient::GetResult(const std::string& job_id, v1::Result* out) {
  v1::GetResultRequest request;
  request.set_job_id(job_id);
  return WithRetry(options_.call_timeout, [&](grpc::ClientContext* context) {
    return stub_->GetResult(context, request, out);
  });
}

grpc::Status ReconstructionClient::WatchJob(
    const std::string& job_id, int from_iteration,
    const std::function<void(const v1::JobEvent&)>& on_event) {
  int64_t last_seq = 0;
  int resume_from = from_iteration;
  return WithRetry(options_.watch_timeout, [&](grpc::ClientContext* context) {
    v1::WatchJobRequest request;
    request.set_job_id(job_id);
    request.set_from_iteration(resume_from);
    std::unique_ptr<grpc::ClientReader<v1::JobEvent>> reader = stub_->WatchJob(context, request);
    v1::JobEvent event;
    while (reader->Read(&event)) {
      if (event.seq() <= last_seq) continue;  // already delivered before a cut
      last_seq = event.seq();
      resume_from = std::max(resume_from, event.iteration());
      on_event(event);
    }
    return reader->Finish();
  });
}

grpc::Status ReconstructionClient::Health(const std::string& service, ServingStatus* out) {
  grpc::GenericStub stub(channel_);
  const grpc::ByteBuffer request = HealthRequest(service);
  return WithRetry(options_.call_timeout, [&](grpc::ClientContext* context) {
    grpc::ByteBuffer response;
    std::promise<grpc::Status> done;
    stub.UnaryCall(context, "/grpc.health.v1.Health/Check", grpc::StubOptions(), &request,
                   &response, [&](grpc::Status status) { done.set_value(std::move(status)); });
    grpc::Status status = done.get_future().get();
    if (status.ok()) *out = ParseHealthResponse(response);
    return status;
  });
}

}  // namespace softid::client
