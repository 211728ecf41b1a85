// Test helpers for softid-server in a process of its own: starting it on a free port with its
// output in a log file, its client, signals and exit status; small fit configs; what its log
// says about start tasks. Shared by the process and multi-node tests.
#pragma once

#include <fcntl.h>
#include <grpcpp/create_channel.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "client/reconstruction_client.h"

extern char** environ;

namespace softid::server::testing {

namespace fs = std::filesystem;
using client::ReconstructionClient;

// Fits youngs_modulus on the small capture with one thread; starts run one after the other.
inline std::string FitConfig(int max_iterations, int starts = 1) {
  return nlohmann::json{{"fit", {"youngs_modulus"}},
                        {"max_iterations", max_iterations},
                        {"starts", starts},
                        {"threads", 1},
                        {"cells", 8},
                        {"substeps", 2},
                        {"fixed", {{"ground", {{"normal", {0, 0, 1}}, {"offset", 0}}}}}}
      .dump();
}

// A config fitting Young's modulus from `starts` random starts between half and twice `truth`.
inline std::string StartsConfig(double truth, int starts, int max_iterations) {
  nlohmann::json config = nlohmann::json::parse(FitConfig(max_iterations, starts));
  config["initial"] = {{"youngs_modulus", {{"min", 0.5 * truth}, {"max", 2.0 * truth}}}};
  return config.dump();
}

// The workers a server's log shows running the start tasks of `job_id` ("job ... start k:
// RUNNING on <worker> (task attempt n)"), with how many each ran.
inline std::map<std::string, int> StartTaskWorkers(const fs::path& log, const std::string& job_id) {
  std::map<std::string, int> workers;
  const std::regex line("job " + job_id + " start [0-9]+: RUNNING on ([^ ]+) ");
  std::ifstream in(log);
  for (std::string text; std::getline(in, text);) {
    std::smatch match;
    if (std::regex_search(text, match, line)) ++workers[match[1].str()];
  }
  return workers;
}

inline std::string ReadFile(const fs::path& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

// One softid-server process on a free port, its output in a log file. Killed (SIGKILL) on
// destruction if still running.
class ServerProcess {
 public:
  struct Flags {
    int workers = 1;
    int max_queued = 100;
    int max_attempts = 3;
    std::vector<std::string> extra = {};  // further flags
    std::string name = "";                // tells apart processes sharing one data directory
  };

  ServerProcess(const fs::path& data_dir, const fs::path& log_file, const Flags& flags)
      : port_file_(data_dir.string() + flags.name + ".port"), log_file_(log_file) {
    std::error_code ignored;
    fs::remove(port_file_, ignored);
    std::vector<std::string> args = {SOFTID_SERVER_BINARY,
                                     "--listen",
                                     "localhost:0",
                                     "--port-file",
                                     port_file_.string(),
                                     "--data",
                                     data_dir.string(),
                                     "--workers",
                                     std::to_string(flags.workers),
                                     "--max-queued",
                                     std::to_string(flags.max_queued),
                                     "--max-attempts",
                                     std::to_string(flags.max_attempts)};
    args.insert(args.end(), flags.extra.begin(), flags.extra.end());
    std::vector<char*> argv;
    for (const std::string& arg : args) argv.push_back(const_cast<char*>(arg.c_str()));
    argv.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    // Appended, so one log file tells the story of every start in a test.
    posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, log_file_.c_str(),
                                     O_WRONLY | O_CREAT | O_APPEND, 0644);
    posix_spawn_file_actions_adddup2(&actions, STDOUT_FILENO, STDERR_FILENO);
    const int spawned =
        posix_spawn(&pid_, SOFTID_SERVER_BINARY, &actions, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&actions);
    if (spawned != 0) {
      ADD_FAILURE() << "cannot start " << SOFTID_SERVER_BINARY << ": " << std::strerror(spawned);
      pid_ = -1;
    }
  }

  ~ServerProcess() {
    if (running()) {
      ::kill(pid_, SIGKILL);
      (void)Wait(std::chrono::seconds(10));
    }
  }

  ServerProcess(const ServerProcess&) = delete;
  ServerProcess& operator=(const ServerProcess&) = delete;

  // Waits until the server wrote its port and answers health checks; false (with a failure
  // naming the log) if it exited or took too long.
  bool WaitUntilServing() {
    const std::chrono::steady_clock::time_point give_up =
        std::chrono::steady_clock::now() + std::chrono::seconds(30);
    while (std::chrono::steady_clock::now() < give_up) {
      if (!running()) {
        ADD_FAILURE() << "softid-server exited with status " << exit_status_.value_or(-1)
                      << " before serving; log:\n"
                      << ReadFile(log_file_);
        return false;
      }
      std::ifstream in(port_file_);
      if (in >> port_ && port_ > 0) {
        client::ServingStatus serving = client::ServingStatus::kUnknown;
        if (Client().Health("", &serving).ok() && serving == client::ServingStatus::kServing) {
          return true;
        }
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    ADD_FAILURE() << "softid-server did not serve within 30 s; log:\n" << ReadFile(log_file_);
    return false;
  }

  ReconstructionClient Client(const std::string& token = "") const {
    client::ClientOptions options;
    options.token = token;
    options.retry_budget = std::chrono::milliseconds(0);
    options.call_timeout = std::chrono::milliseconds(10000);
    // A job that never ends fails the test instead of hanging it.
    options.watch_timeout = std::chrono::milliseconds(180000);
    return ReconstructionClient(grpc::CreateChannel("localhost:" + std::to_string(port_),
                                                    grpc::InsecureChannelCredentials()),
                                options);
  }
  std::unique_ptr<v1::Reconstruction::Stub> Stub() const {
    return v1::Reconstruction::NewStub(grpc::CreateChannel("localhost:" + std::to_string(port_),
                                                           grpc::InsecureChannelCredentials()));
  }

  void Signal(int signal) { ::kill(pid_, signal); }
  pid_t pid() const { return pid_; }

  // The exit status (or 128 + signal), or nullopt if it still runs after `timeout`.
  std::optional<int> Wait(std::chrono::milliseconds timeout) {
    const std::chrono::steady_clock::time_point give_up =
        std::chrono::steady_clock::now() + timeout;
    while (running()) {
      if (std::chrono::steady_clock::now() >= give_up) return std::nullopt;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return exit_status_;
  }

  bool running() {
    if (pid_ <= 0 || exit_status_.has_value()) return false;
    int status = 0;
    const pid_t done = ::waitpid(pid_, &status, WNOHANG);
    if (done == 0) return true;
    if (done == pid_) {
      exit_status_ = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
    } else {
      exit_status_ = -1;
    }
    return false;
  }

 private:
  fs::path port_file_;
  fs::path log_file_;
  pid_t pid_ = -1;
  int port_ = 0;
  std::optional<int> exit_status_;
};

}  // namespace softid::server::testing
