// A thin client of softid.v1.Reconstruction built on an injected channel (so tests can run it
// in-process): every call gets a fresh context with a deadline, and calls that find the server
// UNAVAILABLE are retried with exponential backoff until the retry budget is spent. Upload and
// watch are retried as a whole (an upload is idempotent through its request_id; a watch resumes
// from the last iteration it saw).
#pragma once

#include <grpcpp/channel.h>

#include <chrono>
#include <filesystem>
#include <functional>
#include <memory>
#include <set>
#include <string>

#include "client/capture_files.h"
#include "softid/v1/softid.grpc.pb.h"

namespace softid::client {

struct ClientOptions {
  // Deadline of each unary call.
  std::chrono::milliseconds call_timeout{10000};
  // Deadline of an upload (a capture of hundreds of frames over a slow link).
  std::chrono::milliseconds upload_timeout{600000};
  // Deadline of a watch: jobs run for minutes to hours.
  std::chrono::milliseconds watch_timeout{std::chrono::hours(24)};
  // Total time spent retrying while the server is UNAVAILABLE; backoff doubles from
  // initial_backoff up to max_backoff.
  std::chrono::milliseconds retry_budget{30000};
  std::chrono::milliseconds initial_backoff{200};
  std::chrono::milliseconds max_backoff{5000};
  // Chunk size of uploads; the server accepts at most 1 MiB.
  int64_t chunk_bytes = int64_t{1} << 20;
  // The station's API token, sent as "authorization: Bearer <token>" on every call; empty:
  // none (servers without authentication).
  std::string token;
};

// Health of the server as grpc.health.v1 reports it.
enum class ServingStatus { kUnknown = 0, kServing = 1, kNotServing = 2, kServiceUnknown = 3 };
const char* ToString(ServingStatus status);

class ReconstructionClient {
 public:
  ReconstructionClient(std::shared_ptr<grpc::Channel> channel, ClientOptions options = {});

  // Sends the manifest and the bytes of every file the server does not already hold for this
  // station (FindCaptureFiles; an older server without it gets every file). `skipped`, when
  // given, counts the files left out.
  grpc::Status UploadCapture(const CaptureFiles& capture, const std::string& request_id,
                             v1::Capture* out, int* skipped = nullptr);
  // The hashes among the capture's files that the server holds for this station.
  grpc::Status FindCaptureFiles(const CaptureFiles& capture, std::set<std::string>* out);
  grpc::Status CreateJob(const v1::CreateJobRequest& request, v1::Job* out);
  grpc::Status GetJob(const std::string& job_id, v1::Job* out);
  grpc::Status ListJobs(const v1::ListJobsRequest& request, v1::ListJobsResponse* out);
  grpc::Status ListCaptures(const v1::ListCapturesRequest& request, v1::ListCapturesResponse* out);
  grpc::Status CancelJob(const std::string& job_id, v1::Job* out);
  grpc::Status DeleteJob(const std::string& job_id);
  grpc::Status DeleteCapture(const std::string& capture_id);
  // Downloads a capture's files into `directory` (absent or empty; see CaptureDownload) and sets
  // `out` to the capture. On any error nothing of it is left in `directory`: FAILED_PRECONDITION
  // for a non-empty target, DATA_LOSS for a path outside it, a short file or a wrong sha256.
  grpc::Status DownloadCapture(const std::string& capture_id,
                               const std::filesystem::path& directory, v1::Capture* out);
  grpc::Status GetResult(const std::string& job_id, v1::Result* out);
  // Downloads every file of the job's report (result.artifacts, from GetResult) into `directory`
  // (absent or empty), as DownloadCapture does: on any error nothing of it is left there.
  grpc::Status DownloadReport(const v1::Result& result, const std::filesystem::path& directory);
  // Calls `on_event` for every event until the job is terminal (OK). Resumes after a cut from the
  // last iteration seen, skipping events already delivered (by seq).
  grpc::Status WatchJob(const std::string& job_id, int from_iteration,
                        const std::function<void(const v1::JobEvent&)>& on_event);
  // grpc.health.v1.Health/Check for `service` ("" = the whole server).
  grpc::Status Health(const std::string& service, ServingStatus* out);

 private:
  // The call's deadline and the station's token.
  void Prepare(grpc::ClientContext* context, std::chrono::milliseconds timeout) const;
  // Runs `call` with a fresh deadline until it returns something other than UNAVAILABLE or the
  // retry budget is spent.
  grpc::Status WithRetry(std::chrono::milliseconds timeout,
                         const std::function<grpc::Status(grpc::ClientContext*)>& call);

  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::Reconstruction::Stub> stub_;
  ClientOptions options_;
};

}  // namespace softid::client
