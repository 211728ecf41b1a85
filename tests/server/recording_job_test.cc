// Raw recordings through the service, end to end in one process: a synthetic raw recording
// (core/scenes: a torus dropped in a cluttered room, 160x120, a few frames) uploaded by a station
// with the client library, validated and stored with its format; a job on it that ingests it,
// stores the derived capture and fits it; the derived capture downloaded byte for byte; and what
// a station can get wrong (malformed recording.json, both or neither description, frames without
// the object, another station's capture).
#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>
#include <gtest/gtest.h>
#include <spdlog/spdlog.h>

#include <filesystem>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "client/capture_download.h"
#include "client/capture_files.h"
#include "client/reconstruction_client.h"
#include "core/capture/capture.h"
#include "core/capture/depth_noise.h"
#include "core/scenes/raw_recording_synthesis.h"
#include "core/scenes/scene.h"
#include "server/api_tokens.h"
#include "server/server.h"
#include "server/store/sqlite_job_store.h"
#include "tests/server/temp_dir.h"

namespace softid::server {
namespace {

namespace fs = std::filesystem;
using client::ReconstructionClient;
using store::testing::TempDir;

// One iteration of youngs_modulus on the ingested capture (its floor is the ground): seconds.
std::string ShortFitConfig() {
  return nlohmann::json{{"fit", {"youngs_modulus"}},
                        {"max_iterations", 1},
                        {"starts", 1},
                        {"threads", 1},
                        {"cells", 8},
                        {"substeps", 2},
                        {"uncertainty", false}}
      .dump();
}

// A 0.2 s raw recording of the torus drop (12 frames at 60 fps) with two background frames.
bool WriteRecording(const fs::path& dir, std::string* error) {
  Result<scenes::Scene> scene = scenes::MakeBuiltinScene("torus-drop");
  if (!scene.ok()) {
    *error = scene.status().ToString();
    return false;
  }
  scenes::RawSynthesisOptions options;
  options.run.duration = 0.2;
  options.cameras.width = 160;
  options.cameras.height = 120;
  options.noise = capture::StructuredLightNoise(3);
  options.depth_scale = capture::kStructuredLightDepthScale;
  options.background_frames = 2;
  const Result<scenes::RawSynthesisSummary> written =
      scenes::SynthesizeRawRecording(*scene, options, dir);
  if (!written.ok()) *error = written.status().ToString();
  return written.ok();
}

class RecordingJobTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    spdlog::set_level(spdlog::level::warn);
    folders_ = new TempDir();
    std::string error;
    ok_ = WriteRecording(Recording(), &error);
    // The same recording with every frame replaced by the empty scene: nothing to track.
    if (ok_) {
      fs::copy(Recording(), EmptyRecording(), fs::copy_options::recursive);
      const nlohmann::json json = ReadJson(EmptyRecording() / "recording.json");
      const fs::path background =
          EmptyRecording() / json["cameras"][0]["background"][0].get<std::string>();
      for (const nlohmann::json& frame : json["cameras"][0]["frames"]) {
        fs::copy_file(background, EmptyRecording() / frame["file"].get<std::string>(),
                      fs::copy_options::overwrite_existing);
      }
    }
    error_ = error;
  }
  static void TearDownTestSuite() {
    delete folders_;
    folders_ = nullptr;
  }
  static fs::path Recording() { return folders_->path() / "recording"; }
  static fs::path EmptyRecording() { return folders_->path() / "empty"; }
  static nlohmann::json ReadJson(const fs::path& file) {
    std::ifstream in(file);
    return nlohmann::json::parse(in);
  }

  void SetUp() override {
    ASSERT_TRUE(ok_) << error_;
    Result<std::unique_ptr<store::SqliteJobStore>> tokens =
        store::SqliteJobStore::Open(data_.path() / "softid.db");
    ASSERT_TRUE(tokens.ok()) << tokens.status().ToString();
    for (const char* station : {"station-a", "station-b"}) {
      Result<IssuedToken> issued = IssueToken(**tokens, station, false, std::nullopt);
      ASSERT_TRUE(issued.ok()) << issued.status().ToString();
      secrets_.push_back(issued->secret);
    }
    ASSERT_TRUE((*tokens)->Close().ok());
  }

  void StartServer(int num_workers) {
    ServerOptions options;
    options.listen_address = "localhost:0";
    options.data_dir = data_.path();
    options.num_workers = num_workers;
    options.auth = AuthMode::kToken;
    options.lease = std::chrono::milliseconds(5000);
    options.heartbeat_interval = std::chrono::milliseconds(200);
    options.idle_poll_interval = std::chrono::milliseconds(100);
    options.shutdown_grace = std::chrono::milliseconds(500);
    Result<std::unique_ptr<Server>> server = Server::Start(options);
    ASSERT_TRUE(server.ok()) << server.status().ToString();
    server_ = std::move(*server);
    a_ = ClientFor(secrets_[0]);
    b_ = ClientFor(secrets_[1]);
  }

  void StopServer() {
    a_.reset();
    b_.reset();
    if (server_) {
      ASSERT_TRUE(server_->Shutdown().ok());
    }
    server_.reset();
  }

  void TearDown() override { StopServer(); }

  std::unique_ptr<ReconstructionClient> ClientFor(const std::string& token) {
    client::ClientOptions options;
    options.retry_budget = std::chrono::milliseconds(0);
    options.token = token;
    return std::make_unique<ReconstructionClient>(
        grpc::CreateChannel("localhost:" + std::to_string(server_->port()),
                            grpc::InsecureChannelCredentials()),
        options);
  }

  static client::CaptureFiles FolderFiles(const fs::path& dir) {
    client::CaptureFiles files;
    std::string error;
    EXPECT_TRUE(client::ReadFolderFiles(dir, &files, &error)) << error;
    return files;
  }

  v1::Capture UploadOk(ReconstructionClient& client, const fs::path& dir) {
    v1::Capture capture;
    const grpc::Status status = client.UploadCapture(FolderFiles(dir), "", &capture);
    EXPECT_TRUE(status.ok()) << status.error_message();
    return capture;
  }

  // Creates a job and watches it to its end; the events seen.
  std::vector<v1::JobEvent> RunJob(const std::string& capture_id, v1::Job* job) {
    v1::CreateJobRequest request;
    request.set_capture_id(capture_id);
    request.set_config_json(ShortFitConfig());
    std::vector<v1::JobEvent> events;
    const grpc::Status created = a_->CreateJob(request, job);
    EXPECT_TRUE(created.ok()) << created.error_message();
    if (!created.ok()) return events;
    const grpc::Status watched =
        a_->WatchJob(job->id(), 0, [&](const v1::JobEvent& e) { events.push_back(e); });
    EXPECT_TRUE(watched.ok()) << watched.error_message();
    EXPECT_TRUE(a_->GetJob(job->id(), job).ok());
    return events;
  }

  int NumCaptures(ReconstructionClient& client) {
    v1::ListCapturesResponse page;
    EXPECT_TRUE(client.ListCaptures({}, &page).ok());
    return page.captures_size();
  }

  int NumBlobs() {
    int n = 0;
    const fs::path blobs = data_.path() / "blobs";
    if (!fs::exists(blobs)) return 0;
    for (const auto& entry : fs::recursive_directory_iterator(blobs)) {
      if (entry.is_regular_file() && entry.path().parent_path().filename() != "tmp") ++n;
    }
    return n;
  }

  static TempDir* folders_;
  static bool ok_;
  static std::string error_;
  TempDir data_;
  std::vector<std::string> secrets_;
  std::unique_ptr<Server> server_;
  std::unique_ptr<ReconstructionClient> a_, b_;
};

TempDir* RecordingJobTest::folders_ = nullptr;
bool RecordingJobTest::ok_ = false;
std::string RecordingJobTest::error_;

TEST_F(RecordingJobTest, RecordingUploadIsStoredWithItsFormatAndSizesItsJobs) {
  StartServer(/*num_workers=*/0);
  const client::CaptureFiles files = FolderFiles(Recording());
  EXPECT_TRUE(files.capture_json.empty());
  EXPECT_FALSE(files.recording_json.empty());
  // scan.ply, 12 frames minus the dropped one, 2 background frames.
  EXPECT_GE(files.files.size(), 12u);

  const v1::Capture capture = UploadOk(*a_, Recording());
  EXPECT_EQ(capture.format(), "softid-recording/1");
  ASSERT_EQ(capture.files_size(), static_cast<int>(files.files.size()) + 1);
  EXPECT_EQ(capture.files(0).path(), "recording.json");
  v1::ListCapturesResponse page;
  ASSERT_TRUE(a_->ListCaptures({}, &page).ok());
  ASSERT_EQ(page.captures_size(), 1);
  EXPECT_EQ(page.captures(0).format(), "softid-recording/1");

  // Jobs on it are sized at the door from its mesh and frames, as on a capture.
  const int frames =
      static_cast<int>(nlohmann::json::parse(files.recording_json)["cameras"][0]["frames"].size());
  for (const auto& [config, needle] : std::vector<std::pair<nlohmann::json, std::string>>{
           {{{"cells", 300}}, "config_json: cells = 300"},
           {{{"frames", {{"last", frames}}}},
            "frames.last = " + std::to_string(frames) + ": the capture has " +
                std::to_string(frames) + " frames"}}) {
    v1::CreateJobRequest request;
    request.set_capture_id(capture.id());
    request.set_config_json(config.dump());
    v1::Job job;
    const grpc::Status status = a_->CreateJob(request, &job);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << config.dump();
    EXPECT_NE(status.error_message().find(needle), std::string::npos) << status.error_message();
  }
}

TEST_F(RecordingJobTest, MalformedRecordingIsRefusedNamingFieldAndValueAndNothingStored) {
  StartServer(/*num_workers=*/0);
  client::CaptureFiles files = FolderFiles(Recording());
  nlohmann::json json = nlohmann::json::parse(files.recording_json);
  json["cameras"][0]["depth_scale"] = -0.001;
  files.recording_json = json.dump();
  v1::Capture capture;
  grpc::Status status = a_->UploadCapture(files, "", &capture);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(status.error_message().find("cameras[0].depth_scale = -0.001"), std::string::npos)
      << status.error_message();

  // A frame that is not a PNG: found when the whole recording is validated, named by its file.
  files = FolderFiles(Recording());
  const std::string frame = json["cameras"][0]["frames"][1]["file"];
  const fs::path broken = folders_->path() / "broken";
  fs::remove_all(broken);
  fs::copy(Recording(), broken, fs::copy_options::recursive);
  std::ofstream(broken / frame, std::ios::binary | std::ios::trunc) << "not a png";
  status = a_->UploadCapture(FolderFiles(broken), "", &capture);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(status.error_message().find(frame), std::string::npos) << status.error_message();
  EXPECT_EQ(status.error_message().find(data_.path().string()), std::string::npos);

  EXPECT_EQ(NumCaptures(*a_), 0);
  EXPECT_EQ(NumBlobs(), 0);
}

TEST_F(RecordingJobTest, BothOrNeitherDescriptionIsRefused) {
  StartServer(/*num_workers=*/0);
  client::CaptureFiles files = FolderFiles(Recording());
  files.capture_json = R"({"format": "softid-capture/1"})";
  v1::Capture capture;
  grpc::Status status = a_->UploadCapture(files, "", &capture);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(status.error_message().find("capture_json, recording_json: both are set"),
            std::string::npos)
      << status.error_message();
  files.capture_json.clear();
  files.recording_json.clear();
  status = a_->UploadCapture(files, "", &capture);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(status.error_message().find("capture_json, recording_json: neither is set"),
            std::string::npos)
      << status.error_message();
  EXPECT_EQ(NumCaptures(*a_), 0);
  EXPECT_EQ(NumBlobs(), 0);
}

// The whole path: ingest (its stages as notes), the derived capture stored for the station and
// named by the job, the fit, the ingest report in the result; then the derived capture downloaded
// byte for byte, refused to another station, and kept from deletion while the job exists.
TEST_F(RecordingJobTest, RecordingJobIngestsFitsAndItsDerivedCaptureDownloads) {
  StartServer(/*num_workers=*/1);
  const v1::Capture recording = UploadOk(*a_, Recording());
  v1::Job job;
  const std::vector<v1::JobEvent> events = RunJob(recording.id(), &job);
  ASSERT_EQ(job.state(), v1::SUCCEEDED) << job.error();
  ASSERT_FALSE(job.derived_capture_id().empty());
  EXPECT_NE(job.derived_capture_id(), recording.id());

  int segmentation_notes = 0, iterations = 0, last_ingest_seq = 0, first_iteration_seq = 0;
  for (const v1::JobEvent& event : events) {
    if (event.kind() == v1::JobEvent::ITERATION) {
      ++iterations;
      if (first_iteration_seq == 0) first_iteration_seq = static_cast<int>(event.seq());
    } else if (event.message().rfind("ingest: ", 0) == 0) {
      last_ingest_seq = static_cast<int>(event.seq());
      if (event.message().rfind("ingest: segmentation ", 0) == 0) ++segmentation_notes;
    }
  }
  EXPECT_GE(segmentation_notes, 2);   // the first and the last frame at least
  EXPECT_LE(segmentation_notes, 11);  // throttled: about ten per stage, not one per frame
  EXPECT_GE(iterations, 1);
  EXPECT_LT(last_ingest_seq, first_iteration_seq);  // the ingest came first

  v1::Result result;
  ASSERT_TRUE(a_->GetResult(job.id(), &result).ok());
  ASSERT_FALSE(result.ingest_json().empty());
  const nlohmann::json ingest = nlohmann::json::parse(result.ingest_json());
  EXPECT_EQ(ingest["format"], "softid-ingest/1");
  EXPECT_LT(ingest["registration"]["rms_m"].get<double>(), 0.01);
  EXPECT_EQ(nlohmann::json::parse(result.result_json())["ingest"], ingest);
  EXPECT_FALSE(result.parameters().empty());

  // Station a downloads its derived capture; every file matches the listed sha256 and the folder
  // reads as a capture with the frames the ingest reported.
  TempDir target;
  v1::Capture derived;
  const grpc::Status downloaded =
      a_->DownloadCapture(job.derived_capture_id(), target.path() / "derived", &derived);
  ASSERT_TRUE(downloaded.ok()) << downloaded.error_message();
  EXPECT_EQ(derived.id(), job.derived_capture_id());
  EXPECT_EQ(derived.format(), "softid-capture/1");
  bool has_ingest_json = false;
  for (const v1::CaptureFile& file : derived.files()) {
    std::string sha256;
    int64_t size = 0;
    ASSERT_TRUE(client::Sha256OfFile(target.path() / "derived" / file.path(), &sha256, &size))
        << file.path();
    EXPECT_EQ(sha256, file.sha256()) << file.path();
    EXPECT_EQ(size, file.size_bytes()) << file.path();
    has_ingest_json = has_ingest_json || file.path() == "ingest.json";
  }
  EXPECT_TRUE(has_ingest_json);
  Result<capture::Capture> read = capture::ReadCapture(target.path() / "derived");
  ASSERT_TRUE(read.ok()) << read.status().ToString();
  EXPECT_EQ(read->NumFrames(), ingest["time"]["frames"].get<int>());

  // Another station: NOT_FOUND, and nothing written.
  v1::Capture other;
  const grpc::Status refused =
      b_->DownloadCapture(job.derived_capture_id(), target.path() / "b", &other);
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::NOT_FOUND) << refused.error_message();
  EXPECT_FALSE(fs::exists(target.path() / "b"));
  // A folder with something in it is never written to.
  EXPECT_EQ(
      a_->DownloadCapture(job.derived_capture_id(), target.path() / "derived", &other).error_code(),
      grpc::StatusCode::FAILED_PRECONDITION);

  // Both captures are used by the job until it is deleted; then they go like any other.
  EXPECT_EQ(a_->DeleteCapture(recording.id()).error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_EQ(a_->DeleteCapture(job.derived_capture_id()).error_code(),
            grpc::StatusCode::FAILED_PRECONDITION);
  ASSERT_TRUE(a_->DeleteJob(job.id()).ok());
  EXPECT_TRUE(a_->DeleteCapture(job.derived_capture_id()).ok());
  EXPECT_TRUE(a_->DeleteCapture(recording.id()).ok());
  EXPECT_EQ(NumBlobs(), 0);
}

// A job retried after a lost worker that had finished the ingest fits the derived capture
// without ingesting again.
// A cancel while the recording is being ingested stops the ingest part way: the job ends
// CANCELLED without a derived capture and without fitting.
TEST_F(RecordingJobTest, CancelDuringTheIngestStopsIt) {
  StartServer(/*num_workers=*/1);
  const v1::Capture recording = UploadOk(*a_, Recording());
  v1::CreateJobRequest request;
  request.set_capture_id(recording.id());
  request.set_config_json(ShortFitConfig());
  v1::Job job;
  ASSERT_TRUE(a_->CreateJob(request, &job).ok());
  bool cancelled = false;
  int iterations = 0;
  const grpc::Status watched = a_->WatchJob(job.id(), 0, [&](const v1::JobEvent& event) {
    iterations += event.kind() == v1::JobEvent::ITERATION ? 1 : 0;
    if (!cancelled && event.message().rfind("ingest: segmentation", 0) == 0) {
      v1::Job ignored;
      EXPECT_TRUE(a_->CancelJob(job.id(), &ignored).ok());
      cancelled = true;
    }
  });
  ASSERT_TRUE(watched.ok()) << watched.error_message();
  ASSERT_TRUE(cancelled);
  ASSERT_TRUE(a_->GetJob(job.id(), &job).ok());
  EXPECT_EQ(job.state(), v1::CANCELLED) << job.error();
  EXPECT_TRUE(job.derived_capture_id().empty());
  EXPECT_EQ(iterations, 0);
  EXPECT_EQ(NumCaptures(*a_), 1);  // the recording alone
}

TEST_F(RecordingJobTest, RetriedJobWithADerivedCaptureSkipsTheIngest) {
  StartServer(/*num_workers=*/1);
  const v1::Capture recording = UploadOk(*a_, Recording());
  v1::Job first;
  RunJob(recording.id(), &first);
  ASSERT_EQ(first.state(), v1::SUCCEEDED) << first.error();
  StopServer();

  std::string retried_id;
  {
    Result<std::unique_ptr<store::SqliteJobStore>> jobs =
        store::SqliteJobStore::Open(data_.path() / "softid.db");
    ASSERT_TRUE(jobs.ok());
    Result<store::Job> job = (*jobs)->CreateJob(
        recording.id(), nlohmann::json::parse(ShortFitConfig()), "", "station-a");
    ASSERT_TRUE(job.ok()) << job.status().ToString();
    retried_id = job->id;
    ASSERT_TRUE((*jobs)->ClaimNextJob("lost-worker", std::chrono::seconds(60)).ok());
    ASSERT_TRUE(
        (*jobs)->SetDerivedCapture(retried_id, "lost-worker", first.derived_capture_id()).ok());
    ASSERT_TRUE((*jobs)->Close().ok());
  }
  StartServer(/*num_workers=*/1);  // recovers the RUNNING job: QUEUED again, then run
  std::vector<v1::JobEvent> events;
  ASSERT_TRUE(
      a_->WatchJob(retried_id, 0, [&](const v1::JobEvent& e) { events.push_back(e); }).ok());
  v1::Job job;
  ASSERT_TRUE(a_->GetJob(retried_id, &job).ok());
  ASSERT_EQ(job.state(), v1::SUCCEEDED) << job.error();
  EXPECT_EQ(job.derived_capture_id(), first.derived_capture_id());
  for (const v1::JobEvent& event : events) {
    EXPECT_EQ(event.message().rfind("ingest: segmentation", 0), std::string::npos)
        << event.message();
  }
  v1::Result result;
  ASSERT_TRUE(a_->GetResult(retried_id, &result).ok());
  EXPECT_FALSE(result.ingest_json().empty());
  EXPECT_EQ(NumCaptures(*a_), 2);  // the recording and the one derived capture
}

// Frames that show only the empty scene: the job FAILS naming the stage, camera and frame file.
TEST_F(RecordingJobTest, IngestFailureFailsTheJobNamingTheProblem) {
  StartServer(/*num_workers=*/1);
  const v1::Capture recording = UploadOk(*a_, EmptyRecording());
  v1::Job job;
  RunJob(recording.id(), &job);
  EXPECT_EQ(job.state(), v1::FAILED);
  const std::string frame =
      ReadJson(EmptyRecording() / "recording.json")["cameras"][0]["frames"][0]["file"];
  EXPECT_NE(job.error().find("no foreground"), std::string::npos) << job.error();
  EXPECT_NE(job.error().find("camera \"cam0\" frame 0 (" + frame + ")"), std::string::npos)
      << job.error();
  EXPECT_EQ(job.error().find(data_.path().string()), std::string::npos) << job.error();
  EXPECT_TRUE(job.derived_capture_id().empty());
  EXPECT_EQ(NumCaptures(*a_), 1);
}

// The client tells the folders apart by the description they hold, and refuses a folder that
// holds both or neither, naming it.
TEST_F(RecordingJobTest, ClientDetectsTheFolderFormat) {
  TempDir dir;
  client::CaptureFiles files;
  std::string error;
  EXPECT_FALSE(client::ReadFolderFiles(dir.path(), &files, &error));
  EXPECT_NE(error.find("neither capture.json nor recording.json"), std::string::npos) << error;
  fs::copy(Recording(), dir.path() / "both", fs::copy_options::recursive);
  std::ofstream(dir.path() / "both" / "capture.json") << "{}";
  error.clear();
  EXPECT_FALSE(client::ReadFolderFiles(dir.path() / "both", &files, &error));
  EXPECT_NE(error.find("both capture.json and recording.json"), std::string::npos) << error;
  fs::remove(dir.path() / "both" / "recording.json");
  error.clear();
  EXPECT_TRUE(client::ReadFolderFiles(dir.path() / "both", &files, &error)) << error;
  EXPECT_EQ(files.capture_json, "{}");
  EXPECT_TRUE(files.recording_json.empty());
}

// The client writes only inside the target folder, whatever paths a server names.
TEST(CaptureDownload, RefusesPathsOutsideTheFolder) {
  TempDir dir;
  for (const std::string path :
       {"../escape.png", "/etc/passwd", "a/../../b", "a//b", "./a", "a\\..\\b", ""}) {
    v1::Capture capture;
    capture.add_files()->set_path(path);
    client::CaptureDownload download(dir.path() / "target");
    std::string error;
    EXPECT_FALSE(download.Begin(capture, &error)) << path;
    EXPECT_NE(error.find("not a relative path"), std::string::npos) << error;
    EXPECT_FALSE(fs::exists(dir.path() / "target")) << path;
  }
  EXPECT_FALSE(fs::exists(dir.path().parent_path() / "escape.png"));
}

}  // namespace
}  // namespace softid::server
