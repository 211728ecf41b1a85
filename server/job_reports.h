// The reports of finished jobs: a folder per job under <data>/reports holding the pictures its
// runner drew (core/diagnosis/fit_report.h, and the diagnosis' plots when it ran), served file by
// file (DownloadArtifact) and removed with the job. A file is served only when the job's folder
// lists it, so no name a caller sends can reach outside that folder.
#pragma once

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "core/common/status.h"

namespace softid::server {

struct ReportFile {
  std::string name;        // relative '/'-separated path inside the job's report
  std::string media_type;  // "image/png", "application/json", ...
  int64_t size_bytes = 0;
};

class JobReports {
 public:
  // `root` is created on the first Keep; it must be on the file system of the workers' folders
  // so that Keep moves a report in without copying it.
  explicit JobReports(std::filesystem::path root) : root_(std::move(root)) {}

  // Moves `folder` (a finished job's report) in as the job's report, replacing an earlier one.
  // InvalidArgument for a malformed job id; IoError naming the folder when it cannot be moved.
  Status Keep(const std::string& job_id, const std::filesystem::path& folder) const;
  // The job's files sorted by name (regular files only); empty when it has none.
  std::vector<ReportFile> List(const std::string& job_id) const;
  // The job's file `name` for reading. NotFound unless List(job_id) names it.
  Result<std::ifstream> Open(const std::string& job_id, const std::string& name) const;
  // Removes the job's report; nothing when it has none.
  void Remove(const std::string& job_id) const;

 private:
  std::filesystem::path root_;
};

}  // namespace softid::server
