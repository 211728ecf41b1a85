// The job service without a transport: real SQLite store and blob files in a temporary data
// directory, uploads fed chunk by chunk, jobs created from them. Covers what a client can send
// wrong: every mistake is INVALID_ARGUMENT naming the field or file, never INTERNAL, and no reply
// shows where the server keeps its files.
#include "server/job_service.h"

#include <gtest/gtest.h>
#include <spdlog/spdlog.h>

#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <thread>

#include "server/store/blob_store.h"
#include "server/store/sha256.h"
#include "server/store/sqlite_job_store.h"
#include "tests/core/inverse/inverse_test_util.h"
#include "tests/server/temp_dir.h"

namespace softid::server {
namespace {

namespace fs = std::filesystem;

std::string ReadBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream bytes;
  bytes << in.rdbuf();
  return bytes.str();
}

// A capture as a client sends it: capture.json's text plus files by path.
struct UploadFiles {
  nlohmann::json capture_json;
  std::map<std::string, std::string> files;  // path -> bytes
};

class JobServiceTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    spdlog::set_level(spdlog::level::warn);
    capture_ = new inverse::testing::SmallCapture(
        inverse::testing::MakeSmallCapture("torus-drop", /*duration=*/0.1, /*cameras=*/1));
  }
  static void TearDownTestSuite() {
    delete capture_;
    capture_ = nullptr;
  }

  void SetUp() override {
    ASSERT_TRUE(capture_->ok) << capture_->error;
    Result<std::unique_ptr<store::SqliteJobStore>> jobs =
        store::SqliteJobStore::Open(data_.path() / "softid.db");
    ASSERT_TRUE(jobs.ok()) << jobs.status().ToString();
    jobs_ = std::move(*jobs);
    Result<store::BlobStore> blobs = store::BlobStore::Open(data_.path());
    ASSERT_TRUE(blobs.ok()) << blobs.status().ToString();
    blobs_.emplace(std::move(*blobs));
    fs::create_directories(data_.path() / "uploads");
    fs::create_directories(data_.path() / "work");
    StartService({});
  }

  // A fresh service on the same store with `quotas`.
  void StartService(const StationQuotas& quotas) {
    JobServiceOptions options;
    options.staging_root = data_.path() / "uploads";
    options.scratch_root = data_.path() / "work";
    options.job_limits.cores = 2;
    options.quotas = quotas;
    service_ = std::make_unique<JobService>(jobs_.get(), &*blobs_, &events_, options);
  }

  int NumBlobs() const {
    Result<std::vector<std::string>> listed = blobs_->List();
    return listed.ok() ? static_cast<int>(listed->size()) : -1;
  }

  // Bytes of the small capture's files as uploaded (capture.json included).
  int64_t SmallCaptureBytes() const {
    UploadFiles files = SmallCaptureFiles();
    int64_t bytes = static_cast<int64_t>(files.capture_json.dump().size());
    for (const auto& [path, data] : files.files) bytes += static_cast<int64_t>(data.size());
    return bytes;
  }

  // The small capture's files as they lie on disk.
  UploadFiles SmallCaptureFiles() const {
    UploadFiles out;
    out.capture_json = nlohmann::json::parse(ReadBytes(capture_->directory / "capture.json"));
    out.files[out.capture_json["mesh"]] =
        ReadBytes(capture_->directory / out.capture_json["mesh"].get<std::string>());
    for (const auto& frame : out.capture_json["cameras"][0]["frames"]) {
      out.files[frame] = ReadBytes(capture_->directory / frame.get<std::string>());
    }
    return out;
  }

  // Begin, every file in one chunk, Finish and store: the first error on the way, or the capture.
  ServiceResult<store::Capture> Upload(const UploadFiles& upload,
                                       const std::string& request_id = "") {
    return UploadAs(caller_, upload, request_id);
  }
  ServiceResult<store::Capture> UploadAs(const Caller& caller, const UploadFiles& upload,
                                         const std::string& request_id = "") {
    UploadManifest manifest;
    manifest.request_id = request_id;
    manifest.capture_json = upload.capture_json.dump();
    for (const auto& [path, bytes] : upload.files) {
      manifest.files.push_back(
          {path, store::Sha256::Hex(bytes), static_cast<int64_t>(bytes.size())});
    }
    ServiceResult<std::unique_ptr<CaptureUpload>> begun = service_->BeginUpload(caller, manifest);
    if (!begun.ok()) return begun.status();
    for (const auto& [path, bytes] : upload.files) {
      if (bytes.empty()) continue;
      if (ServiceStatus added = (*begun)->AddChunk(path, 0, bytes); !added.ok()) return added;
    }
    return service_->FinishUpload(caller, **begun);
  }

  // Expects INVALID_ARGUMENT whose message contains `needle` and no server path.
  void ExpectInvalid(const ServiceStatus& status, const std::string& needle) {
    EXPECT_EQ(status.code(), ServiceCode::kInvalidArgument) << status.ToString();
    EXPECT_NE(status.message().find(needle), std::string::npos) << status.message();
    EXPECT_EQ(status.message().find(data_.path().string()), std::string::npos) << status.message();
  }

  static inverse::testing::SmallCapture* capture_;
  const Caller caller_ = Caller::Operator();
  store::testing::TempDir data_;
  std::unique_ptr<store::SqliteJobStore> jobs_;
  std::optional<store::BlobStore> blobs_;
  JobEvents events_;
  std::unique_ptr<JobService> service_;
};

inverse::testing::SmallCapture* JobServiceTest::capture_ = nullptr;

// 100,000 nested arrays in 200 KB used to overflow the parsing thread's stack and kill the server.
TEST_F(JobServiceTest, DeeplyNestedJsonIsRefusedNotCrashed) {
  const std::string deep = std::string(100000, '[') + std::string(100000, ']');
  Status status;
  std::thread rpc([&] {
    ServiceResult<store::Job> job = service_->CreateJob(caller_, "cap-0123456789abcdef", deep, "");
    status = job.ok() ? Status::Ok() : Status::InvalidArgument(job.status().message());
  });
  rpc.join();
  EXPECT_NE(status.message().find("config_json: nested deeper than"), std::string::npos)
      << status.message();

  UploadManifest manifest;
  manifest.capture_json = "{\"cameras\": " + deep + "}";
  ExpectInvalid(service_->BeginUpload(caller_, manifest).status(),
                "capture_json: nested deeper than");
}

TEST_F(JobServiceTest, NanInCaptureJsonNamesTheField) {
  UploadManifest manifest;
  std::string text = SmallCaptureFiles().capture_json.dump();
  const size_t fx = text.find("\"fx\":");
  ASSERT_NE(fx, std::string::npos);
  text.insert(fx + 5, "NaN, \"fx_was\":");
  manifest.capture_json = text;
  ExpectInvalid(service_->BeginUpload(caller_, manifest).status(), "(in cameras[0].fx)");
}

// Configs that would exhaust memory or run for days, or that do not fit the capture, are refused
// at CreateJob with the field named; an ordinary config is queued.
TEST_F(JobServiceTest, ResourceBoundsAreCheckedAtCreateJob) {
  ServiceResult<store::Capture> capture = Upload(SmallCaptureFiles());
  ASSERT_TRUE(capture.ok()) << capture.status().ToString();
  const std::string id = capture->id;
  ExpectInvalid(service_->CreateJob(caller_, id, R"({"cells": 300})", "").status(), "cells = 300");
  ExpectInvalid(service_->CreateJob(caller_, id, R"({"cells": 100000})", "").status(),
                "cells = 100000");
  ExpectInvalid(service_->CreateJob(caller_, id, R"({"substeps": 20000})", "").status(),
                "substeps = 20000");
  ExpectInvalid(service_->CreateJob(caller_, id, R"({"cell_size": 1e-9})", "").status(),
                "cell_size = 1e-09");
  ExpectInvalid(service_->CreateJob(caller_, id, R"({"max_iterations": 1000000})", "").status(),
                "max_iterations = 1000000: the job could run for about");
  const int frames = capture_->capture.NumFrames();
  ExpectInvalid(
      service_->CreateJob(caller_, id, nlohmann::json{{"frames", {{"last", frames}}}}.dump(), "")
          .status(),
      "frames.last = " + std::to_string(frames) + ": the capture has " + std::to_string(frames) +
          " frames");
  ExpectInvalid(
      service_
          ->CreateJob(caller_, id, nlohmann::json{{"frames", {{"first", frames + 5}}}}.dump(), "")
          .status(),
      "frames.first");
  const ServiceResult<store::Job> ok = service_->CreateJob(caller_, id, R"({"cells": 12})", "");
  ASSERT_TRUE(ok.ok()) << ok.status().ToString();
  EXPECT_EQ(ok->state, store::JobState::kQueued);
}

TEST_F(JobServiceTest, RequestIdIsBounded) {
  ServiceResult<store::Capture> capture = Upload(SmallCaptureFiles());
  ASSERT_TRUE(capture.ok()) << capture.status().ToString();
  ExpectInvalid(service_->CreateJob(caller_, capture->id, "{}", std::string(129, 'r')).status(),
                "request_id");
  ExpectInvalid(service_->CreateJob(caller_, capture->id, "{}", "a\nb").status(),
                "control characters");
  EXPECT_TRUE(service_->CreateJob(caller_, capture->id, "{}", std::string(128, 'r')).ok());
  ExpectInvalid(Upload(SmallCaptureFiles(), std::string(200, 'x')).status(), "request_id");
}

// Mistakes in the file list are the client's: INVALID_ARGUMENT naming the file.
TEST_F(JobServiceTest, ManifestMistakesAreInvalidArgumentNamingTheFile) {
  {  // An empty frame in a folder that no other file creates.
    UploadFiles upload = SmallCaptureFiles();
    upload.capture_json["cameras"][0]["frames"][0] = "new/empty.png";
    upload.files["new/empty.png"] = "";
    ExpectInvalid(Upload(upload).status(), "new/empty.png");
  }
  {  // A 304-character file name.
    UploadFiles upload = SmallCaptureFiles();
    const std::string name = std::string(300, 'n') + ".png";
    upload.files[name] = upload.files.begin()->second;
    upload.capture_json["cameras"][0]["frames"][0] = name;
    ExpectInvalid(Upload(upload).status(), "at most 255 bytes");
  }
  {  // A file and a folder of the same name.
    UploadFiles upload = SmallCaptureFiles();
    upload.files["cam0"] = "x";
    ExpectInvalid(Upload(upload).status(), "lies in a folder named like the file \"cam0\"");
  }
  {  // Declared sizes whose sum overflows 64 bits: refused by the per-file limit, never summed.
    UploadManifest manifest;
    manifest.capture_json = SmallCaptureFiles().capture_json.dump();
    for (const auto& [path, bytes] : SmallCaptureFiles().files) {
      manifest.files.push_back({path, store::Sha256::Hex(bytes), int64_t{1} << 62});
    }
    ExpectInvalid(service_->BeginUpload(caller_, manifest).status(), "exceeds the limit");
  }
  {  // A control character in a name.
    UploadFiles upload = SmallCaptureFiles();
    upload.files["cam0/a\nb.png"] = "x";
    ExpectInvalid(Upload(upload).status(), "control characters");
  }
}

// A glTF mesh whose buffer points outside the upload is refused with one message whether the
// target exists or not, and nothing of that file is read.
TEST_F(JobServiceTest, MeshReferringOutsideTheUploadIsRefused) {
  const fs::path outside = data_.path() / "outside.bin";
  {
    const float xyz[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    std::ofstream out(outside, std::ios::binary);
    out.write(reinterpret_cast<const char*>(xyz), sizeof(xyz));
  }
  const auto gltf = [](const std::string& uri) {
    return nlohmann::json{{"asset", {{"version", "2.0"}}},
                          {"buffers", {{{"uri", uri}, {"byteLength", 36}}}},
                          {"bufferViews", {{{"buffer", 0}, {"byteOffset", 0}, {"byteLength", 36}}}},
                          {"accessors",
                           {{{"bufferView", 0},
                             {"componentType", 5126},
                             {"count", 3},
                             {"type", "VEC3"},
                             {"min", {0, 0, 0}},
                             {"max", {1, 1, 0}}}}},
                          {"meshes", {{{"primitives", {{{"attributes", {{"POSITION", 0}}}}}}}}},
                          {"nodes", {{{"mesh", 0}}}},
                          {"scenes", {{{"nodes", {0}}}}},
                          {"scene", 0}}
        .dump();
  };
  std::string messages[2];
  const std::string uris[2] = {"../../../../../../../.." + outside.string(),
                               "../../../../../../../.." + outside.string() + ".missing"};
  for (int i = 0; i < 2; ++i) {
    UploadFiles upload = SmallCaptureFiles();
    upload.files.erase(upload.capture_json["mesh"].get<std::string>());
    upload.capture_json["mesh"] = "object.gltf";
    upload.files["object.gltf"] = gltf(uris[i]);
    const ServiceStatus status = Upload(upload).status();
    ExpectInvalid(status, "outside its folder");
    messages[i] = status.message();
  }
  EXPECT_EQ(messages[0], messages[1]);
}

// A station sees, watches, cancels and deletes only its own captures and jobs; another station's
// answer NOT_FOUND like missing ones; an admin sees everything.
TEST_F(JobServiceTest, StationsSeeOnlyTheirOwnCapturesAndJobs) {
  const Caller a{"lab-a", false}, b{"lab-b", false}, admin{"ops", true};
  ServiceResult<store::Capture> capture = UploadAs(a, SmallCaptureFiles(), "a-upload");
  ASSERT_TRUE(capture.ok()) << capture.status().ToString();
  EXPECT_EQ(capture->owner, "lab-a");
  ServiceResult<store::Job> job = service_->CreateJob(a, capture->id, R"({"cells": 8})", "a-job");
  ASSERT_TRUE(job.ok()) << job.status().ToString();
  EXPECT_EQ(job->owner, "lab-a");

  const auto not_found = [](const ServiceStatus& status) {
    return status.code() == ServiceCode::kNotFound;
  };
  EXPECT_TRUE(not_found(service_->GetJob(b, job->id).status()));
  EXPECT_TRUE(not_found(service_->CancelJob(b, job->id).status()));
  EXPECT_TRUE(not_found(service_->DeleteJob(b, job->id)));
  EXPECT_TRUE(not_found(service_->GetResult(b, job->id).status()));
  EXPECT_TRUE(not_found(
      service_->WatchJob(b, job->id, 0, [](const auto&, const auto&) { return true; }, {})));
  EXPECT_TRUE(not_found(service_->CreateJob(b, capture->id, "{}", "").status()));
  // The message is the one a missing job gets: nothing tells B the job exists.
  EXPECT_EQ(service_->GetJob(b, job->id).status().message(), "job " + job->id + " not found");
  EXPECT_EQ(service_->GetJob(b, "job-0123456789abcdef").status().message(),
            "job job-0123456789abcdef not found");

  ServiceResult<store::JobPage> b_jobs = service_->ListJobs(b, {});
  ASSERT_TRUE(b_jobs.ok());
  EXPECT_TRUE(b_jobs->jobs.empty());
  ServiceResult<store::JobPage> a_jobs = service_->ListJobs(a, {});
  ASSERT_TRUE(a_jobs.ok());
  ASSERT_EQ(a_jobs->jobs.size(), 1u);
  EXPECT_EQ(a_jobs->jobs[0].id, job->id);

  ServiceResult<store::Capture> b_capture = UploadAs(b, SmallCaptureFiles());
  ASSERT_TRUE(b_capture.ok());
  // Request ids are per station: B's "a-job" is a job of its own, and A's is untouched.
  ServiceResult<store::Job> b_job =
      service_->CreateJob(b, b_capture->id, R"({"cells": 8})", "a-job");
  ASSERT_TRUE(b_job.ok()) << b_job.status().ToString();
  EXPECT_NE(b_job->id, job->id);
  EXPECT_EQ(b_job->owner, b.station);
  ServiceResult<store::JobPage> all = service_->ListJobs(admin, {});
  ASSERT_TRUE(all.ok());
  EXPECT_EQ(all->jobs.size(), 2u);
  EXPECT_TRUE(service_->GetJob(admin, job->id).ok());
  EXPECT_TRUE(service_->CancelJob(a, job->id).ok());
  EXPECT_TRUE(service_->DeleteJob(a, job->id).ok());
}

// Each station's quotas hold and are refused RESOURCE_EXHAUSTED naming the station: jobs QUEUED
// (a repeated request id still gets its job), bytes stored (room comes back when a capture is
// deleted) and uploads in progress; other stations are not affected.
TEST_F(JobServiceTest, StationQuotasHold) {
  StationQuotas quotas;
  quotas.max_queued_jobs = 2;
  quotas.max_stored_bytes = SmallCaptureBytes() + 10;
  quotas.max_concurrent_uploads = 1;
  StartService(quotas);
  const Caller a{"lab-a", false}, b{"lab-b", false};
  ServiceResult<store::Capture> capture = UploadAs(a, SmallCaptureFiles());
  ASSERT_TRUE(capture.ok()) << capture.status().ToString();

  ASSERT_TRUE(service_->CreateJob(a, capture->id, R"({"cells": 8})", "first").ok());
  ASSERT_TRUE(service_->CreateJob(a, capture->id, R"({"cells": 8})", "").ok());
  const ServiceStatus third = service_->CreateJob(a, capture->id, R"({"cells": 8})", "").status();
  EXPECT_EQ(third.code(), ServiceCode::kResourceExhausted);
  EXPECT_NE(third.message().find("station \"lab-a\" has 2 jobs QUEUED"), std::string::npos)
      << third.message();
  EXPECT_TRUE(service_->CreateJob(a, capture->id, R"({"cells": 8})", "first").ok());

  // Bytes: a second copy does not fit A's quota; B has its own.
  const ServiceStatus full = UploadAs(a, SmallCaptureFiles()).status();
  EXPECT_EQ(full.code(), ServiceCode::kResourceExhausted);
  EXPECT_NE(full.message().find("exceed its quota"), std::string::npos) << full.message();
  ServiceResult<store::Capture> b_capture = UploadAs(b, SmallCaptureFiles());
  ASSERT_TRUE(b_capture.ok()) << b_capture.status().ToString();

  // Uploads in progress: B's second at once is refused while its first is open; A is not.
  UploadManifest manifest;
  const UploadFiles files = SmallCaptureFiles();
  manifest.capture_json = files.capture_json.dump();
  for (const auto& [path, bytes] : files.files) {
    manifest.files.push_back({path, store::Sha256::Hex(bytes), static_cast<int64_t>(bytes.size())});
  }
  ASSERT_TRUE(service_->DeleteCapture(b, b_capture->id).ok());
  ServiceResult<std::unique_ptr<CaptureUpload>> open = service_->BeginUpload(b, manifest);
  ASSERT_TRUE(open.ok()) << open.status().ToString();
  EXPECT_EQ(service_->BeginUpload(b, manifest).status().code(), ServiceCode::kResourceExhausted);
  open->reset();
  EXPECT_TRUE(service_->BeginUpload(b, manifest).ok());
}

// A capture is deleted only when no job uses it, only by its station, and its files go unless
// another capture has them.
TEST_F(JobServiceTest, DeleteCaptureRemovesItsUnsharedFiles) {
  const Caller a{"lab-a", false}, b{"lab-b", false};
  ServiceResult<store::Capture> first = UploadAs(a, SmallCaptureFiles());
  ASSERT_TRUE(first.ok());
  const int blobs = NumBlobs();
  ServiceResult<store::Capture> copy = UploadAs(a, SmallCaptureFiles());  // same files
  ASSERT_TRUE(copy.ok());
  EXPECT_EQ(NumBlobs(), blobs);
  ServiceResult<store::Job> job = service_->CreateJob(a, first->id, R"({"cells": 8})", "");
  ASSERT_TRUE(job.ok());

  EXPECT_EQ(service_->DeleteCapture(b, first->id).code(), ServiceCode::kNotFound);
  const ServiceStatus used = service_->DeleteCapture(a, first->id);
  EXPECT_EQ(used.code(), ServiceCode::kFailedPrecondition);
  EXPECT_NE(used.message().find(job->id), std::string::npos) << used.message();

  ASSERT_TRUE(service_->DeleteCapture(a, copy->id).ok());
  EXPECT_EQ(NumBlobs(), blobs);  // still listed by the first capture
  ASSERT_TRUE(service_->DeleteJob(a, job->id).ok());
  ASSERT_TRUE(service_->DeleteCapture(a, first->id).ok());
  EXPECT_EQ(NumBlobs(), 0);
  EXPECT_EQ(service_->DeleteCapture(a, first->id).code(), ServiceCode::kNotFound);
}

// Retention deletes ended jobs and then unused captures older than the age, with their files,
// and keeps what is younger.
TEST_F(JobServiceTest, RetentionRemovesEndedJobsAndUnusedCapturesOlderThanTheAge) {
  ServiceResult<store::Capture> used = Upload(SmallCaptureFiles());
  ServiceResult<store::Capture> unused = Upload(SmallCaptureFiles());
  ASSERT_TRUE(used.ok() && unused.ok());
  ServiceResult<store::Job> job = service_->CreateJob(caller_, used->id, R"({"cells": 8})", "");
  ASSERT_TRUE(job.ok());
  ASSERT_TRUE(service_->CancelJob(caller_, job->id).ok());  // QUEUED: CANCELLED at once
  ServiceResult<store::Job> queued = service_->CreateJob(caller_, used->id, R"({"cells": 8})", "");
  ASSERT_TRUE(queued.ok());

  ServiceResult<std::pair<int, int>> young = service_->RemoveOlderThan(std::chrono::hours(1));
  ASSERT_TRUE(young.ok());
  EXPECT_EQ(*young, std::make_pair(0, 0));
  std::this_thread::sleep_for(std::chrono::milliseconds(5));
  ServiceResult<std::pair<int, int>> old = service_->RemoveOlderThan(std::chrono::seconds(0));
  ASSERT_TRUE(old.ok());
  EXPECT_EQ(*old, std::make_pair(1, 1));  // the QUEUED job keeps its capture
  EXPECT_EQ(service_->GetJob(caller_, job->id).status().code(), ServiceCode::kNotFound);
  EXPECT_TRUE(service_->GetJob(caller_, queued->id).ok());
  EXPECT_GT(NumBlobs(), 0);
}

// A station lists only its own captures, each with its job count; an admin lists all.
// DownloadCapture streams the manifest, then every file in order in chunks of at most 1 MiB that
// reassemble to the stored bytes (a 2.5 MiB file in three, an empty file as one empty chunk);
// another station's capture is NotFound and nothing is sent.
TEST_F(JobServiceTest, DownloadCaptureStreamsEveryFileInBoundedChunks) {
  std::string big(5 << 19, '\0');
  for (size_t i = 0; i < big.size(); ++i) big[i] = static_cast<char>((i * 7919) >> 5);
  const std::map<std::string, std::string> files = {
      {"capture.json", "{}"}, {"frames/big.bin", big}, {"frames/empty.png", ""}};
  std::vector<store::ManifestEntry> manifest;
  for (const auto& [path, bytes] : files) {
    Result<std::string> put = blobs_->Put(bytes);
    ASSERT_TRUE(put.ok()) << put.status().ToString();
    manifest.push_back({path, *put, static_cast<int64_t>(bytes.size())});
  }
  Result<store::Capture> stored = jobs_->CreateCapture(manifest, "", "lab-a");
  ASSERT_TRUE(stored.ok()) << stored.status().ToString();

  std::vector<store::ManifestEntry> sent_manifest;
  std::map<std::string, std::string> received;
  std::map<std::string, int> chunks;
  const ServiceStatus done = service_->DownloadCapture(
      Caller{"lab-a", false}, stored->id,
      [&](const store::Capture& capture) {
        sent_manifest = capture.manifest;
        return true;
      },
      [&](const std::string& path, int64_t offset, std::string_view data) {
        EXPECT_LE(data.size(), size_t{1} << 20);
        EXPECT_EQ(offset, static_cast<int64_t>(received[path].size())) << path;
        received[path].append(data);
        ++chunks[path];
        return true;
      });
  ASSERT_TRUE(done.ok()) << done.ToString();
  EXPECT_EQ(sent_manifest, manifest);
  EXPECT_EQ(received, files);
  EXPECT_EQ(chunks["frames/big.bin"], 3);
  EXPECT_EQ(chunks["frames/empty.png"], 1);

  bool sent = false;
  const ServiceStatus refused = service_->DownloadCapture(
      Caller{"lab-b", false}, stored->id, [&](const store::Capture&) { return sent = true; },
      [&](const std::string&, int64_t, std::string_view) { return sent = true; });
  EXPECT_EQ(refused.code(), ServiceCode::kNotFound);
  EXPECT_FALSE(sent);
}

TEST_F(JobServiceTest, CapturesAreListedPerStation) {
  const Caller lab1{"lab-1", false}, lab2{"lab-2", false}, admin{"operator", true};
  UploadFiles files = SmallCaptureFiles();
  ServiceResult<store::Capture> first = UploadAs(lab1, files);
  ASSERT_TRUE(first.ok()) << first.status().ToString();
  files.files["extra.bin"] = "another capture, other bytes";
  ServiceResult<store::Capture> second = UploadAs(lab2, files);
  ASSERT_TRUE(second.ok()) << second.status().ToString();
  ASSERT_TRUE(service_->CreateJob(lab1, first->id, R"({"cells": 12})", "").ok());

  ServiceResult<store::CapturePage> mine = service_->ListCaptures(lab1, {});
  ASSERT_TRUE(mine.ok()) << mine.status().ToString();
  ASSERT_EQ(mine->captures.size(), 1u);
  EXPECT_EQ(mine->captures[0].capture.id, first->id);
  EXPECT_EQ(mine->captures[0].num_jobs, 1);
  ServiceResult<store::CapturePage> theirs = service_->ListCaptures(lab2, {});
  ASSERT_TRUE(theirs.ok());
  ASSERT_EQ(theirs->captures.size(), 1u);
  EXPECT_EQ(theirs->captures[0].capture.id, second->id);
  EXPECT_EQ(theirs->captures[0].num_jobs, 0);
  ServiceResult<store::CapturePage> all = service_->ListCaptures(admin, {});
  ASSERT_TRUE(all.ok());
  EXPECT_EQ(all->captures.size(), 2u);
}

}  // namespace
}  // namespace softid::server
