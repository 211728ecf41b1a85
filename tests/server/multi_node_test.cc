// Past one machine, proved on one: PostgreSQL (tests/server/with_postgres.sh starts it), two API
// processes and three worker processes with fanned-out starts share one store and one data
// directory, all real softid-server processes on loopback. Thirty small jobs, each on its own
// upload, go in through both APIs. While they run, one worker is killed (kill -9) right after a
// start of a job it leads finished, and another gets SIGTERM. Then every job has SUCCEEDED exactly
// once, every history is whole (seq 1..n; per attempt and start the iterations count up by one
// from 0, a start run again beginning at 0 again: nothing duplicated, nothing missing), every
// upload is still there, and the killed worker's job resumed: its result keeps the starts the
// lost attempt finished, and its new attempt ran none of them again.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <fstream>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <regex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "client/capture_files.h"
#include "tests/core/inverse/inverse_test_util.h"
#include "tests/server/postgres_test_server.h"
#include "tests/server/server_process.h"
#include "tests/server/temp_dir.h"

namespace softid::server {
namespace {

namespace fs = std::filesystem;
using client::ReconstructionClient;
using store::testing::TempDir;
using testing::ReadFile;
using testing::ServerProcess;

constexpr int kJobs = 30;
constexpr int kStarts = 3;

// The jobs a worker's log shows it leading ("job <id>: RUNNING on <worker>"), and the starts of
// any job its log shows finished ("job <id> start <k>: done").
struct WorkerLog {
  std::set<std::string> led;
  std::map<std::string, std::set<int>> done;
};

WorkerLog ReadWorkerLog(const fs::path& path) {
  static const std::regex led("job (job-[0-9a-f]+): RUNNING on ");
  static const std::regex done("job (job-[0-9a-f]+) start ([0-9]+): done");
  WorkerLog log;
  std::ifstream in(path);
  for (std::string line; std::getline(in, line);) {
    std::smatch match;
    if (std::regex_search(line, match, led)) log.led.insert(match[1].str());
    if (std::regex_search(line, match, done)) log.done[match[1].str()].insert(std::stoi(match[2]));
  }
  return log;
}

// Checks one job's history: whole and in order, one success.
void ExpectWholeHistory(const std::string& job, const std::vector<v1::JobEvent>& history) {
  SCOPED_TRACE(job);
  int succeeded = 0;
  std::map<std::pair<int, int>, int> last_iteration;  // (attempt, start) -> iteration
  for (size_t i = 0; i < history.size(); ++i) {
    const v1::JobEvent& e = history[i];
    EXPECT_EQ(e.seq(), static_cast<int64_t>(i + 1)) << "a gap or a repeat in the history";
    if (e.kind() == v1::JobEvent::STATE_CHANGE && e.state() == v1::SUCCEEDED &&
        e.message().find("succeeded") != std::string::npos) {
      ++succeeded;
    }
    if (e.kind() != v1::JobEvent::ITERATION) continue;
    const auto key = std::make_pair(e.attempt(), e.start());
    const auto previous = last_iteration.find(key);
    // A start's iterations count 0, 1, 2, ...; a start run again (its worker lost) begins at 0.
    if (previous != last_iteration.end() && e.iteration() != 0) {
      EXPECT_EQ(e.iteration(), previous->second + 1)
          << "attempt " << e.attempt() << " start " << e.start() << " at seq " << e.seq();
    }
    if (previous == last_iteration.end()) EXPECT_EQ(e.iteration(), 0) << "seq " << e.seq();
    last_iteration[key] = e.iteration();
  }
  EXPECT_EQ(succeeded, 1);
}

class PostgresMultiNodeTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (const std::optional<std::string> why = store::testing::PostgresUnavailable()) {
      GTEST_SKIP() << *why;
    }
    // Built in place: a copy's destructor would remove the capture's folder.
    capture_.reset(new inverse::testing::SmallCapture(
        inverse::testing::MakeSmallCapture("torus-drop", /*duration=*/0.2, /*cameras=*/1)));
    ASSERT_TRUE(capture_->ok) << capture_->error;
    Result<std::string> url = store::testing::TestDatabase(root_.path().string());
    ASSERT_TRUE(url.ok()) << url.status().ToString();
    url_ = *url;
  }
  void TearDown() override {
    processes_.clear();
    if (url_.empty()) return;
    const Status dropped = store::testing::DropTestDatabase(root_.path().string());
    EXPECT_TRUE(dropped.ok()) << dropped.ToString();
  }

  ServerProcess& Launch(const std::string& role, const std::string& name) {
    ServerProcess::Flags flags;
    flags.extra = {"--store", url_, "--role", role, "--lease-seconds", "5"};
    if (role == "worker") flags.extra.push_back("--fan-out-starts");
    flags.name = "-" + name;
    processes_[name] = std::make_unique<ServerProcess>(root_.path() / "data", LogOf(name), flags);
    EXPECT_TRUE(processes_[name]->WaitUntilServing()) << name;
    return *processes_[name];
  }
  fs::path LogOf(const std::string& name) const { return root_.path() / (name + ".log"); }

  std::string Upload(ReconstructionClient& client) {
    client::CaptureFiles files;
    std::string error;
    EXPECT_TRUE(client::ReadCaptureFiles(capture_->directory, &files, &error)) << error;
    v1::Capture capture;
    const grpc::Status status = client.UploadCapture(files, "", &capture);
    EXPECT_TRUE(status.ok()) << status.error_message();
    return capture.id();
  }

  // Waits until a worker leads a job one of whose starts has finished while another has not,
  // and kills that worker at once; returns the worker and the job.
  std::pair<std::string, std::string> KillALeaderWithAFinishedStart() {
    const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(120);
    while (std::chrono::steady_clock::now() < give_up) {
      std::map<std::string, std::set<int>> done;
      std::map<std::string, WorkerLog> logs;
      for (const std::string w : {"w1", "w2", "w3"}) {
        logs[w] = ReadWorkerLog(LogOf(w));
        for (const auto& [job, starts] : logs[w].done)
          done[job].insert(starts.begin(), starts.end());
      }
      for (const std::string w : {"w1", "w2", "w3"}) {
        for (const std::string& job : logs[w].led) {
          const size_t finished = done.count(job) ? done[job].size() : 0;
          if (finished >= 1 && finished < static_cast<size_t>(kStarts)) {
            processes_[w]->Signal(SIGKILL);
            EXPECT_EQ(processes_[w]->Wait(std::chrono::seconds(10)), 128 + SIGKILL);
            return {w, job};
          }
        }
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    ADD_FAILURE() << "no worker led a job with a start finished and another running";
    return {};
  }

  std::unique_ptr<inverse::testing::SmallCapture> capture_;
  TempDir root_;
  std::string url_;
  std::map<std::string, std::unique_ptr<ServerProcess>> processes_;
};

TEST_F(PostgresMultiNodeTest, ThirtyJobsSurviveAKilledAndAStoppedWorker) {
  ServerProcess& api1 = Launch("api", "api1");
  ServerProcess& api2 = Launch("api", "api2");
  for (const std::string w : {"w1", "w2", "w3"}) Launch("worker", w);
  ReconstructionClient clients[2] = {api1.Client(), api2.Client()};
  const std::string config =
      testing::StartsConfig(capture_->truth.youngs_modulus, kStarts, /*max_iterations=*/6);

  std::vector<std::string> captures, jobs;
  for (int i = 0; i < kJobs; ++i) {
    ReconstructionClient& client = clients[i % 2];
    captures.push_back(Upload(client));
    v1::CreateJobRequest request;
    request.set_capture_id(captures.back());
    request.set_config_json(config);
    v1::Job job;
    ASSERT_TRUE(client.CreateJob(request, &job).ok());
    jobs.push_back(job.id());
  }

  const auto [killed, resumed_job] = KillALeaderWithAFinishedStart();
  ASSERT_FALSE(killed.empty());
  // SIGTERM to another worker: it hands its work back and exits 0.
  const std::string stopped = killed == "w1" ? "w2" : "w1";
  processes_[stopped]->Signal(SIGTERM);
  EXPECT_EQ(processes_[stopped]->Wait(std::chrono::seconds(30)), 0) << ReadFile(LogOf(stopped));

  for (size_t i = 0; i < jobs.size(); ++i) {
    std::vector<v1::JobEvent> history;
    const grpc::Status watched =
        clients[i % 2].WatchJob(jobs[i], 0, [&](const v1::JobEvent& e) { history.push_back(e); });
    ASSERT_TRUE(watched.ok()) << jobs[i] << ": " << watched.error_message();
    ASSERT_FALSE(history.empty());
    EXPECT_EQ(history.back().state(), v1::SUCCEEDED) << jobs[i];
    ExpectWholeHistory(jobs[i], history);
  }
  // Every upload is listed (through the API that did not take it, for half of them) with its job.
  v1::ListCapturesRequest list;
  list.set_page_size(100);
  v1::ListCapturesResponse listed;
  ASSERT_TRUE(clients[1].ListCaptures(list, &listed).ok());
  std::set<std::string> listed_ids;
  for (const auto& c : listed.captures()) listed_ids.insert(c.id());
  for (const std::string& id : captures) EXPECT_TRUE(listed_ids.contains(id)) << id;

  // The killed leader's job: a second attempt that kept what the first finished.
  v1::Job job;
  ASSERT_TRUE(clients[0].GetJob(resumed_job, &job).ok());
  EXPECT_EQ(job.attempts(), 2);
  v1::Result result;
  ASSERT_TRUE(clients[0].GetResult(resumed_job, &result).ok());
  const nlohmann::json json = nlohmann::json::parse(result.result_json());
  ASSERT_TRUE(json.contains("resumed")) << json.dump();
  const std::vector<int> kept = json["resumed"]["finished_starts"].get<std::vector<int>>();
  EXPECT_FALSE(kept.empty());
  std::vector<v1::JobEvent> history;
  ASSERT_TRUE(clients[0]
                  .WatchJob(resumed_job, 0, [&](const v1::JobEvent& e) { history.push_back(e); })
                  .ok());
  for (const v1::JobEvent& e : history) {
    if (e.kind() == v1::JobEvent::ITERATION && e.attempt() == 2) {
      EXPECT_EQ(std::count(kept.begin(), kept.end(), e.start()), 0)
          << "start " << e.start() << " ran again";
    }
  }

  for (auto& [name, process] : processes_) {
    if (name == killed || name == stopped) continue;
    process->Signal(SIGTERM);
    EXPECT_EQ(process->Wait(std::chrono::seconds(30)), 0) << name;
  }
}

}  // namespace
}  // namespace softid::server
