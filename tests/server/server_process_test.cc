// The real softid-server binary in its own process, driven over loopback with the client library:
// what only a separate process shows (kill -9 and restart, SIGTERM and its exit status, the
// command line) plus the API's answers to bad input, a full queue and repeated request ids.
#include "tests/server/server_process.h"

#include <fcntl.h>
#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <spdlog/spdlog.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <latch>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <random>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "client/capture_files.h"
#include "client/reconstruction_client.h"
#include "server/store/postgres_connection.h"
#include "tests/core/inverse/inverse_test_util.h"
#include "tests/server/postgres_test_server.h"
#include "tests/server/temp_dir.h"

namespace softid::server {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using client::ReconstructionClient;
using store::testing::TempDir;
using testing::FitConfig;
using testing::ReadFile;
using testing::ServerProcess;
using testing::StartsConfig;
using testing::StartTaskWorkers;

// Listening TCP sockets of process `pid`: its socket inodes matched against the kernel's tables.
int CountListeningSockets(pid_t pid) {
  std::set<std::string> inodes;
  for (const auto& fd : fs::directory_iterator("/proc/" + std::to_string(pid) + "/fd")) {
    std::error_code error;
    const std::string target = fs::read_symlink(fd.path(), error).string();
    if (!error && target.rfind("socket:[", 0) == 0) {
      inodes.insert(target.substr(8, target.size() - 9));
    }
  }
  int listening = 0;
  for (const char* table : {"/proc/net/tcp", "/proc/net/tcp6"}) {
    std::ifstream in(table);
    std::string line;
    std::getline(in, line);  // header
    while (std::getline(in, line)) {
      std::istringstream fields(line);
      std::string sl, local, remote, state, queues, timer, retransmits, uid, timeout, inode;
      fields >> sl >> local >> remote >> state >> queues >> timer >> retransmits >> uid >>
          timeout >> inode;
      if (state == "0A" && inodes.contains(inode)) ++listening;  // 0A: TCP_LISTEN
    }
  }
  return listening;
}

class ServerProcessTest : public ::testing::Test {
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

  // Starts a server on the test's data directory and waits until it serves.
  std::unique_ptr<ServerProcess> Start(const ServerProcess::Flags& flags) {
    auto server = std::make_unique<ServerProcess>(data_dir(), log_file(), flags);
    if (!server->WaitUntilServing()) return nullptr;
    return server;
  }

  // kill -9, then a new server on the same data directory, as after a crash (null when the new
  // one does not serve).
  std::unique_ptr<ServerProcess> KillAndRestart(std::unique_ptr<ServerProcess> server,
                                                const ServerProcess::Flags& flags) {
    server->Signal(SIGKILL);
    EXPECT_EQ(server->Wait(std::chrono::seconds(10)), 128 + SIGKILL);
    server.reset();
    return Start(flags);
  }

  // SIGTERM, then the exit status must be 0 within a few seconds.
  void StopCleanly(ServerProcess& server) {
    server.Signal(SIGTERM);
    const std::optional<int> status = server.Wait(std::chrono::seconds(20));
    ASSERT_TRUE(status.has_value()) << "no exit 20 s after SIGTERM; log:\n" << ReadFile(log_file());
    EXPECT_EQ(*status, 0) << ReadFile(log_file());
  }

  fs::path data_dir() const { return root_.path() / "data"; }
  fs::path log_file() const { return root_.path() / "server.log"; }

  static client::CaptureFiles CaptureFiles() {
    client::CaptureFiles files;
    std::string error;
    EXPECT_TRUE(client::ReadCaptureFiles(capture_->directory, &files, &error)) << error;
    return files;
  }

  static std::string Upload(ReconstructionClient& client, const std::string& request_id = "") {
    v1::Capture capture;
    const grpc::Status status = client.UploadCapture(CaptureFiles(), request_id, &capture);
    EXPECT_TRUE(status.ok()) << status.error_message();
    return capture.id();
  }

  static grpc::Status Create(ReconstructionClient& client, const std::string& capture_id,
                             const std::string& config, const std::string& request_id,
                             v1::Job* job) {
    v1::CreateJobRequest request;
    request.set_capture_id(capture_id);
    request.set_config_json(config);
    request.set_request_id(request_id);
    return client.CreateJob(request, job);
  }

  static v1::Job CreateOk(ReconstructionClient& client, const std::string& capture_id,
                          const std::string& config, const std::string& request_id = "") {
    v1::Job job;
    const grpc::Status status = Create(client, capture_id, config, request_id, &job);
    EXPECT_TRUE(status.ok()) << status.error_message();
    return job;
  }

  // Reads the job's event stream until an event satisfies `until`, which it returns with every
  // event before it.
  static std::vector<v1::JobEvent> WatchUntil(
      ServerProcess& server, const std::string& job_id,
      const std::function<bool(const v1::JobEvent&)>& until) {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(120));
    v1::WatchJobRequest request;
    request.set_job_id(job_id);
    auto stub = server.Stub();
    auto reader = stub->WatchJob(&context, request);
    std::vector<v1::JobEvent> events;
    v1::JobEvent event;
    while (reader->Read(&event)) {
      events.push_back(event);
      if (until(event)) break;
    }
    context.TryCancel();
    (void)reader->Finish();
    return events;
  }

  // Until the first ITERATION event: the fit is running.
  static std::vector<v1::JobEvent> WatchUntilFirstIteration(ServerProcess& server,
                                                            const std::string& job_id) {
    return WatchUntil(server, job_id,
                      [](const v1::JobEvent& e) { return e.kind() == v1::JobEvent::ITERATION; });
  }

  static std::vector<v1::JobEvent> WatchToEnd(ReconstructionClient& client,
                                              const std::string& job_id) {
    std::vector<v1::JobEvent> events;
    const grpc::Status status =
        client.WatchJob(job_id, 0, [&](const v1::JobEvent& e) { events.push_back(e); });
    EXPECT_TRUE(status.ok()) << status.error_message();
    return events;
  }

  static v1::Job GetJob(ReconstructionClient& client, const std::string& job_id) {
    v1::Job job;
    const grpc::Status status = client.GetJob(job_id, &job);
    EXPECT_TRUE(status.ok()) << status.error_message();
    return job;
  }

  static int CountBlobs(const fs::path& data) {
    int n = 0;
    for (const auto& entry : fs::recursive_directory_iterator(data / "blobs")) {
      if (entry.is_regular_file() && entry.path().parent_path().filename() != "tmp") ++n;
    }
    return n;
  }

  static inverse::testing::SmallCapture* capture_;
  TempDir root_;
};

inverse::testing::SmallCapture* ServerProcessTest::capture_ = nullptr;

// kill -9 while a job runs: the restarted server requeues it, the job then completes, and its
// history still holds every event of the lost attempt, in order, with nothing renumbered.
TEST_F(ServerProcessTest, KillNineWhileRunningThenRestartCompletesTheJob) {
  std::unique_ptr<ServerProcess> server = Start({.workers = 1});
  ASSERT_NE(server, nullptr);
  std::string job_id;
  {
    ReconstructionClient client = server->Client();
    job_id = CreateOk(client, Upload(client), FitConfig(/*max_iterations=*/3)).id();
  }
  const std::vector<v1::JobEvent> before = WatchUntilFirstIteration(*server, job_id);
  ASSERT_FALSE(before.empty());
  ASSERT_EQ(before.back().kind(), v1::JobEvent::ITERATION);

  server = KillAndRestart(std::move(server), {.workers = 1});
  ASSERT_NE(server, nullptr);
  ReconstructionClient client = server->Client();
  const std::vector<v1::JobEvent> history = WatchToEnd(client, job_id);
  ASSERT_GT(history.size(), before.size());
  EXPECT_EQ(history.back().state(), v1::SUCCEEDED);
  for (size_t i = 0; i < history.size(); ++i) {
    EXPECT_EQ(history[i].seq(), static_cast<int64_t>(i + 1)) << "history has a gap";
  }
  for (size_t i = 0; i < before.size(); ++i) {
    EXPECT_EQ(history[i].kind(), before[i].kind()) << "event " << i;
    EXPECT_EQ(history[i].iteration(), before[i].iteration()) << "event " << i;
    EXPECT_EQ(history[i].attempt(), before[i].attempt()) << "event " << i;
    EXPECT_LE(history[i].attempt(), 1) << "event " << i;  // 0 before the first claim
    EXPECT_EQ(history[i].message(), before[i].message()) << "event " << i;
  }
  EXPECT_DOUBLE_EQ(history[before.size() - 1].cost(), before.back().cost());
  const v1::JobEvent& requeued = history[before.size()];
  EXPECT_EQ(requeued.state(), v1::QUEUED);
  EXPECT_NE(requeued.message().find("requeued: its worker was lost"), std::string::npos)
      << requeued.message();
  bool second_attempt_iteration = false;
  for (const v1::JobEvent& e : history) {
    if (e.kind() == v1::JobEvent::ITERATION && e.attempt() == 2) second_attempt_iteration = true;
  }
  EXPECT_TRUE(second_attempt_iteration);
  EXPECT_EQ(GetJob(client, job_id).attempts(), 2);
  v1::Result result;
  ASSERT_TRUE(client.GetResult(job_id, &result).ok());
  EXPECT_TRUE(nlohmann::json::parse(result.result_json())["parameters"].contains("youngs_modulus"));
  StopCleanly(*server);
}

// kill -9 after the first of three starts finished (one thread: they run in turn): the restarted
// server resumes from the job's checkpoint, runs only the other two, and the result is the one an
// uninterrupted run of the same job computes.
TEST_F(ServerProcessTest, KillNineAfterAFinishedStartResumesFromTheCheckpoint) {
  const nlohmann::json config = nlohmann::json::parse(
      StartsConfig(capture_->truth.youngs_modulus, /*starts=*/3, /*max_iterations=*/4));
  std::unique_ptr<ServerProcess> server = Start({.workers = 1});
  ASSERT_NE(server, nullptr);
  std::string job_id, capture_id;
  {
    ReconstructionClient client = server->Client();
    capture_id = Upload(client);
    job_id = CreateOk(client, capture_id, config.dump()).id();
  }
  // The second start's first iteration: the first start has finished and been saved.
  const std::vector<v1::JobEvent> before = WatchUntil(*server, job_id, [](const v1::JobEvent& e) {
    return e.kind() == v1::JobEvent::ITERATION && e.start() == 1;
  });
  ASSERT_EQ(before.back().start(), 1);

  server = KillAndRestart(std::move(server), {.workers = 1});
  ASSERT_NE(server, nullptr);
  ReconstructionClient client = server->Client();
  const std::vector<v1::JobEvent> history = WatchToEnd(client, job_id);
  ASSERT_EQ(history.back().state(), v1::SUCCEEDED);
  bool noted = false;
  for (const v1::JobEvent& e : history) {
    if (e.attempt() != 2) continue;
    EXPECT_FALSE(e.kind() == v1::JobEvent::ITERATION && e.start() == 0) << "start 0 ran again";
    noted |= e.message().find("resumed from a checkpoint: 1 of 3 starts") != std::string::npos;
  }
  EXPECT_TRUE(noted);
  v1::Result resumed;
  ASSERT_TRUE(client.GetResult(job_id, &resumed).ok());
  const nlohmann::json resumed_json = nlohmann::json::parse(resumed.result_json());
  EXPECT_EQ(resumed_json["resumed"]["finished_starts"], nlohmann::json::array({0}));

  const std::string again = CreateOk(client, capture_id, config.dump()).id();
  ASSERT_EQ(WatchToEnd(client, again).back().state(), v1::SUCCEEDED);
  v1::Result uninterrupted;
  ASSERT_TRUE(client.GetResult(again, &uninterrupted).ok());
  const nlohmann::json uninterrupted_json = nlohmann::json::parse(uninterrupted.result_json());
  EXPECT_FALSE(uninterrupted_json.contains("resumed"));
  EXPECT_EQ(resumed_json["parameters"], uninterrupted_json["parameters"]);
  ASSERT_EQ(resumed_json["starts"].size(), 3u);
  for (int s = 0; s < 3; ++s) {
    EXPECT_EQ(resumed_json["starts"][s]["parameters"],
              uninterrupted_json["starts"][s]["parameters"])
        << "start " << s;
    EXPECT_EQ(resumed_json["starts"][s]["iterations"],
              uninterrupted_json["starts"][s]["iterations"]);
  }
  StopCleanly(*server);
}

// --fan-out-starts: a job's four starts run as tasks on both workers of the process, and the
// result is the one a server without fan-out computes for the same job, start for start.
TEST_F(ServerProcessTest, FannedOutStartsRunOnEveryWorkerAndMatchTheOneWorkerResult) {
  const std::string config = StartsConfig(capture_->truth.youngs_modulus, 4, 6);
  std::string capture_id;
  nlohmann::json fanned;
  {
    std::unique_ptr<ServerProcess> server = Start({.workers = 2, .extra = {"--fan-out-starts"}});
    ASSERT_NE(server, nullptr);
    ReconstructionClient client = server->Client();
    capture_id = Upload(client);
    const std::string job = CreateOk(client, capture_id, config).id();
    ASSERT_EQ(WatchToEnd(client, job).back().state(), v1::SUCCEEDED) << ReadFile(log_file());
    v1::Result result;
    ASSERT_TRUE(client.GetResult(job, &result).ok());
    fanned = nlohmann::json::parse(result.result_json());
    const std::map<std::string, int> workers = StartTaskWorkers(log_file(), job);
    EXPECT_EQ(workers.size(), 2u) << ReadFile(log_file());
    int tasks = 0;
    for (const auto& [worker, count] : workers) tasks += count;
    EXPECT_EQ(tasks, 4);
    StopCleanly(*server);
  }
  std::unique_ptr<ServerProcess> server = Start({.workers = 1});
  ASSERT_NE(server, nullptr);
  ReconstructionClient client = server->Client();
  const std::string job = CreateOk(client, capture_id, config).id();
  ASSERT_EQ(WatchToEnd(client, job).back().state(), v1::SUCCEEDED);
  v1::Result result;
  ASSERT_TRUE(client.GetResult(job, &result).ok());
  const nlohmann::json alone = nlohmann::json::parse(result.result_json());
  EXPECT_TRUE(StartTaskWorkers(log_file(), job).empty());
  EXPECT_EQ(fanned["parameters"], alone["parameters"]);
  EXPECT_EQ(fanned["best_start"], alone["best_start"]);
  ASSERT_EQ(fanned["starts"].size(), 4u);
  for (int s = 0; s < 4; ++s) {
    EXPECT_EQ(fanned["starts"][s]["parameters"], alone["starts"][s]["parameters"]) << s;
    EXPECT_EQ(fanned["starts"][s]["cost"], alone["starts"][s]["cost"]) << s;
  }
  StopCleanly(*server);
}

// --fan-out-starts with "diagnose": true: the diagnosis' refits run as tasks on both workers, and
// the diagnosis is the one a server without fan-out makes for the same job. The base model is
// told a wrong sideways launch, so the motion misfits and candidates are refitted.
TEST_F(ServerProcessTest, FannedOutDiagnosisRefitsRunOnEveryWorkerAndMatchTheOneWorkerDiagnosis) {
  nlohmann::json config = nlohmann::json::parse(FitConfig(/*max_iterations=*/6));
  config["fixed"]["initial_velocity"] = {0.3, 0.0, 0.0};
  config["diagnose"] = true;
  std::string capture_id;
  nlohmann::json fanned;
  {
    std::unique_ptr<ServerProcess> server = Start({.workers = 2, .extra = {"--fan-out-starts"}});
    ASSERT_NE(server, nullptr);
    ReconstructionClient client = server->Client();
    capture_id = Upload(client);
    const std::string job = CreateOk(client, capture_id, config.dump()).id();
    ASSERT_EQ(WatchToEnd(client, job).back().state(), v1::SUCCEEDED) << ReadFile(log_file());
    v1::Result result;
    ASSERT_TRUE(client.GetResult(job, &result).ok());
    fanned = nlohmann::json::parse(result.result_json());
    std::map<std::string, int> workers;
    const std::regex line("job " + job +
                          " refit task [0-9]+ \\(diagnosis [^)]*\\): RUNNING on ([^ ]+) ");
    std::istringstream log(ReadFile(log_file()));
    for (std::string text; std::getline(log, text);) {
      std::smatch match;
      if (std::regex_search(text, match, line)) ++workers[match[1].str()];
    }
    EXPECT_EQ(workers.size(), 2u) << ReadFile(log_file());
    StopCleanly(*server);
  }
  ASSERT_TRUE(fanned.contains("diagnosis"));
  ASSERT_FALSE(fanned["diagnosis"].contains("error")) << fanned["diagnosis"].dump(1);
  EXPECT_GE(fanned["diagnosis"].value("candidates", nlohmann::json::array()).size(), 2u)
      << fanned["diagnosis"].dump(1);
  // The plots are named inside the job's report, not where its worker drew them.
  EXPECT_EQ(fanned["diagnosis"]["plots"][0], "diagnosis/residual_per_frame.png");
  std::unique_ptr<ServerProcess> server = Start({.workers = 1});
  ASSERT_NE(server, nullptr);
  ReconstructionClient client = server->Client();
  const std::string job = CreateOk(client, capture_id, config.dump()).id();
  ASSERT_EQ(WatchToEnd(client, job).back().state(), v1::SUCCEEDED);
  v1::Result result;
  ASSERT_TRUE(client.GetResult(job, &result).ok());
  const nlohmann::json alone = nlohmann::json::parse(result.result_json());
  EXPECT_EQ(ReadFile(log_file()).find("job " + job + " refit task"), std::string::npos);
  EXPECT_EQ(inverse::testing::WithoutTiming(fanned["diagnosis"]),
            inverse::testing::WithoutTiming(alone["diagnosis"]));
  EXPECT_EQ(fanned["parameters"], alone["parameters"]);
  StopCleanly(*server);
}

// SIGTERM while a job runs: exit status 0, the job QUEUED at once (nothing left RUNNING, so the
// next start recovers nothing), and the interrupted attempt is not held against max_attempts:
// with --max-attempts 1 the job still runs to SUCCEEDED afterwards.
TEST_F(ServerProcessTest, SigtermRequeuesTheRunningJobWithoutUsingAnAttempt) {
  std::string job_id;
  {
    std::unique_ptr<ServerProcess> server = Start({.workers = 1, .max_attempts = 1});
    ASSERT_NE(server, nullptr);
    ReconstructionClient client = server->Client();
    job_id = CreateOk(client, Upload(client), FitConfig(/*max_iterations=*/3)).id();
    ASSERT_FALSE(WatchUntilFirstIteration(*server, job_id).empty());
    StopCleanly(*server);
  }
  {
    std::unique_ptr<ServerProcess> server = Start({.workers = 0, .max_attempts = 1});
    ASSERT_NE(server, nullptr);
    ReconstructionClient client = server->Client();
    const v1::Job job = GetJob(client, job_id);
    EXPECT_EQ(job.state(), v1::QUEUED);
    EXPECT_EQ(job.attempts(), 1);
    StopCleanly(*server);
  }
  EXPECT_EQ(ReadFile(log_file()).find("recovered"), std::string::npos)
      << "a start found jobs left RUNNING:\n"
      << ReadFile(log_file());

  std::unique_ptr<ServerProcess> server = Start({.workers = 1, .max_attempts = 1});
  ASSERT_NE(server, nullptr);
  ReconstructionClient client = server->Client();
  const std::vector<v1::JobEvent> history = WatchToEnd(client, job_id);
  ASSERT_FALSE(history.empty());
  EXPECT_EQ(history.back().state(), v1::SUCCEEDED) << history.back().message();
  bool released = false;
  for (const v1::JobEvent& e : history) {
    if (e.state() == v1::QUEUED &&
        e.message().find("requeued: the server shut down during attempt 1") != std::string::npos) {
      released = true;
    }
  }
  EXPECT_TRUE(released);
  EXPECT_EQ(GetJob(client, job_id).attempts(), 2);
  StopCleanly(*server);
}

// Cancelling a RUNNING job stops its fit: the job ends CANCELLED long before its 8 starts of up to
// 200 iterations could finish, and has no result.
TEST_F(ServerProcessTest, CancelStopsARunningJob) {
  std::unique_ptr<ServerProcess> server = Start({.workers = 1});
  ASSERT_NE(server, nullptr);
  ReconstructionClient client = server->Client();
  const std::string job_id =
      CreateOk(client, Upload(client), FitConfig(/*max_iterations=*/200, /*starts=*/8)).id();
  ASSERT_FALSE(WatchUntilFirstIteration(*server, job_id).empty());
  v1::Job cancelled;
  ASSERT_TRUE(client.CancelJob(job_id, &cancelled).ok());
  EXPECT_TRUE(cancelled.cancel_requested());
  const Clock::time_point asked = Clock::now();
  const std::vector<v1::JobEvent> history = WatchToEnd(client, job_id);
  ASSERT_FALSE(history.empty());
  EXPECT_EQ(history.back().state(), v1::CANCELLED);
  EXPECT_LT(Clock::now() - asked, std::chrono::seconds(30));
  v1::Result result;
  EXPECT_EQ(client.GetResult(job_id, &result).error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  StopCleanly(*server);
}

// Five jobs on two workers: never more than two RUNNING at once, all five SUCCEEDED.
TEST_F(ServerProcessTest, JobsQueuedBeyondTheWorkersAllFinish) {
  std::unique_ptr<ServerProcess> server = Start({.workers = 2});
  ASSERT_NE(server, nullptr);
  ReconstructionClient client = server->Client();
  const std::string capture_id = Upload(client);
  std::vector<std::string> ids;
  for (int i = 0; i < 5; ++i) ids.push_back(CreateOk(client, capture_id, FitConfig(1)).id());

  const Clock::time_point give_up = Clock::now() + std::chrono::seconds(150);
  int max_running = 0;
  int succeeded = 0;
  while (Clock::now() < give_up) {
    v1::ListJobsResponse page;
    ASSERT_TRUE(client.ListJobs(v1::ListJobsRequest(), &page).ok());
    ASSERT_EQ(page.jobs_size(), 5);
    int running = 0;
    succeeded = 0;
    for (const v1::Job& job : page.jobs()) {
      running += job.state() == v1::RUNNING;
      succeeded += job.state() == v1::SUCCEEDED;
      ASSERT_NE(job.state(), v1::FAILED) << job.id() << ": " << job.error();
    }
    max_running = std::max(max_running, running);
    if (succeeded == 5) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  EXPECT_EQ(succeeded, 5);
  EXPECT_LE(max_running, 2);
  EXPECT_GE(max_running, 1);
  for (const std::string& id : ids) EXPECT_EQ(GetJob(client, id).attempts(), 1);
  StopCleanly(*server);
}

// A repeated request_id returns the job created the first time, also when the queue is full
// (RESOURCE_EXHAUSTED for anything new, naming the bound); reused with another config it is
// ALREADY_EXISTS.
TEST_F(ServerProcessTest, RequestIdIsIdempotentAndTheQueueIsBounded) {
  std::unique_ptr<ServerProcess> server = Start({.workers = 0, .max_queued = 2});
  ASSERT_NE(server, nullptr);
  ReconstructionClient client = server->Client();
  const std::string capture_id = Upload(client, "station-1/take-1");
  EXPECT_EQ(Upload(client, "station-1/take-1"), capture_id);

  const v1::Job first = CreateOk(client, capture_id, FitConfig(2), "take-1/job");
  EXPECT_EQ(first.state(), v1::QUEUED);
  EXPECT_EQ(CreateOk(client, capture_id, FitConfig(2), "take-1/job").id(), first.id());
  CreateOk(client, capture_id, FitConfig(2));

  v1::Job job;
  const grpc::Status full = Create(client, capture_id, FitConfig(2), "take-2/job", &job);
  EXPECT_EQ(full.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_NE(full.error_message().find("max_queued = 2"), std::string::npos) << full.error_message();
  const grpc::Status repeat = Create(client, capture_id, FitConfig(2), "take-1/job", &job);
  ASSERT_TRUE(repeat.ok()) << repeat.error_message();
  EXPECT_EQ(job.id(), first.id());

  const grpc::Status reused = Create(client, capture_id, FitConfig(5), "take-1/job", &job);
  EXPECT_EQ(reused.error_code(), grpc::StatusCode::ALREADY_EXISTS);
  EXPECT_NE(reused.error_message().find(first.id()), std::string::npos) << reused.error_message();

  v1::ListJobsResponse page;
  ASSERT_TRUE(client.ListJobs(v1::ListJobsRequest(), &page).ok());
  EXPECT_EQ(page.jobs_size(), 2);
  StopCleanly(*server);
}

// Each malformed job config field is INVALID_ARGUMENT naming the field and the value; nothing is
// queued.
TEST_F(ServerProcessTest, BadJobConfigNamesTheFieldAndValue) {
  std::unique_ptr<ServerProcess> server = Start({.workers = 0});
  ASSERT_NE(server, nullptr);
  ReconstructionClient client = server->Client();
  const std::string capture_id = Upload(client);
  struct Case {
    std::string config;
    std::vector<std::string> expected;  // substrings of the message
  };
  const std::vector<Case> cases = {
      {R"({"max_iterations": -3})", {"max_iterations", "-3"}},
      {R"({"fit": ["youngs_modulo"]})", {"fit[0]", "youngs_modulo"}},
      {R"({"cells": "many"})", {"cells", "many"}},
      {R"({"starts": 0})", {"starts", "0"}},
      {R"({"gradient": "guess"})", {"gradient", "guess"}},
      {R"({"max_iteration": 5})", {"max_iteration"}},
      {R"({"fit": )", {"config_json", "invalid JSON"}},
  };
  for (const Case& c : cases) {
    v1::Job job;
    const grpc::Status status = Create(client, capture_id, c.config, "", &job);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << c.config;
    for (const std::string& part : c.expected) {
      EXPECT_NE(status.error_message().find(part), std::string::npos)
          << c.config << " -> " << status.error_message();
    }
  }
  v1::Job job;
  EXPECT_EQ(Create(client, "cap-0123456789abcdef", "", "", &job).error_code(),
            grpc::StatusCode::NOT_FOUND);
  v1::ListJobsResponse page;
  ASSERT_TRUE(client.ListJobs(v1::ListJobsRequest(), &page).ok());
  EXPECT_EQ(page.jobs_size(), 0);
  StopCleanly(*server);
}

// Each malformed capture manifest is INVALID_ARGUMENT naming the field (or file) and the value,
// and stores nothing.
TEST_F(ServerProcessTest, BadCaptureManifestNamesTheFieldAndValue) {
  std::unique_ptr<ServerProcess> server = Start({.workers = 0});
  ASSERT_NE(server, nullptr);
  ReconstructionClient client = server->Client();
  const client::CaptureFiles good = CaptureFiles();
  ASSERT_GE(good.files.size(), 2u);
  nlohmann::json capture_json = nlohmann::json::parse(good.capture_json);

  struct Case {
    std::string name;
    client::CaptureFiles files;
    std::vector<std::string> expected;
  };
  std::vector<Case> cases;
  {
    Case c{"not JSON", good, {"capture_json", "invalid JSON"}};
    c.files.capture_json = "{\"format\": ";
    cases.push_back(c);
  }
  {
    Case c{"negative fps", good, {"fps", "-30"}};
    nlohmann::json bad = capture_json;
    bad["fps"] = -30;
    c.files.capture_json = bad.dump();
    cases.push_back(c);
  }
  {
    Case c{"unknown format", good, {"format", "softid-capture/9"}};
    nlohmann::json bad = capture_json;
    bad["format"] = "softid-capture/9";
    c.files.capture_json = bad.dump();
    cases.push_back(c);
  }
  {
    const std::string missing = good.files.back().path();
    Case c{"frame not listed", good, {missing, "is not listed"}};
    c.files.files.pop_back();
    cases.push_back(c);
  }
  {
    Case c{"bad sha256", good, {"sha256", "xyz"}};
    c.files.files[0].set_sha256("xyz");
    cases.push_back(c);
  }
  {
    Case c{"negative size", good, {"size_bytes", "-1"}};
    c.files.files[0].set_size_bytes(-1);
    cases.push_back(c);
  }
  {
    Case c{"path escapes", good, {"path", "../x.png"}};
    c.files.files[0].set_path("../x.png");
    cases.push_back(c);
  }
  for (const Case& c : cases) {
    v1::Capture capture;
    const grpc::Status status = client.UploadCapture(c.files, "", &capture);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << c.name;
    for (const std::string& part : c.expected) {
      EXPECT_NE(status.error_message().find(part), std::string::npos)
          << c.name << " -> " << status.error_message();
    }
  }
  EXPECT_EQ(CountBlobs(data_dir()), 0);
  EXPECT_TRUE(fs::is_empty(data_dir() / "uploads"));
  StopCleanly(*server);
}

// An upload that fails after its files were stored as blobs (here: a request_id reused for other
// bytes, ALREADY_EXISTS) removes the blobs it added, and keeps those another capture uses.
TEST_F(ServerProcessTest, FailedUploadLeavesNoOrphanedBlobs) {
  std::unique_ptr<ServerProcess> server = Start({.workers = 0});
  ASSERT_NE(server, nullptr);
  ReconstructionClient client = server->Client();
  Upload(client, "take-1");
  const int stored = CountBlobs(data_dir());
  ASSERT_GT(stored, 2);

  // The same capture with its mesh file changed by a comment line: a different blob.
  TempDir copy;
  fs::copy(capture_->directory, copy.path(), fs::copy_options::recursive);
  client::CaptureFiles files;
  std::string error;
  ASSERT_TRUE(client::ReadCaptureFiles(copy.path(), &files, &error)) << error;
  const nlohmann::json capture_json = nlohmann::json::parse(files.capture_json);
  const fs::path mesh = copy.path() / capture_json["mesh"].get<std::string>();
  {
    std::ofstream out(mesh, std::ios::app);
    out << "# changed\n";
  }
  files = client::CaptureFiles();
  ASSERT_TRUE(client::ReadCaptureFiles(copy.path(), &files, &error)) << error;

  v1::Capture capture;
  const grpc::Status reused = client.UploadCapture(files, "take-1", &capture);
  EXPECT_EQ(reused.error_code(), grpc::StatusCode::ALREADY_EXISTS) << reused.error_message();
  EXPECT_EQ(CountBlobs(data_dir()), stored);

  // Without the clash the same files are stored: one new blob.
  const grpc::Status fresh = client.UploadCapture(files, "take-2", &capture);
  ASSERT_TRUE(fresh.ok()) << fresh.error_message();
  EXPECT_EQ(CountBlobs(data_dir()), stored + 1);
  StopCleanly(*server);
}

// --listen localhost:0 opens exactly the port it writes; the data directory and its files are
// private to the server's user; blobs that no capture lists (an upload killed between storing its
// blobs and committing) are removed at the next start, while a capture's blobs stay.
TEST_F(ServerProcessTest, OneListenerPrivateFilesAndOrphanBlobsSweptAtStart) {
  std::string capture_id;
  {
    std::unique_ptr<ServerProcess> server = Start({});
    ASSERT_NE(server, nullptr);
    EXPECT_EQ(CountListeningSockets(server->pid()), 1);
    ReconstructionClient client = server->Client();
    capture_id = Upload(client);
    ASSERT_FALSE(capture_id.empty());
    StopCleanly(*server);
  }
  EXPECT_EQ(fs::status(data_dir()).permissions() & fs::perms::all, fs::perms::owner_all);
  EXPECT_EQ(fs::status(data_dir() / "softid.db").permissions() &
                (fs::perms::group_all | fs::perms::others_all),
            fs::perms::none);
  int stored = 0;
  for (const auto& entry : fs::recursive_directory_iterator(data_dir() / "blobs")) {
    if (entry.is_regular_file() && entry.path().parent_path().filename() != "tmp") ++stored;
  }
  ASSERT_GT(stored, 0);
  const std::string orphan(64, 'a');
  fs::create_directories(data_dir() / "blobs" / "aa");
  std::ofstream(data_dir() / "blobs" / "aa" / orphan) << "left by a killed upload";

  std::unique_ptr<ServerProcess> server = Start({});
  ASSERT_NE(server, nullptr);
  EXPECT_FALSE(fs::exists(data_dir() / "blobs" / "aa" / orphan));
  int kept = 0;
  for (const auto& entry : fs::recursive_directory_iterator(data_dir() / "blobs")) {
    if (entry.is_regular_file() && entry.path().parent_path().filename() != "tmp") ++kept;
  }
  EXPECT_EQ(kept, stored);
  ReconstructionClient client = server->Client();
  v1::Job job;
  EXPECT_TRUE(Create(client, capture_id, FitConfig(1), "", &job).ok());
  StopCleanly(*server);
}

// Standard output and exit status of `softid-server <args>` (the tokens subcommand).
std::pair<std::string, int> RunServerCommand(const std::string& args) {
  const std::string command = std::string(SOFTID_SERVER_BINARY) + " " + args + " 2>/dev/null";
  FILE* pipe = ::popen(command.c_str(), "r");
  if (pipe == nullptr) return {"", -1};
  std::string out;
  char buffer[512];
  while (std::fgets(buffer, sizeof buffer, pipe) != nullptr) out += buffer;
  const int status = ::pclose(pipe);
  return {out, WIFEXITED(status) ? WEXITSTATUS(status) : -1};
}

// The secret `softid-server tokens create <store> --station <station>` prints for a new token,
// or "" (with a failure) if it printed none. `store`: "--data DIR" or "--store URL".
std::string CreateTokenIn(const std::string& store, const std::string& station,
                          bool admin = false) {
  const auto [out, status] = RunServerCommand("tokens create " + store + " --station " + station +
                                              (admin ? " --admin" : ""));
  const std::string secret = out.substr(0, out.find('\n'));
  EXPECT_EQ(status, 0) << station;
  EXPECT_EQ(secret.rfind("softid_", 0), 0u) << station << ": " << out;
  return secret;
}
std::string CreateToken(const fs::path& data, const std::string& station, bool admin = false) {
  return CreateTokenIn("--data " + data.string(), station, admin);
}

// The operator's token commands on a running server's data directory: a created token works at
// once, list shows it (never its secret), and a revoked one is refused on the next call.
TEST_F(ServerProcessTest, TokensCreatedAndRevokedFromTheCommandLine) {
  fs::create_directories(data_dir());
  const std::string secret = CreateToken(data_dir(), "lab-7");
  ASSERT_FALSE(secret.empty());
  EXPECT_EQ(
      RunServerCommand("tokens create --data " + data_dir().string() + " --station 'a b'").second,
      2);

  ServerProcess::Flags flags;
  flags.extra = {"--auth", "token"};
  std::unique_ptr<ServerProcess> server = Start(flags);
  ASSERT_NE(server, nullptr);
  ReconstructionClient station = server->Client(secret);
  const std::string capture_id = Upload(station);
  ASSERT_FALSE(capture_id.empty());
  v1::ListJobsResponse page;
  EXPECT_EQ(server->Client().ListJobs(v1::ListJobsRequest(), &page).error_code(),
            grpc::StatusCode::UNAUTHENTICATED);

  const auto [listed, list_status] =
      RunServerCommand("tokens list --json --data " + data_dir().string());
  ASSERT_EQ(list_status, 0);
  const nlohmann::json tokens = nlohmann::json::parse(listed);
  ASSERT_EQ(tokens.size(), 1u);
  EXPECT_EQ(tokens[0]["station"], "lab-7");
  EXPECT_EQ(listed.find(secret), std::string::npos);
  ASSERT_EQ(RunServerCommand("tokens revoke --data " + data_dir().string() + " " +
                             tokens[0]["id"].get<std::string>())
                .second,
            0);
  EXPECT_EQ(station.ListJobs(v1::ListJobsRequest(), &page).error_code(),
            grpc::StatusCode::UNAUTHENTICATED);
  StopCleanly(*server);
}

// Every page of ListJobs as `client`'s caller sees it, `page_size` jobs a page.
grpc::Status ListAllJobs(ReconstructionClient& client, int page_size, std::vector<v1::Job>* jobs) {
  v1::ListJobsRequest request;
  request.set_page_size(page_size);
  while (true) {
    v1::ListJobsResponse page;
    const grpc::Status status = client.ListJobs(request, &page);
    if (!status.ok()) return status;
    jobs->insert(jobs->end(), page.jobs().begin(), page.jobs().end());
    if (page.next_page_token().empty()) return grpc::Status::OK;
    request.set_page_token(page.next_page_token());
  }
}

// Sixteen stations, each with its own API token, upload a capture and submit jobs all at once.
// Each station then lists exactly the jobs it created (across pages); another station's job and
// capture answer NOT_FOUND to it, word for word like a missing one, for every call (get, cancel,
// delete, result, watch, create on the capture, delete the capture), and leave that job untouched;
// all stations use the same request ids, which are per station. An admin token lists every
// job; a call without a token, or with an unknown one, is UNAUTHENTICATED.
TEST_F(ServerProcessTest, SixteenStationsWithTheirOwnTokensSeeOnlyTheirOwnJobs) {
  constexpr int kStations = 16;  // also the server's default --max-uploads: all upload at once
  constexpr int kJobsPerStation = 3;
  fs::create_directories(data_dir());
  std::vector<std::string> names;
  std::vector<std::string> tokens;
  for (int s = 0; s < kStations; ++s) {
    names.push_back("station-" + std::to_string(s));
    tokens.push_back(CreateToken(data_dir(), names.back()));
  }
  const std::string admin_token = CreateToken(data_dir(), "operator", /*admin=*/true);
  ASSERT_FALSE(HasFailure());

  ServerProcess::Flags flags{.workers = 0};  // the jobs stay QUEUED
  flags.extra = {"--auth", "token"};
  std::unique_ptr<ServerProcess> server = Start(flags);
  ASSERT_NE(server, nullptr);

  std::vector<std::string> capture_ids(kStations);
  std::vector<std::vector<std::string>> job_ids(kStations);  // in creation order
  {
    std::latch ready(kStations);
    std::vector<std::thread> stations;
    for (int s = 0; s < kStations; ++s) {
      stations.emplace_back([&, s] {
        ReconstructionClient client = server->Client(tokens[s]);
        ready.arrive_and_wait();
        // Every station uses the same request ids: they are per station.
        capture_ids[s] = Upload(client, "take-1");
        if (capture_ids[s].empty()) return;
        for (int k = 0; k < kJobsPerStation; ++k) {
          const std::string request_id = "take-1/job-" + std::to_string(k);
          job_ids[s].push_back(CreateOk(client, capture_ids[s], FitConfig(1), request_id).id());
        }
      });
    }
    for (std::thread& station : stations) station.join();
  }
  std::set<std::string> all_jobs;
  std::set<std::string> all_captures;
  for (int s = 0; s < kStations; ++s) {
    ASSERT_EQ(job_ids[s].size(), static_cast<size_t>(kJobsPerStation)) << names[s];
    all_jobs.insert(job_ids[s].begin(), job_ids[s].end());
    all_captures.insert(capture_ids[s]);
  }
  ASSERT_EQ(all_jobs.size(), static_cast<size_t>(kStations * kJobsPerStation));
  ASSERT_EQ(all_captures.size(), static_cast<size_t>(kStations));

  const std::string missing_job = "job-0123456789abcdef";
  for (int s = 0; s < kStations; ++s) {
    SCOPED_TRACE(names[s]);
    ReconstructionClient client = server->Client(tokens[s]);
    std::vector<v1::Job> listed;
    ASSERT_TRUE(ListAllJobs(client, /*page_size=*/2, &listed).ok());
    std::set<std::string> listed_ids;
    for (const v1::Job& job : listed) {
      listed_ids.insert(job.id());
      EXPECT_EQ(job.capture_id(), capture_ids[s]) << job.id();
    }
    EXPECT_EQ(listed.size(), job_ids[s].size());
    EXPECT_EQ(listed_ids, std::set<std::string>(job_ids[s].begin(), job_ids[s].end()));

    const int other = (s + 5) % kStations;
    const std::string& theirs = job_ids[other][1];
    v1::Job job;
    const grpc::Status absent = client.GetJob(missing_job, &job);
    ASSERT_EQ(absent.error_code(), grpc::StatusCode::NOT_FOUND);
    std::string as_if_absent = absent.error_message();
    const size_t named = as_if_absent.find(missing_job);
    ASSERT_NE(named, std::string::npos) << as_if_absent;
    as_if_absent.replace(named, missing_job.size(), theirs);
    const grpc::Status got = client.GetJob(theirs, &job);
    EXPECT_EQ(got.error_code(), grpc::StatusCode::NOT_FOUND);
    EXPECT_EQ(got.error_message(), as_if_absent);
    EXPECT_EQ(client.CancelJob(theirs, &job).error_code(), grpc::StatusCode::NOT_FOUND);
    EXPECT_EQ(client.DeleteJob(theirs).error_code(), grpc::StatusCode::NOT_FOUND);
    v1::Result result;
    EXPECT_EQ(client.GetResult(theirs, &result).error_code(), grpc::StatusCode::NOT_FOUND);
    int watched = 0;
    EXPECT_EQ(client.WatchJob(theirs, 0, [&](const v1::JobEvent&) { ++watched; }).error_code(),
              grpc::StatusCode::NOT_FOUND);
    EXPECT_EQ(watched, 0);
    EXPECT_EQ(Create(client, capture_ids[other], FitConfig(1), "", &job).error_code(),
              grpc::StatusCode::NOT_FOUND);
    EXPECT_EQ(client.DeleteCapture(capture_ids[other]).error_code(), grpc::StatusCode::NOT_FOUND);
    // Its request id, which every station used, gives back its own job.
    job.Clear();
    ASSERT_TRUE(Create(client, capture_ids[s], FitConfig(1), "take-1/job-0", &job).ok());
    EXPECT_EQ(job.id(), job_ids[s][0]);
  }

  // The admin sees all of them, in pages that cross stations, none touched by the calls above.
  ReconstructionClient admin = server->Client(admin_token);
  std::vector<v1::Job> everything;
  ASSERT_TRUE(ListAllJobs(admin, /*page_size=*/7, &everything).ok());
  std::set<std::string> everything_ids;
  for (const v1::Job& job : everything) {
    everything_ids.insert(job.id());
    EXPECT_EQ(job.state(), v1::QUEUED) << job.id();
    EXPECT_FALSE(job.cancel_requested()) << job.id();
  }
  EXPECT_EQ(everything.size(), all_jobs.size());
  EXPECT_EQ(everything_ids, all_jobs);
  v1::Job job;
  EXPECT_TRUE(admin.GetJob(job_ids[3][2], &job).ok());

  // Each station cancels its own first job: those, and only those, are cancelled.
  std::set<std::string> cancelled;
  for (int s = 0; s < kStations; ++s) {
    ReconstructionClient client = server->Client(tokens[s]);
    EXPECT_TRUE(client.CancelJob(job_ids[s][0], &job).ok()) << names[s];
    cancelled.insert(job_ids[s][0]);
  }
  everything.clear();
  ASSERT_TRUE(ListAllJobs(admin, /*page_size=*/0, &everything).ok());
  EXPECT_EQ(everything.size(), all_jobs.size());
  for (const v1::Job& listed : everything) {
    const bool was_cancelled = listed.cancel_requested() || listed.state() == v1::CANCELLED;
    EXPECT_EQ(was_cancelled, cancelled.contains(listed.id())) << listed.id();
  }

  for (const std::string& token : {std::string(), "softid_" + std::string(64, '0')}) {
    SCOPED_TRACE(token.empty() ? "no token" : "unknown token");
    ReconstructionClient stranger = server->Client(token);
    v1::ListJobsResponse page;
    EXPECT_EQ(stranger.ListJobs(v1::ListJobsRequest(), &page).error_code(),
              grpc::StatusCode::UNAUTHENTICATED);
    EXPECT_EQ(page.jobs_size(), 0);
    EXPECT_EQ(stranger.GetJob(job_ids[0][1], &job).error_code(), grpc::StatusCode::UNAUTHENTICATED);
    EXPECT_EQ(Create(stranger, capture_ids[0], FitConfig(1), "", &job).error_code(),
              grpc::StatusCode::UNAUTHENTICATED);
    v1::Capture capture;
    EXPECT_EQ(stranger.UploadCapture(CaptureFiles(), "", &capture).error_code(),
              grpc::StatusCode::UNAUTHENTICATED);
  }
  StopCleanly(*server);
}

// What lies in a data directory's blobs/ and uploads/ (the staging folders) at one moment. Files
// may come and go while it is read; those are skipped.
struct DiskState {
  std::set<std::string> blobs;  // names of the files under blobs/<xx>/
  int blob_temp_files = 0;      // under blobs/tmp/
  int64_t blob_temp_bytes = 0;
  int staged_files = 0;  // under uploads/
  int64_t staged_bytes = 0;
};

DiskState ReadDiskState(const fs::path& data) {
  DiskState state;
  for (const char* folder : {"blobs", "uploads"}) {
    std::error_code error;
    for (fs::recursive_directory_iterator it(data / folder, error), end; !error && it != end;
         it.increment(error)) {
      std::error_code stat_error;
      if (!it->is_regular_file(stat_error)) continue;
      const uintmax_t size = it->file_size(stat_error);
      const int64_t bytes = stat_error ? 0 : static_cast<int64_t>(size);
      if (folder == std::string("uploads")) {
        ++state.staged_files;
        state.staged_bytes += bytes;
      } else if (it->path().parent_path().filename() == "tmp") {
        ++state.blob_temp_files;
        state.blob_temp_bytes += bytes;
      } else {
        state.blobs.insert(it->path().filename().string());
      }
    }
  }
  return state;
}

// Names of the stored blobs whose bytes do not hash to their name.
std::vector<std::string> CorruptBlobs(const fs::path& data, const std::set<std::string>& blobs) {
  std::vector<std::string> corrupt;
  for (const std::string& name : blobs) {
    std::string sha256;
    int64_t size = 0;
    const fs::path path = data / "blobs" / name.substr(0, 2) / name;
    if (!client::Sha256OfFile(path, &sha256, &size) || sha256 != name) corrupt.push_back(name);
  }
  return corrupt;
}

// `count` files of random bytes, bulk/part-<i>.bin in `directory`, listed after the capture's own
// files: the upload stores them as blobs last. The server keeps files the capture does not name.
client::CaptureFiles WithBulkFiles(const fs::path& directory, int count, int64_t bytes_each) {
  client::CaptureFiles files;
  std::string error;
  EXPECT_TRUE(client::ReadCaptureFiles(directory, &files, &error)) << error;
  fs::create_directories(directory / "bulk");
  std::vector<uint64_t> buffer((size_t{1} << 20) / sizeof(uint64_t));
  for (int i = 0; i < count; ++i) {
    const std::string path = "bulk/part-" + std::to_string(i) + ".bin";
    std::mt19937_64 random(static_cast<uint64_t>(bytes_each) * 31 + i);
    {
      std::ofstream out(directory / path, std::ios::binary | std::ios::trunc);
      for (int64_t written = 0; written < bytes_each; written += int64_t{1} << 20) {
        for (uint64_t& word : buffer) word = random();
        out.write(reinterpret_cast<const char*>(buffer.data()),
                  std::min<int64_t>(int64_t{1} << 20, bytes_each - written));
      }
      EXPECT_TRUE(out.flush()) << path;
    }
    v1::CaptureFile file;
    file.set_path(path);
    std::string sha256;
    int64_t size = 0;
    EXPECT_TRUE(client::Sha256OfFile(directory / path, &sha256, &size)) << path;
    file.set_sha256(sha256);
    file.set_size_bytes(size);
    files.files.push_back(file);
  }
  return files;
}

// kill -9 while an upload's files are being stored as blobs (some under their names already, the
// next one part-written, the capture not committed): the restarted server has swept them all (no
// capture lists them), its staging and temporary folders are empty, and the same upload (same
// request_id) then succeeds, leaving exactly the blobs its capture lists, and a job can be created
// on it. Blobs under their final name are never a prefix of their bytes.
TEST_F(ServerProcessTest, KillNineDuringBlobStorageLeavesNothingOrphanedAfterRestart) {
  constexpr int kBulkFiles = 4;
  TempDir copy;
  fs::copy(capture_->directory, copy.path(), fs::copy_options::recursive);
  client::CaptureFiles files;
  DiskState at_kill;
  bool killed_while_storing = false;
  std::string attempts;
  // Each attempt doubles the bulk files, should the blob writes end before they were seen.
  for (int attempt = 0; attempt < 3 && !killed_while_storing; ++attempt) {
    const int64_t bytes_each = (int64_t{32} << 20) << attempt;
    files = WithBulkFiles(copy.path(), kBulkFiles, bytes_each);
    ASSERT_FALSE(HasFailure());
    std::error_code ignored;
    fs::remove_all(data_dir(), ignored);
    std::unique_ptr<ServerProcess> server = Start({.workers = 0});
    ASSERT_NE(server, nullptr);
    ReconstructionClient client = server->Client();
    std::atomic<bool> done{false};
    grpc::Status uploaded;
    std::thread upload([&] {
      v1::Capture capture;
      uploaded = client.UploadCapture(files, "take-1", &capture);
      done = true;
    });
    // Blob writes are under way when a blob has its name and a temporary file holds more than
    // a chunk: only the bulk files are that large, and they are stored last.
    bool seen_storing = false;
    const Clock::time_point give_up = Clock::now() + std::chrono::seconds(60);
    while (!done && Clock::now() < give_up) {
      const DiskState now = ReadDiskState(data_dir());
      if (!now.blobs.empty() && now.blob_temp_bytes > (int64_t{1} << 20)) {
        seen_storing = true;
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    server->Signal(SIGKILL);
    const std::optional<int> status = server->Wait(std::chrono::seconds(10));
    upload.join();
    ASSERT_EQ(status, 128 + SIGKILL) << ReadFile(log_file());
    at_kill = ReadDiskState(data_dir());
    // The capture is committed only after its last file, the last bulk file, was stored.
    const bool committed = uploaded.ok() || at_kill.blobs.contains(files.files.back().sha256());
    attempts += "attempt " + std::to_string(attempt) + ": " + std::to_string(kBulkFiles) + " x " +
                std::to_string(bytes_each >> 20) + " MiB, " +
                (seen_storing ? "seen storing" : "not seen storing") +
                (committed ? ", killed too late" : "") + "; upload: " + uploaded.error_message() +
                "\n";
    killed_while_storing = seen_storing && !committed;
  }
  ASSERT_TRUE(killed_while_storing) << attempts;
  RecordProperty("attempts", attempts);
  RecordProperty("at_kill", std::to_string(at_kill.blobs.size()) + " blobs named, " +
                                std::to_string(at_kill.blob_temp_bytes) + " bytes in blobs/tmp, " +
                                std::to_string(at_kill.staged_bytes) + " bytes staged");
  // Bytes were on disk at the kill: the staged upload, and blobs no capture lists.
  EXPECT_GT(at_kill.staged_bytes, 0) << attempts;
  EXPECT_FALSE(at_kill.blobs.empty()) << attempts;
  EXPECT_EQ(CorruptBlobs(data_dir(), at_kill.blobs), std::vector<std::string>());

  std::unique_ptr<ServerProcess> server = Start({.workers = 0});
  ASSERT_NE(server, nullptr);
  const DiskState restarted = ReadDiskState(data_dir());
  EXPECT_EQ(restarted.blobs, std::set<std::string>()) << "no capture lists them";
  EXPECT_TRUE(fs::is_empty(data_dir() / "blobs" / "tmp"));
  EXPECT_TRUE(fs::is_empty(data_dir() / "uploads"));

  ReconstructionClient client = server->Client();
  v1::Capture capture;
  const grpc::Status fresh = client.UploadCapture(files, "take-1", &capture);
  ASSERT_TRUE(fresh.ok()) << fresh.error_message();
  std::set<std::string> listed;
  for (const v1::CaptureFile& file : capture.files()) listed.insert(file.sha256());
  for (const v1::CaptureFile& file : files.files) EXPECT_TRUE(listed.contains(file.sha256()));
  const DiskState stored = ReadDiskState(data_dir());
  EXPECT_EQ(stored.blobs, listed);
  EXPECT_EQ(stored.blob_temp_files, 0);
  EXPECT_EQ(stored.staged_files, 0);
  EXPECT_EQ(CorruptBlobs(data_dir(), stored.blobs), std::vector<std::string>());
  const v1::Job job = CreateOk(client, capture.id(), FitConfig(1));
  EXPECT_EQ(job.capture_id(), capture.id());
  EXPECT_EQ(job.state(), v1::QUEUED);
  StopCleanly(*server);
}

// Standard output and error, together, and exit status of `softid-server <args>`.
std::pair<std::string, int> RunServerCommandWithErrors(const std::string& args) {
  const std::string command = std::string(SOFTID_SERVER_BINARY) + " " + args + " 2>&1";
  FILE* pipe = ::popen(command.c_str(), "r");
  if (pipe == nullptr) return {"", -1};
  std::string out;
  char buffer[512];
  while (std::fgets(buffer, sizeof buffer, pipe) != nullptr) out += buffer;
  const int status = ::pclose(pipe);
  return {out, WIFEXITED(status) ? WEXITSTATUS(status) : -1};
}

// A --store the server cannot use stops it at start with the flag and the URL in the message,
// never the password: exit 2 for a value that is not a PostgreSQL URL, 1 for a server that cannot
// be reached.
TEST_F(ServerProcessTest, UnusableStoreIsRefusedNamingTheFlag) {
  const std::string data = "--listen localhost:0 --data " + data_dir().string();
  const auto [unreachable, unreachable_status] =
      RunServerCommandWithErrors(data + " --store postgresql://softid:s3cret@127.0.0.1:1/softid");
  EXPECT_EQ(unreachable_status, 1) << unreachable;
  EXPECT_NE(unreachable.find("--store postgresql://softid:****@127.0.0.1:1/softid: cannot "
                             "connect: "),
            std::string::npos)
      << unreachable;
  EXPECT_EQ(unreachable.find("s3cret"), std::string::npos) << unreachable;

  const auto [other, other_status] = RunServerCommandWithErrors(data + " --store mysql://db/x");
  EXPECT_EQ(other_status, 2) << other;
  EXPECT_NE(other.find("--store mysql://db/x: must be a postgresql:// URL"), std::string::npos)
      << other;
}

// A role the server does not have, or a worker without workers, stops it naming the flag.
TEST_F(ServerProcessTest, BadRoleIsRefusedNamingTheFlag) {
  const std::string data = "--listen localhost:0 --data " + data_dir().string();
  const auto [unknown, unknown_status] = RunServerCommandWithErrors(data + " --role boss");
  EXPECT_EQ(unknown_status, 2) << unknown;
  EXPECT_NE(unknown.find("--role boss: must be all, api or worker"), std::string::npos) << unknown;
  const auto [idle, idle_status] = RunServerCommandWithErrors(data + " --role worker --workers 0");
  EXPECT_NE(idle_status, 0) << idle;
  EXPECT_NE(idle.find("role = worker with workers = 0"), std::string::npos) << idle;
}

// The server on a PostgreSQL store (tests/server/with_postgres.sh starts one): a token made with
// `tokens create --store` lets a station in, and a job runs to SUCCEEDED, recorded in PostgreSQL
// rather than in a SQLite file under --data, which keeps only the uploaded files.
class PostgresServerProcessTest : public ServerProcessTest {
 protected:
  void SetUp() override {
    if (const std::optional<std::string> why = store::testing::PostgresUnavailable()) {
      GTEST_SKIP() << *why;
    }
    ServerProcessTest::SetUp();
    Result<std::string> url = store::testing::TestDatabase(root_.path().string());
    ASSERT_TRUE(url.ok()) << url.status().ToString();
    url_ = *url;
  }
  void TearDown() override {
    if (url_.empty()) return;
    const Status dropped = store::testing::DropTestDatabase(root_.path().string());
    EXPECT_TRUE(dropped.ok()) << dropped.ToString();
  }

  std::string url_;
};

// Two processes on one store and one data directory: an API process (takes RPCs, never fits) and
// a worker (runs jobs, answers only health probes). A job submitted to the API runs on the worker,
// and the API serves its progress, result and report.
TEST_F(PostgresServerProcessTest, ApiAndWorkerProcessesShareTheStoreAndTheData) {
  ServerProcess::Flags api_flags;
  api_flags.extra = {"--store", url_, "--role", "api", "--store-connections", "2"};
  api_flags.name = "-api";
  ServerProcess::Flags worker_flags;
  worker_flags.extra = {"--store", url_, "--role", "worker"};
  worker_flags.name = "-worker";
  const fs::path api_log = root_.path() / "api.log", worker_log = root_.path() / "worker.log";
  auto api = std::make_unique<ServerProcess>(data_dir(), api_log, api_flags);
  ASSERT_TRUE(api->WaitUntilServing());
  ReconstructionClient client = api->Client();
  const v1::Job job = CreateOk(client, Upload(client), FitConfig(1));
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));
  EXPECT_EQ(GetJob(client, job.id()).state(), v1::QUEUED) << "the API process ran a job";

  auto worker = std::make_unique<ServerProcess>(data_dir(), worker_log, worker_flags);
  ASSERT_TRUE(worker->WaitUntilServing());
  WatchToEnd(client, job.id());
  EXPECT_EQ(GetJob(client, job.id()).state(), v1::SUCCEEDED) << ReadFile(worker_log);
  v1::Result result;
  ASSERT_TRUE(client.GetResult(job.id(), &result).ok());
  EXPECT_EQ(result.artifacts_size(), 3);
  v1::Job listed;
  EXPECT_EQ(worker->Client().GetJob(job.id(), &listed).error_code(),
            grpc::StatusCode::UNIMPLEMENTED);
  StopCleanly(*worker);
  api->Signal(SIGTERM);
  EXPECT_EQ(api->Wait(std::chrono::seconds(20)).value_or(-1), 0) << ReadFile(api_log);
}

TEST_F(PostgresServerProcessTest, RunsAJobWithItsStoreInPostgres) {
  const std::string secret = CreateTokenIn("--store '" + url_ + "'", "lab-pg");
  ASSERT_FALSE(secret.empty());

  ServerProcess::Flags flags;
  flags.extra = {"--store", url_, "--auth", "token"};
  std::unique_ptr<ServerProcess> server = Start(flags);
  ASSERT_NE(server, nullptr);
  ReconstructionClient client = server->Client(secret);
  const std::string capture_id = Upload(client);
  ASSERT_FALSE(capture_id.empty());
  const v1::Job job = CreateOk(client, capture_id, FitConfig(2));
  WatchToEnd(client, job.id());
  const v1::Job done = GetJob(client, job.id());
  EXPECT_EQ(done.state(), v1::SUCCEEDED) << done.error();
  StopCleanly(*server);

  EXPECT_FALSE(fs::exists(data_dir() / "softid.db"));
  EXPECT_GT(CountBlobs(data_dir()), 0);
  Result<store::PostgresConnection> db = store::PostgresConnection::Connect(url_);
  ASSERT_TRUE(db.ok()) << db.status().ToString();
  Result<store::PostgresResult> row =
      db->Query("SELECT state, owner FROM jobs WHERE id = $1", job.id());
  ASSERT_TRUE(row.ok()) << row.status().ToString();
  ASSERT_EQ(row->rows(), 1);
  EXPECT_EQ(row->Text(0, 0), "SUCCEEDED");
  EXPECT_EQ(row->Text(0, 1), "lab-pg");
}

// Fan-out over processes: an API and two worker processes with --fan-out-starts share the store.
// The second worker is killed (kill -9) while it runs one of the job's start tasks; once that
// task's lease expires the first worker runs it again, and the job SUCCEEDS with every start.
TEST_F(PostgresServerProcessTest, AStartTaskOfAKilledWorkerRunsAgainElsewhere) {
  auto flags = [&](const std::string& role, const std::string& name) {
    ServerProcess::Flags f;
    f.extra = {"--store", url_, "--role", role, "--fan-out-starts", "--lease-seconds", "5"};
    f.name = name;
    return f;
  };
  const fs::path api_log = root_.path() / "api.log", a_log = root_.path() / "worker-a.log",
                 b_log = root_.path() / "worker-b.log";
  auto api = std::make_unique<ServerProcess>(data_dir(), api_log, flags("api", "-api"));
  ASSERT_TRUE(api->WaitUntilServing());
  ReconstructionClient client = api->Client();
  const std::string job =
      CreateOk(client, Upload(client), StartsConfig(capture_->truth.youngs_modulus, 4, 12)).id();
  auto a = std::make_unique<ServerProcess>(data_dir(), a_log, flags("worker", "-a"));
  ASSERT_TRUE(a->WaitUntilServing());
  WatchUntilFirstIteration(*api, job);
  auto b = std::make_unique<ServerProcess>(data_dir(), b_log, flags("worker", "-b"));
  ASSERT_TRUE(b->WaitUntilServing());
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (StartTaskWorkers(b_log, job).empty() && std::chrono::steady_clock::now() < give_up) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  ASSERT_FALSE(StartTaskWorkers(b_log, job).empty()) << ReadFile(b_log);
  b->Signal(SIGKILL);
  EXPECT_EQ(b->Wait(std::chrono::seconds(10)), 128 + SIGKILL);

  ASSERT_EQ(WatchToEnd(client, job).back().state(), v1::SUCCEEDED) << ReadFile(a_log);
  EXPECT_NE(ReadFile(a_log).find("(task attempt 2)"), std::string::npos) << ReadFile(a_log);
  v1::Result result;
  ASSERT_TRUE(client.GetResult(job, &result).ok());
  const nlohmann::json json = nlohmann::json::parse(result.result_json());
  ASSERT_EQ(json["starts"].size(), 4u);
  for (const nlohmann::json& start : json["starts"]) {
    EXPECT_FALSE(start["failed"].get<bool>());
    EXPECT_GT(start["evaluations"].get<int>(), 0);
  }
  EXPECT_EQ(GetJob(client, job).attempts(), 1);  // the job's own worker was never lost
}

}  // namespace
}  // namespace softid::server
