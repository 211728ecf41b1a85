// A uniquely named temporary folder for one test, removed with its contents on destruction.
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <filesystem>
#include <string>

namespace softid::capture::testing {

class TempDir {
 public:
  TempDir() {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    const std::string name = info == nullptr
                                 ? std::string("no_test")
                                 : std::string(info->test_suite_name()) + "_" + info->name();
    path_ = std::filesystem::temp_directory_path() /
            ("softid_capture_" + name + "_" + std::to_string(::getpid()) + "_" +
             std::to_string(counter_++));
    std::filesystem::remove_all(path_);
    std::filesystem::create_directories(path_);
  }
  ~TempDir() {
    std::error_code error;
    std::filesystem::remove_all(path_, error);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;

  const std::filesystem::path& path() const { return path_; }

 private:
  static inline std::atomic<int> counter_{0};  // tells apart several folders in one test
  std::filesystem::path path_;
};

}  // namespace softid::capture::testing
