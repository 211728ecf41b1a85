// The gRPC transport of the JobService: converts softid.v1 messages to domain calls and back and
// maps outcomes to status codes (grpc_status.h). No job logic lives here. Uses gRPC's synchronous
// API: every call is short except uploads and watches, which block one thread of gRPC's pool each
// while they stream.
#pragma once

#include <spdlog/logger.h>

#include <chrono>
#include <filesystem>
#include <memory>
#include <string_view>

#include "server/api_tokens.h"
#include "server/idle_stream_watchdog.h"
#include "server/job_service.h"
#include "server/metrics.h"
#include "softid/v1/softid.grpc.pb.h"

namespace softid::server {

class GrpcReconstructionService final : public v1::Reconstruction::Service {
 public:
  // `service` must outlive this object. Error texts sent to clients have `data_dir` (the
  // server's data directory) removed; every refused call is logged with its full reason.
  // Upload streams idle for longer than `upload_idle_timeout` are cancelled.
  // Every call is authenticated by `authenticator` (from its "authorization" metadata) before
  // it reaches the service.
  // Refusals are counted in `metrics` (may be null).
  GrpcReconstructionService(JobService* service, const Authenticator* authenticator,
                            Metrics* metrics, std::filesystem::path data_dir,
                            std::chrono::milliseconds upload_idle_timeout,
                            std::shared_ptr<spdlog::logger> logger);

  grpc::Status UploadCapture(grpc::ServerContext* context,
                             grpc::ServerReader<v1::UploadCaptureRequest>* reader,
                             v1::Capture* response) override;
  grpc::Status FindCaptureFiles(grpc::ServerContext* context,
                                const v1::FindCaptureFilesRequest* request,
                                v1::FindCaptureFilesResponse* response) override;
  grpc::Status DownloadCapture(grpc::ServerContext* context,
                               const v1::DownloadCaptureRequest* request,
                               grpc::ServerWriter<v1::DownloadCaptureResponse>* writer) override;
  grpc::Status DeleteCapture(grpc::ServerContext* context, const v1::DeleteCaptureRequest* request,
                             v1::DeleteCaptureResponse* response) override;
  grpc::Status CreateJob(grpc::ServerContext* context, const v1::CreateJobRequest* request,
                         v1::Job* response) override;
  grpc::Status GetJob(grpc::ServerContext* context, const v1::GetJobRequest* request,
                      v1::Job* response) override;
  grpc::Status ListJobs(grpc::ServerContext* context, const v1::ListJobsRequest* request,
                        v1::ListJobsResponse* response) override;
  grpc::Status ListCaptures(grpc::ServerContext* context, const v1::ListCapturesRequest* request,
                            v1::ListCapturesResponse* response) override;
  grpc::Status CancelJob(grpc::ServerContext* context, const v1::CancelJobRequest* request,
                         v1::Job* response) override;
  grpc::Status DeleteJob(grpc::ServerContext* context, const v1::DeleteJobRequest* request,
                         v1::DeleteJobResponse* response) override;
  grpc::Status WatchJob(grpc::ServerContext* context, const v1::WatchJobRequest* request,
                        grpc::ServerWriter<v1::JobEvent>* writer) override;
  grpc::Status GetResult(grpc::ServerContext* context, const v1::GetResultRequest* request,
                         v1::Result* response) override;
  grpc::Status DownloadArtifact(grpc::ServerContext* context,
                                const v1::DownloadArtifactRequest* request,
                                grpc::ServerWriter<v1::FileChunk>* writer) override;

 private:
  // The gRPC status of `status` for `method`, redacted and logged when it is not OK.
  grpc::Status Reply(std::string_view method, const ServiceStatus& status) const;
  // The reply to an upload the watchdog cancelled.
  grpc::Status IdledOut() const;

  // The caller of this call, from its "authorization" metadata, counted against its call rate.
  ServiceResult<Caller> Authenticate(const grpc::ServerContext* context) const;

  JobService* service_;
  const Authenticator* authenticator_;
  Metrics* metrics_;
  std::filesystem::path data_dir_;
  std::shared_ptr<spdlog::logger> logger_;
  IdleStreamWatchdog upload_watchdog_;
};

}  // namespace softid::server
