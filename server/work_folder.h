// A private folder for one piece of work (a job, a start task): emptied when taken, removed with
// everything in it when the work ends.
#pragma once

#include <filesystem>
#include <system_error>
#include <utility>

namespace softid::server {

struct WorkFolder {
  explicit WorkFolder(std::filesystem::path p) : path(std::move(p)) {
    std::error_code ignored;
    std::filesystem::remove_all(path, ignored);
  }
  ~WorkFolder() {
    std::error_code ignored;
    std::filesystem::remove_all(path, ignored);
  }
  WorkFolder(const WorkFolder&) = delete;
  WorkFolder& operator=(const WorkFolder&) = delete;

  std::filesystem::path path;
};

}  // namespace softid::server
