// End to end in one process: a real gRPC server on a free localhost port with a temporary data
// directory, driven through the client library over loopback.
#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>
#include <gtest/gtest.h>
#include <spdlog/spdlog.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "client/capture_files.h"
#include "client/reconstruction_client.h"
#include "server/api_tokens.h"
#include "server/server.h"
#include "server/store/sqlite_job_store.h"
#include "tests/core/inverse/inverse_test_util.h"
#include "tests/server/temp_dir.h"

// Last: <httplib.h> pulls in <resolv.h>, whose _res macro breaks Eigen headers included after it.
#include <httplib.h>

namespace softid::server {
namespace {

namespace fs = std::filesystem;
using client::ReconstructionClient;
using store::testing::TempDir;

// Fits youngs_modulus on the small capture: a couple of seconds per iteration at most.
std::string FitConfig(int max_iterations) {
  return nlohmann::json{{"fit", {"youngs_modulus"}},
                        {"max_iterations", max_iterations},
                        {"starts", 1},
                        {"threads", 1},
                        {"cells", 8},
                        {"substeps", 2},
                        {"fixed", {{"ground", {{"normal", {0, 0, 1}}, {"offset", 0}}}}}}
      .dump();
}

class GrpcServerTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    spdlog::set_level(spdlog::level::warn);
    capture_ = new inverse::testing::SmallCapture(
        inverse::testing::MakeSmallCapture("torus-drop", /*duration=*/0.2, /*cameras=*/1));
  }
  static void TearDownTestSuite() {
    delete capture_;
    capture_ = nullptr;
  }

  void SetUp() override { ASSERT_TRUE(capture_->ok) << capture_->error; }

  // Starts (or restarts) the server on data_.
  void StartServer(int num_workers, const std::function<void(ServerOptions&)>& adjust = {}) {
    ServerOptions options;
    options.listen_address = "localhost:0";
    options.data_dir = data_.path();
    options.num_workers = num_workers;
    options.lease = std::chrono::milliseconds(5000);
    options.heartbeat_interval = std::chrono::milliseconds(200);
    options.idle_poll_interval = std::chrono::milliseconds(100);
    options.shutdown_grace = std::chrono::milliseconds(500);
    if (adjust) adjust(options);
    Result<std::unique_ptr<Server>> server = Server::Start(options);
    ASSERT_TRUE(server.ok()) << server.status().ToString();
    server_ = std::move(*server);
    client::ClientOptions client_options;
    client_options.retry_budget = std::chrono::milliseconds(2000);
    client_ = std::make_unique<ReconstructionClient>(
        grpc::CreateChannel("localhost:" + std::to_string(server_->port()),
                            grpc::InsecureChannelCredentials()),
        client_options);
  }

  void StopServer() {
    client_.reset();
    if (server_) {
      ASSERT_TRUE(server_->Shutdown().ok());
    }
    server_.reset();
  }

  void TearDown() override { StopServer(); }

  client::CaptureFiles CaptureFiles() {
    client::CaptureFiles files;
    std::string error;
    EXPECT_TRUE(client::ReadCaptureFiles(capture_->directory, &files, &error)) << error;
    return files;
  }

  v1::Capture Upload(const std::string& request_id = "") {
    v1::Capture capture;
    const grpc::Status status = client_->UploadCapture(CaptureFiles(), request_id, &capture);
    EXPECT_TRUE(status.ok()) << status.error_message();
    return capture;
  }

  v1::Job CreateJob(const std::string& capture_id, const std::string& config) {
    v1::CreateJobRequest request;
    request.set_capture_id(capture_id);
    request.set_config_json(config);
    v1::Job job;
    const grpc::Status status = client_->CreateJob(request, &job);
    EXPECT_TRUE(status.ok()) << status.error_message();
    return job;
  }

  // Regular files under DIR/blobs (temporary files excluded).
  int NumBlobs() {
    int n = 0;
    const fs::path blobs = data_.path() / "blobs";
    if (!fs::exists(blobs)) return 0;
    for (const auto& entry : fs::recursive_directory_iterator(blobs)) {
      if (entry.is_regular_file() && entry.path().parent_path().filename() != "tmp") ++n;
    }
    return n;
  }

  static inverse::testing::SmallCapture* capture_;
  TempDir data_;
  std::unique_ptr<Server> server_;
  std::unique_ptr<ReconstructionClient> client_;
};

inverse::testing::SmallCapture* GrpcServerTest::capture_ = nullptr;

// Upload, create, watch to SUCCEEDED, fetch a result with the fitted parameter.
TEST_F(GrpcServerTest, JobRunsFromUploadToResult) {
  StartServer(/*num_workers=*/1);
  const v1::Capture capture = Upload();
  ASSERT_FALSE(capture.id().empty());
  EXPECT_EQ(capture.format(), "softid-capture/1");
  const v1::Job job = CreateJob(capture.id(), FitConfig(/*max_iterations=*/2));
  EXPECT_EQ(job.state(), v1::QUEUED);

  std::vector<v1::JobEvent> events;
  const grpc::Status watched =
      client_->WatchJob(job.id(), 0, [&](const v1::JobEvent& e) { events.push_back(e); });
  ASSERT_TRUE(watched.ok()) << watched.error_message();
  ASSERT_FALSE(events.empty());
  EXPECT_EQ(events.back().state(), v1::SUCCEEDED);
  int iterations = 0;
  for (size_t i = 0; i < events.size(); ++i) {
    if (i > 0) {
      EXPECT_GT(events[i].seq(), events[i - 1].seq());
    }
    if (events[i].kind() == v1::JobEvent::ITERATION) {
      ++iterations;
      EXPECT_EQ(events[i].max_iterations(), 2);
      EXPECT_TRUE(nlohmann::json::parse(events[i].parameters_json()).contains("youngs_modulus"));
    }
  }
  EXPECT_GE(iterations, 1);

  v1::Result result;
  const grpc::Status got = client_->GetResult(job.id(), &result);
  ASSERT_TRUE(got.ok()) << got.error_message();
  const nlohmann::json json = nlohmann::json::parse(result.result_json());
  ASSERT_TRUE(json.contains("parameters"));
  EXPECT_TRUE(json["parameters"].contains("youngs_modulus"));
  EXPECT_FALSE(result.cost_history().empty());
  EXPECT_TRUE(result.ingest_json().empty());  // a capture needs no ingest
  v1::Job done;
  ASSERT_TRUE(client_->GetJob(job.id(), &done).ok());
  EXPECT_TRUE(done.derived_capture_id().empty());

  client::ServingStatus serving = client::ServingStatus::kUnknown;
  ASSERT_TRUE(client_->Health("", &serving).ok());
  EXPECT_EQ(serving, client::ServingStatus::kServing);
}

// "refine_grid": the worker decides after the uncertainty analysis, notes why in the job's
// history, and a refined result is the refit's, on the finer grid, with the first fit beside it.
TEST_F(GrpcServerTest, GridRefinementIsDecidedAndRecordedByTheWorker) {
  StartServer(/*num_workers=*/1);
  const v1::Capture capture = Upload();
  nlohmann::json config = nlohmann::json::parse(FitConfig(/*max_iterations=*/15));
  config["cells"] = 4;  // coarse enough for the grid to move E by more than its noise
  config["refine_grid"] = true;
  const v1::Job job = CreateJob(capture.id(), config.dump());
  std::vector<v1::JobEvent> events;
  ASSERT_TRUE(
      client_->WatchJob(job.id(), 0, [&](const v1::JobEvent& e) { events.push_back(e); }).ok());
  ASSERT_FALSE(events.empty());
  EXPECT_EQ(events.back().state(), v1::SUCCEEDED);
  int notes = 0;
  for (const v1::JobEvent& e : events) {
    if (e.message().rfind("grid refinement: ", 0) == 0) ++notes;
  }
  EXPECT_EQ(notes, 1);

  v1::Result result;
  ASSERT_TRUE(client_->GetResult(job.id(), &result).ok());
  const nlohmann::json json = nlohmann::json::parse(result.result_json());
  ASSERT_TRUE(json.contains("grid_refinement")) << json.dump();
  const nlohmann::json& refinement = json["grid_refinement"];
  std::printf("%s\n", refinement["reason"].get<std::string>().c_str());
  EXPECT_EQ(refinement["cells"], 4);
  ASSERT_TRUE(refinement["refined"].get<bool>());
  EXPECT_EQ(refinement["finer_cells"], 6);
  EXPECT_EQ(json["grid"]["cells"], 6);
  EXPECT_EQ(refinement["first_fit"]["grid"]["cells"], 4);
  EXPECT_TRUE(json["parameters"]["youngs_modulus"].contains("discretisation_error"));
}

// A station uploading files the server already holds for it sends only the new ones; another
// station's copies do not count (it cannot learn what others uploaded), and a file left out that
// the station does not hold fails the upload naming it.
TEST_F(GrpcServerTest, UploadsLeaveOutTheFilesTheStationAlreadyStored) {
  std::string alice, bob;
  {
    Result<std::unique_ptr<store::SqliteJobStore>> tokens =
        store::SqliteJobStore::Open(data_.path() / "softid.db");
    ASSERT_TRUE(tokens.ok()) << tokens.status().ToString();
    alice = IssueToken(**tokens, "alice", false, std::nullopt)->secret;
    bob = IssueToken(**tokens, "bob", false, std::nullopt)->secret;
    ASSERT_TRUE((*tokens)->Close().ok());
  }
  StartServer(/*num_workers=*/0, [](ServerOptions& options) { options.auth = AuthMode::kToken; });
  const auto client_for = [&](const std::string& token) {
    client::ClientOptions options;
    options.token = token;
    return std::make_unique<ReconstructionClient>(
        grpc::CreateChannel("localhost:" + std::to_string(server_->port()),
                            grpc::InsecureChannelCredentials()),
        options);
  };
  const client::CaptureFiles files = CaptureFiles();
  const int num_files = static_cast<int>(files.files.size());
  std::unique_ptr<ReconstructionClient> as_alice = client_for(alice);
  v1::Capture first, second, bobs;
  int skipped = -1;
  ASSERT_TRUE(as_alice->UploadCapture(files, "", &first, &skipped).ok());
  EXPECT_EQ(skipped, 0);
  ASSERT_TRUE(as_alice->UploadCapture(files, "", &second, &skipped).ok());
  EXPECT_EQ(skipped, num_files);
  EXPECT_NE(second.id(), first.id());
  ASSERT_EQ(second.files_size(), first.files_size());
  for (int i = 0; i < first.files_size(); ++i) {
    EXPECT_EQ(second.files(i).sha256(), first.files(i).sha256());
  }
  std::unique_ptr<ReconstructionClient> as_bob = client_for(bob);
  std::set<std::string> held;
  ASSERT_TRUE(as_bob->FindCaptureFiles(files, &held).ok());
  EXPECT_TRUE(held.empty());
  ASSERT_TRUE(as_bob->UploadCapture(files, "", &bobs, &skipped).ok());
  EXPECT_EQ(skipped, 0);

  // A manifest whose frame's bytes never come, for a frame nobody holds.
  client::CaptureFiles forged = files;
  forged.files.back().set_sha256(std::string(64, 'a'));
  auto channel = grpc::CreateChannel("localhost:" + std::to_string(server_->port()),
                                     grpc::InsecureChannelCredentials());
  auto stub = v1::Reconstruction::NewStub(channel);
  grpc::ClientContext context;
  context.AddMetadata("authorization", "Bearer " + alice);
  v1::Capture none;
  auto writer = stub->UploadCapture(&context, &none);
  v1::UploadCaptureRequest request;
  request.mutable_manifest()->set_capture_json(forged.capture_json);
  for (const v1::CaptureFile& file : forged.files) *request.mutable_manifest()->add_files() = file;
  ASSERT_TRUE(writer->Write(request));
  writer->WritesDone();
  const grpc::Status refused = writer->Finish();
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(refused.error_message().find(forged.files.back().path()), std::string::npos)
      << refused.error_message();
}

// A finished job's report: listed in the result, downloaded into a new folder as PNGs of the
// listed sizes, refused for names it does not list (no path leaves the report), gone with the job.
TEST_F(GrpcServerTest, ReportIsListedDownloadedAndDeletedWithTheJob) {
  StartServer(/*num_workers=*/1);
  const v1::Job job = CreateJob(Upload().id(), FitConfig(/*max_iterations=*/1));
  ASSERT_TRUE(client_->WatchJob(job.id(), 0, [](const v1::JobEvent&) {}).ok());
  v1::Result result;
  ASSERT_TRUE(client_->GetResult(job.id(), &result).ok());
  std::vector<std::string> names;
  for (const v1::Artifact& artifact : result.artifacts()) {
    names.push_back(artifact.name());
    EXPECT_EQ(artifact.media_type(), "image/png");
  }
  EXPECT_EQ(names, (std::vector<std::string>{"cost_per_iteration.png", "residual_per_frame.png",
                                             "surface_overlay.png"}));
  EXPECT_EQ(nlohmann::json::parse(result.result_json())["report"]["files"].size(), 3u);

  TempDir local;
  const fs::path into = local.path() / "report";
  const grpc::Status downloaded = client_->DownloadReport(result, into);
  ASSERT_TRUE(downloaded.ok()) << downloaded.error_message();
  for (const v1::Artifact& artifact : result.artifacts()) {
    const fs::path file = into / artifact.name();
    ASSERT_TRUE(fs::exists(file)) << file;
    EXPECT_EQ(static_cast<int64_t>(fs::file_size(file)), artifact.size_bytes());
    std::ifstream in(file, std::ios::binary);
    std::string magic(8, '\0');
    in.read(magic.data(), 8);
    EXPECT_EQ(magic, std::string("\x89PNG\r\n\x1a\n", 8)) << file;
  }
  // A second download into the same (now full) folder is refused and leaves it as it was.
  EXPECT_EQ(client_->DownloadReport(result, into).error_code(),
            grpc::StatusCode::FAILED_PRECONDITION);

  for (const std::string& name : {"../softid.db", "/etc/passwd", "missing.png", ""}) {
    // The server is asked for `name` directly: the client's own path check is not what stops it.
    v1::DownloadArtifactRequest request;
    request.set_job_id(job.id());
    request.set_name(name);
    auto channel = grpc::CreateChannel("localhost:" + std::to_string(server_->port()),
                                       grpc::InsecureChannelCredentials());
    auto stub = v1::Reconstruction::NewStub(channel);
    grpc::ClientContext context;
    auto reader = stub->DownloadArtifact(&context, request);
    v1::FileChunk chunk;
    EXPECT_FALSE(reader->Read(&chunk)) << name;
    EXPECT_EQ(reader->Finish().error_code(), grpc::StatusCode::NOT_FOUND) << name;
  }

  ASSERT_TRUE(client_->DeleteJob(job.id()).ok());
  EXPECT_FALSE(fs::exists(data_.path() / "reports" / job.id()));
}

// The progress contract (softid.proto, WatchJob): every start sends iteration 0 and each of its
// iterations once, across continuation stages and the refinement; the result's cost history has
// one entry per iteration of the best start, each with the last frame its cost is over.
TEST_F(GrpcServerTest, ProgressEventsAndCostHistoryFollowTheContract) {
  StartServer(/*num_workers=*/1);
  const v1::Capture capture = Upload();
  const std::string config =
      nlohmann::json{{"fit", {"youngs_modulus"}},
                     {"initial", {{"youngs_modulus", {{"min", 2e4}, {"max", 2e5}}}}},
                     {"max_iterations", 4},
                     {"refine_iterations", 1},
                     {"starts", 2},
                     {"threads", 2},
                     {"cells", 8},
                     {"substeps", 2},
                     {"fixed", {{"ground", {{"normal", {0, 0, 1}}, {"offset", 0}}}}}}
          .dump();
  const v1::Job job = CreateJob(capture.id(), config);
  std::vector<v1::JobEvent> events;
  const grpc::Status watched =
      client_->WatchJob(job.id(), 0, [&](const v1::JobEvent& e) { events.push_back(e); });
  ASSERT_TRUE(watched.ok()) << watched.error_message();
  ASSERT_EQ(events.back().state(), v1::SUCCEEDED) << events.back().message();
  v1::Result result;
  ASSERT_TRUE(client_->GetResult(job.id(), &result).ok());
  const nlohmann::json json = nlohmann::json::parse(result.result_json());

  std::map<int, std::vector<int>> iterations_by_start;
  for (const v1::JobEvent& event : events) {
    if (event.kind() != v1::JobEvent::ITERATION) continue;
    EXPECT_EQ(event.num_starts(), 2);
    EXPECT_EQ(event.max_iterations(), 5);
    EXPECT_GE(event.remaining_seconds(), 0.0);
    iterations_by_start[event.start()].push_back(event.iteration());
  }
  ASSERT_EQ(iterations_by_start.size(), 2u);
  for (const auto& [start, iterations] : iterations_by_start) {
    const nlohmann::json& start_json = json["starts"][start];
    int ran = start_json["iterations"].get<int>();
    if (!start_json["refinement"].is_null())
      ran += start_json["refinement"]["iterations"].get<int>();
    ASSERT_EQ(iterations.size(), static_cast<size_t>(ran + 1)) << "start " << start;
    for (int i = 0; i <= ran; ++i) EXPECT_EQ(iterations[i], i) << "start " << start;
  }
  const int best = json["best_start"].get<int>();
  const size_t best_iterations = iterations_by_start[best].size() - 1;
  ASSERT_EQ(static_cast<size_t>(result.cost_history_size()), best_iterations);
  ASSERT_EQ(static_cast<size_t>(result.cost_history_last_frame_size()), best_iterations);
  EXPECT_EQ(json["cost_history"].size(), best_iterations);
  ASSERT_GT(best_iterations, 0u);
  EXPECT_EQ(result.cost_history_last_frame(result.cost_history_last_frame_size() - 1),
            capture_->capture.NumFrames() - 1);
  EXPECT_DOUBLE_EQ(result.cost_history(result.cost_history_size() - 1),
                   json["cost"]["final"].get<double>());
}

// An upload stream that stops sending is cancelled after the idle timeout and leaves nothing
// staged; uploads beyond the concurrent limit are refused while the others run.
TEST_F(GrpcServerTest, IdleUploadsAreCancelledAndConcurrentUploadsBounded) {
  StartServer(/*num_workers=*/0, [](ServerOptions& options) {
    options.upload_limits.idle_timeout = std::chrono::milliseconds(300);
    options.upload_limits.max_concurrent = 2;
  });
  const client::CaptureFiles files = CaptureFiles();
  auto stub = v1::Reconstruction::NewStub(grpc::CreateChannel(
      "localhost:" + std::to_string(server_->port()), grpc::InsecureChannelCredentials()));
  v1::UploadCaptureRequest manifest;
  manifest.mutable_manifest()->set_capture_json(files.capture_json);
  for (const v1::CaptureFile& file : files.files) *manifest.mutable_manifest()->add_files() = file;

  struct Stream {
    grpc::ClientContext context;
    v1::Capture reply;
    std::unique_ptr<grpc::ClientWriter<v1::UploadCaptureRequest>> writer;
  };
  std::vector<std::unique_ptr<Stream>> streams;
  for (int i = 0; i < 3; ++i) {
    auto stream = std::make_unique<Stream>();
    stream->writer = stub->UploadCapture(&stream->context, &stream->reply);
    ASSERT_TRUE(stream->writer->Write(manifest));
    streams.push_back(std::move(stream));
    std::this_thread::sleep_for(std::chrono::milliseconds(50));  // begun in this order
  }
  // The third found two uploads in progress.
  const grpc::Status third = streams[2]->writer->Finish();
  EXPECT_EQ(third.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << third.error_message();
  // The first two send nothing more: cancelled by the server, nothing staged.
  for (int i = 0; i < 2; ++i) {
    const grpc::Status status = streams[i]->writer->Finish();
    EXPECT_EQ(status.error_code(), grpc::StatusCode::CANCELLED) << status.error_message();
  }
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (!fs::is_empty(data_.path() / "uploads") && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  EXPECT_TRUE(fs::is_empty(data_.path() / "uploads"));
  // The slots are free again: a complete upload goes through.
  EXPECT_FALSE(Upload().id().empty());
}

// With tokens on, 16 stations upload and create jobs at once, each through its own token; each
// lists and reads only its own job, another's is NOT_FOUND, a call without a token or with a
// revoked one is UNAUTHENTICATED, and an admin token sees all.
TEST_F(GrpcServerTest, SixteenStationsWithTokensSeeOnlyTheirOwnJobs) {
  constexpr int kStations = 16;
  std::vector<std::string> secrets;
  std::string admin_secret, revoked_secret;
  {
    Result<std::unique_ptr<store::SqliteJobStore>> tokens =
        store::SqliteJobStore::Open(data_.path() / "softid.db");
    ASSERT_TRUE(tokens.ok()) << tokens.status().ToString();
    for (int i = 0; i < kStations; ++i) {
      Result<IssuedToken> issued =
          IssueToken(**tokens, "station-" + std::to_string(i), false, std::nullopt);
      ASSERT_TRUE(issued.ok()) << issued.status().ToString();
      secrets.push_back(issued->secret);
    }
    admin_secret = IssueToken(**tokens, "ops", true, std::nullopt)->secret;
    Result<IssuedToken> revoked = IssueToken(**tokens, "old", false, std::nullopt);
    ASSERT_TRUE(revoked.ok());
    revoked_secret = revoked->secret;
    ASSERT_TRUE((*tokens)->RevokeToken(revoked->token.id).ok());
    ASSERT_TRUE((*tokens)->Close().ok());
  }
  StartServer(/*num_workers=*/0, [](ServerOptions& options) { options.auth = AuthMode::kToken; });
  const auto client_for = [&](const std::string& token) {
    client::ClientOptions options;
    options.retry_budget = std::chrono::milliseconds(0);
    options.token = token;
    return std::make_unique<ReconstructionClient>(
        grpc::CreateChannel("localhost:" + std::to_string(server_->port()),
                            grpc::InsecureChannelCredentials()),
        options);
  };

  std::vector<std::string> job_ids(kStations);
  std::vector<std::string> errors(kStations);
  {
    const client::CaptureFiles files = CaptureFiles();
    std::vector<std::thread> stations;
    for (int i = 0; i < kStations; ++i) {
      stations.emplace_back([&, i] {
        std::unique_ptr<ReconstructionClient> client = client_for(secrets[i]);
        v1::Capture capture;
        grpc::Status status = client->UploadCapture(files, "", &capture);
        if (!status.ok()) {
          errors[i] = "upload: " + status.error_message();
          return;
        }
        v1::CreateJobRequest request;
        request.set_capture_id(capture.id());
        request.set_config_json(FitConfig(1));
        v1::Job job;
        status = client->CreateJob(request, &job);
        if (!status.ok()) {
          errors[i] = "create: " + status.error_message();
          return;
        }
        job_ids[i] = job.id();
      });
    }
    for (std::thread& station : stations) station.join();
  }
  for (int i = 0; i < kStations; ++i) ASSERT_EQ(errors[i], "") << "station " << i;

  for (int i = 0; i < kStations; ++i) {
    std::unique_ptr<ReconstructionClient> client = client_for(secrets[i]);
    v1::ListJobsResponse page;
    ASSERT_TRUE(client->ListJobs(v1::ListJobsRequest(), &page).ok());
    ASSERT_EQ(page.jobs_size(), 1) << "station " << i;
    EXPECT_EQ(page.jobs(0).id(), job_ids[i]);
    v1::Job other;
    EXPECT_EQ(client->GetJob(job_ids[(i + 1) % kStations], &other).error_code(),
              grpc::StatusCode::NOT_FOUND);
  }
  v1::ListJobsResponse all;
  ASSERT_TRUE(client_for(admin_secret)->ListJobs(v1::ListJobsRequest(), &all).ok());
  EXPECT_EQ(all.jobs_size(), kStations);
  v1::ListJobsResponse none;
  EXPECT_EQ(client_for("")->ListJobs(v1::ListJobsRequest(), &none).error_code(),
            grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_EQ(client_for(revoked_secret)->ListJobs(v1::ListJobsRequest(), &none).error_code(),
            grpc::StatusCode::UNAUTHENTICATED);
  // Health stays open for load balancers and probes.
  client::ServingStatus serving = client::ServingStatus::kUnknown;
  EXPECT_TRUE(client_for("")->Health("", &serving).ok());
}

// GET /metrics serves the Prometheus text format: jobs by state, iterations, uploads and their
// bytes, refusals by method and code, and the time histograms.
TEST_F(GrpcServerTest, MetricsEndpointCountsWhatHappened) {
  StartServer(/*num_workers=*/1,
              [](ServerOptions& options) { options.metrics_listen = "127.0.0.1:0"; });
  ASSERT_GT(server_->metrics_port(), 0);
  const v1::Capture capture = Upload();
  const v1::Job job = CreateJob(capture.id(), FitConfig(/*max_iterations=*/2));
  ASSERT_TRUE(client_->WatchJob(job.id(), 0, [](const v1::JobEvent&) {}).ok());
  v1::CreateJobRequest bad;
  bad.set_capture_id(capture.id());
  bad.set_config_json(R"({"cells": "many"})");
  v1::Job refused;
  EXPECT_EQ(client_->CreateJob(bad, &refused).error_code(), grpc::StatusCode::INVALID_ARGUMENT);

  httplib::Client http("127.0.0.1", server_->metrics_port());
  // The worker counts the run just after it records the job's end: wait for it to be idle.
  httplib::Result response = http.Get("/metrics");
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (response && response->body.find("softid_workers_busy 0\n") == std::string::npos &&
         std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    response = http.Get("/metrics");
  }
  ASSERT_TRUE(response) << "no answer from /metrics";
  EXPECT_EQ(response->status, 200);
  EXPECT_NE(response->get_header_value("Content-Type").find("text/plain; version=0.0.4"),
            std::string::npos);
  const std::string& text = response->body;
  for (const char* line :
       {"softid_jobs{state=\"SUCCEEDED\"} 1\n", "softid_jobs{state=\"QUEUED\"} 0\n",
        "softid_uploads_total{outcome=\"stored\"} 1\n", "softid_workers 1\n",
        "softid_workers_busy 0\n",
        "softid_refused_requests_total{method=\"CreateJob\",code=\"INVALID_ARGUMENT\"} 1\n",
        "softid_job_queue_wait_seconds_count 1\n",
        "softid_job_run_seconds_count{outcome=\"succeeded\"} 1\n",
        "# TYPE softid_job_run_seconds histogram\n"}) {
    EXPECT_NE(text.find(line), std::string::npos) << "missing " << line << " in:\n" << text;
  }
  const size_t iterations = text.find("\nsoftid_iterations_total ");
  ASSERT_NE(iterations, std::string::npos);
  EXPECT_GE(std::stoi(text.substr(iterations + 25)), 1);
  EXPECT_EQ(http.Get("/other")->status, 404);
}

// A config the core rejects is INVALID_ARGUMENT naming the field and value.
TEST_F(GrpcServerTest, InvalidConfigIsRejectedWithTheField) {
  StartServer(/*num_workers=*/0);
  const v1::Capture capture = Upload();
  v1::CreateJobRequest request;
  request.set_capture_id(capture.id());
  request.set_config_json(R"({"fit": ["youngs_modulo"]})");
  v1::Job job;
  const grpc::Status status = client_->CreateJob(request, &job);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(status.error_message().find("fit[0]"), std::string::npos) << status.error_message();
  EXPECT_NE(status.error_message().find("youngs_modulo"), std::string::npos);

  request.set_capture_id("cap-0123456789abcdef");
  request.set_config_json("");
  EXPECT_EQ(client_->CreateJob(request, &job).error_code(), grpc::StatusCode::NOT_FOUND);
}

// A file whose bytes do not match its declared sha256 fails the upload and stores nothing.
TEST_F(GrpcServerTest, BadSha256StoresNothing) {
  StartServer(/*num_workers=*/0);
  client::CaptureFiles files = CaptureFiles();
  ASSERT_GE(files.files.size(), 2u);
  const std::string path = files.files[1].path();
  files.files[1].set_sha256(std::string(64, '0'));
  v1::Capture capture;
  const grpc::Status status = client_->UploadCapture(files, "", &capture);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(status.error_message().find(path), std::string::npos) << status.error_message();
  EXPECT_NE(status.error_message().find("sha256"), std::string::npos);
  EXPECT_EQ(NumBlobs(), 0);
  EXPECT_TRUE(fs::is_empty(data_.path() / "uploads"));
}

// A repeated request_id returns the capture stored the first time.
TEST_F(GrpcServerTest, UploadIsIdempotentByRequestId) {
  StartServer(/*num_workers=*/0);
  const v1::Capture first = Upload("station-7/take-1");
  const v1::Capture again = Upload("station-7/take-1");
  EXPECT_EQ(first.id(), again.id());
}

// Unknown ids are NOT_FOUND; a result asked before the job succeeded is FAILED_PRECONDITION; a
// queued job cancels at once.
TEST_F(GrpcServerTest, UnknownJobResultBeforeDoneAndCancel) {
  StartServer(/*num_workers=*/0);
  v1::Job job;
  EXPECT_EQ(client_->GetJob("job-0123456789abcdef", &job).error_code(),
            grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(client_->GetJob("nonsense", &job).error_code(), grpc::StatusCode::INVALID_ARGUMENT);

  const v1::Capture capture = Upload();
  const v1::Job queued = CreateJob(capture.id(), FitConfig(/*max_iterations=*/2));
  v1::Result result;
  EXPECT_EQ(client_->GetResult(queued.id(), &result).error_code(),
            grpc::StatusCode::FAILED_PRECONDITION);

  v1::Job cancelled;
  ASSERT_TRUE(client_->CancelJob(queued.id(), &cancelled).ok());
  EXPECT_EQ(cancelled.state(), v1::CANCELLED);

  v1::ListJobsRequest list;
  list.set_state(v1::CANCELLED);
  v1::ListJobsResponse page;
  ASSERT_TRUE(client_->ListJobs(list, &page).ok());
  ASSERT_EQ(page.jobs_size(), 1);
  EXPECT_EQ(page.jobs(0).id(), queued.id());
}

// A job RUNNING when the server stops is QUEUED again (released at shutdown), keeps its history
// after a restart and then completes.
TEST_F(GrpcServerTest, RunningJobSurvivesRestart) {
  StartServer(/*num_workers=*/1);
  const v1::Capture capture = Upload();
  const v1::Job job = CreateJob(capture.id(), FitConfig(/*max_iterations=*/15));

  // Stop on the first iteration: the fit is running.
  int iterations_before = 0;
  {
    grpc::ClientContext context;
    v1::WatchJobRequest request;
    request.set_job_id(job.id());
    auto stub = v1::Reconstruction::NewStub(grpc::CreateChannel(
        "localhost:" + std::to_string(server_->port()), grpc::InsecureChannelCredentials()));
    auto reader = stub->WatchJob(&context, request);
    v1::JobEvent event;
    while (reader->Read(&event)) {
      if (event.kind() == v1::JobEvent::ITERATION) {
        ++iterations_before;
        break;
      }
    }
    context.TryCancel();
    (void)reader->Finish();
  }
  ASSERT_EQ(iterations_before, 1);
  StopServer();

  // No workers: the recovered job waits in the queue.
  StartServer(/*num_workers=*/0);
  v1::Job recovered;
  ASSERT_TRUE(client_->GetJob(job.id(), &recovered).ok());
  EXPECT_EQ(recovered.state(), v1::QUEUED);
  StopServer();

  StartServer(/*num_workers=*/1);
  std::vector<v1::JobEvent> events;
  ASSERT_TRUE(
      client_->WatchJob(job.id(), 0, [&](const v1::JobEvent& e) { events.push_back(e); }).ok());
  ASSERT_FALSE(events.empty());
  EXPECT_EQ(events.back().state(), v1::SUCCEEDED);
  // The first attempt's iterations are still in the history, followed by the second attempt's.
  bool first_attempt_iteration = false, second_attempt_iteration = false, requeued = false;
  for (const v1::JobEvent& e : events) {
    if (e.kind() == v1::JobEvent::ITERATION && e.attempt() == 1) first_attempt_iteration = true;
    if (e.kind() == v1::JobEvent::ITERATION && e.attempt() == 2) second_attempt_iteration = true;
    if (e.kind() == v1::JobEvent::STATE_CHANGE && e.state() == v1::QUEUED &&
        e.message().find("requeued") != std::string::npos) {
      requeued = true;
    }
  }
  EXPECT_TRUE(first_attempt_iteration);
  EXPECT_TRUE(second_attempt_iteration);
  EXPECT_TRUE(requeued);
  v1::Job done;
  ASSERT_TRUE(client_->GetJob(job.id(), &done).ok());
  EXPECT_EQ(done.attempts(), 2);
}

}  // namespace
}  // namespace softid::server
