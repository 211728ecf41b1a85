#include "server/log_context.h"

#include <fcntl.h>
#include <spdlog/pattern_formatter.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <thread>

namespace softid::server {
namespace {

thread_local std::string current_job;

// %J: the job this thread works on ("" outside a job).
class JobFlag : public spdlog::custom_flag_formatter {
 public:
  explicit JobFlag(bool text) : text_(text) {}
  void format(const spdlog::details::log_msg&, const std::tm&,
              spdlog::memory_buf_t& dest) override {
    if (current_job.empty()) return;
    const std::string shown = text_ ? "[" + current_job + "] " : current_job;
    dest.append(shown.data(), shown.data() + shown.size());
  }
  std::unique_ptr<custom_flag_formatter> clone() const override {
    return std::make_unique<JobFlag>(text_);
  }

 private:
  bool text_;
};

// %E: the message as the inside of a JSON string.
class JsonMessageFlag : public spdlog::custom_flag_formatter {
 public:
  void format(const spdlog::details::log_msg& msg, const std::tm&,
              spdlog::memory_buf_t& dest) override {
    static constexpr char kHex[] = "0123456789abcdef";
    for (const char c : std::string_view(msg.payload.data(), msg.payload.size())) {
      const auto u = static_cast<unsigned char>(c);
      if (c == '"' || c == '\\') {
        dest.push_back('\\');
        dest.push_back(c);
      } else if (u < 0x20) {
        const char escaped[] = {'\\', 'u', '0', '0', kHex[u >> 4], kHex[u & 0xf]};
        dest.append(escaped, escaped + sizeof escaped);
      } else {
        dest.push_back(c);
      }
    }
  }
  std::unique_ptr<custom_flag_formatter> clone() const override {
    return std::make_unique<JsonMessageFlag>();
  }
};

}  // namespace

Result<LogFormat> LogFormatFromString(std::string_view text) {
  if (text == "text") return LogFormat::kText;
  if (text == "json") return LogFormat::kJson;
  return Status::InvalidArgument("--log-format = " + std::string(text) + ": must be text or json");
}

void ConfigureLogging(LogFormat format) {
  const bool text = format == LogFormat::kText;
  auto formatter = std::make_unique<spdlog::pattern_formatter>(
      text ? spdlog::pattern_time_type::local : spdlog::pattern_time_type::utc);
  formatter->add_flag<JobFlag>('J', text);
  if (text) {
    formatter->set_pattern("[%Y-%m-%d %H:%M:%S.%e] [%^%l%$] %J%v");
  } else {
    formatter->add_flag<JsonMessageFlag>('E');
    formatter->set_pattern(
        R"({"time":"%Y-%m-%dT%H:%M:%S.%fZ","level":"%l","job":"%J","message":"%E"})");
  }
  spdlog::set_formatter(std::move(formatter));
}

ScopedJobLog::ScopedJobLog(std::string job_id) : previous_(std::move(current_job)) {
  current_job = std::move(job_id);
}

ScopedJobLog::~ScopedJobLog() {
  current_job = std::move(previous_);
}

struct StderrCapture::State {
  int saved_stderr = -1;
  int read_end = -1;
  std::thread reader;
};

std::unique_ptr<StderrCapture> CaptureStderr() {
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0) return nullptr;
  std::unique_ptr<StderrCapture> capture(new StderrCapture());
  capture->state_ = std::make_unique<StderrCapture::State>();
  StderrCapture::State& state = *capture->state_;
  state.saved_stderr = ::dup(STDERR_FILENO);
  ::dup2(fds[1], STDERR_FILENO);
  ::close(fds[1]);
  state.read_end = fds[0];
  state.reader = std::thread([fd = fds[0]] {
    std::string line;
    char buffer[4096];
    while (true) {
      const ssize_t n = ::read(fd, buffer, sizeof buffer);
      if (n <= 0) break;
      for (ssize_t i = 0; i < n; ++i) {
        if (buffer[i] == '\n') {
          if (!line.empty()) spdlog::warn("stderr: {}", line);
          line.clear();
        } else if (line.size() < 4096) {
          line.push_back(buffer[i]);
        }
      }
    }
    if (!line.empty()) spdlog::warn("stderr: {}", line);
  });
  return capture;
}

StderrCapture::~StderrCapture() {
  if (!state_) return;
  // Putting the saved descriptor back closes the pipe's last write end: the reader sees EOF.
  ::dup2(state_->saved_stderr, STDERR_FILENO);
  ::close(state_->saved_stderr);
  if (state_->reader.joinable()) state_->reader.join();
  ::close(state_->read_end);
}

}  // namespace softid::server
