// Log lines name the job a thread works on, the JSON format is one valid object per line even
// for messages with quotes and control characters, and stderr writes become log lines.
#include "server/log_context.h"

#include <gtest/gtest.h>
#include <spdlog/sinks/ostream_sink.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

namespace softid::server {
namespace {

class LogContextTest : public ::testing::Test {
 protected:
  void SetUp() override {
    previous_ = spdlog::default_logger();
    auto sink = std::make_shared<spdlog::sinks::ostream_sink_mt>(out_);
    spdlog::set_default_logger(std::make_shared<spdlog::logger>("test", sink));
  }
  void TearDown() override { spdlog::set_default_logger(previous_); }

  std::vector<std::string> Lines() const {
    std::vector<std::string> lines;
    std::istringstream in(out_.str());
    for (std::string line; std::getline(in, line);) lines.push_back(line);
    return lines;
  }

  std::ostringstream out_;
  std::shared_ptr<spdlog::logger> previous_;
};

TEST_F(LogContextTest, JsonLinesCarryTheJobOfTheirThread) {
  ConfigureLogging(LogFormat::kJson);
  spdlog::info("before");
  {
    const ScopedJobLog job("job-0123456789abcdef");
    spdlog::warn("time step: \"quoted\"\tand\nnew line \\ done");
  }
  spdlog::info("after");
  const std::vector<std::string> lines = Lines();
  ASSERT_EQ(lines.size(), 3u) << out_.str();
  const nlohmann::json before = nlohmann::json::parse(lines[0]);
  const nlohmann::json inside = nlohmann::json::parse(lines[1]);
  const nlohmann::json after = nlohmann::json::parse(lines[2]);
  EXPECT_EQ(before["job"], "");
  EXPECT_EQ(inside["job"], "job-0123456789abcdef");
  EXPECT_EQ(inside["level"], "warning");
  EXPECT_EQ(inside["message"], "time step: \"quoted\"\tand\nnew line \\ done");
  EXPECT_EQ(after["job"], "");
  EXPECT_NE(before["time"].get<std::string>().find('T'), std::string::npos);
}

TEST_F(LogContextTest, TextLinesNameTheJob) {
  ConfigureLogging(LogFormat::kText);
  {
    const ScopedJobLog job("job-0123456789abcdef");
    spdlog::info("iteration 3");
  }
  EXPECT_NE(out_.str().find("[job-0123456789abcdef] iteration 3"), std::string::npos) << out_.str();
  EXPECT_FALSE(LogFormatFromString("xml").ok());
}

TEST_F(LogContextTest, StderrWritesBecomeLogLines) {
  ConfigureLogging(LogFormat::kText);
  {
    std::unique_ptr<StderrCapture> capture = CaptureStderr();
    ASSERT_NE(capture, nullptr);
    const char text[] = "libpng warning: iCCP: known incorrect sRGB profile\n";
    ASSERT_EQ(::write(STDERR_FILENO, text, sizeof text - 1), static_cast<ssize_t>(sizeof text - 1));
  }  // restores stderr and drains the pipe
  EXPECT_NE(out_.str().find("stderr: libpng warning: iCCP: known incorrect sRGB profile"),
            std::string::npos)
      << out_.str();
}

}  // namespace
}  // namespace softid::server
