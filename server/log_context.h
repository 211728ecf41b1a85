// How the server's log lines look and what they carry. Every line a worker thread writes while
// it runs a job, including the core's own lines (time-step choice, warnings), names the job; the
// format is text for people or one JSON object per line for log collectors. Other libraries'
// writes to stderr (libpng's warnings through OpenCV) are captured and logged as lines of their
// own instead of interleaving raw with the log.
#pragma once

#include <memory>
#include <string>
#include <string_view>

#include "core/common/status.h"

namespace softid::server {

enum class LogFormat { kText, kJson };
// "text" | "json"; InvalidArgument naming --log-format otherwise.
Result<LogFormat> LogFormatFromString(std::string_view text);

// Installs the pattern of `format` on the default logger (stdout). Call once from main.
void ConfigureLogging(LogFormat format);

// While alive, lines written by this thread carry `job_id` ("job" in JSON, "[job-...]" in text).
class ScopedJobLog {
 public:
  explicit ScopedJobLog(std::string job_id);
  ~ScopedJobLog();
  ScopedJobLog(const ScopedJobLog&) = delete;
  ScopedJobLog& operator=(const ScopedJobLog&) = delete;

 private:
  std::string previous_;
};

// Redirects file descriptor 2 into a pipe whose lines are logged as warnings ("stderr: ...")
// by a background thread; stops (restoring stderr) when the returned object is destroyed.
class StderrCapture;
std::unique_ptr<StderrCapture> CaptureStderr();

class StderrCapture {
 public:
  ~StderrCapture();
  StderrCapture(const StderrCapture&) = delete;
  StderrCapture& operator=(const StderrCapture&) = delete;

 private:
  friend std::unique_ptr<StderrCapture> CaptureStderr();
  StderrCapture() = default;
  struct State;
  std::unique_ptr<State> state_;
};

}  // namespace softid::server
