#include "server/job_reports.h"

#include <algorithm>
#include <system_error>

#include "server/store/resource_id.h"

namespace softid::server {
namespace {

namespace fs = std::filesystem;

std::string MediaType(const fs::path& file) {
  const std::string extension = file.extension().string();
  if (extension == ".png") return "image/png";
  if (extension == ".json") return "application/json";
  if (extension == ".html") return "text/html";
  return "application/octet-stream";
}

}  // namespace

Status JobReports::Keep(const std::string& job_id, const fs::path& folder) const {
  SOFTID_RETURN_IF_ERROR(store::CheckResourceId(job_id, store::kJobIdPrefix, "job id"));
  std::error_code error;
  fs::create_directories(root_, error);
  const fs::path target = root_ / job_id;
  fs::remove_all(target, error);
  fs::rename(folder, target, error);
  if (error) {
    // Another file system (an unusual layout of the data directory): copy, then drop the source.
    error.clear();
    fs::copy(folder, target, fs::copy_options::recursive, error);
    if (error) {
      std::error_code ignored;
      fs::remove_all(target, ignored);
      return Status::IoError("cannot keep the report " + folder.string() + ": " + error.message());
    }
    fs::remove_all(folder, error);
  }
  return Status::Ok();
}

std::vector<ReportFile> JobReports::List(const std::string& job_id) const {
  std::vector<ReportFile> out;
  if (!store::CheckResourceId(job_id, store::kJobIdPrefix, "job id").ok()) return out;
  const fs::path folder = root_ / job_id;
  std::error_code error;
  for (fs::recursive_directory_iterator it(folder, error), end; !error && it != end;
       it.increment(error)) {
    // symlink_status: a link is never followed out of the folder.
    if (!fs::is_regular_file(it->symlink_status())) continue;
    const int64_t size = static_cast<int64_t>(it->file_size(error));
    if (error) break;
    out.push_back(
        {it->path().lexically_relative(folder).generic_string(), MediaType(it->path()), size});
  }
  std::sort(out.begin(), out.end(),
            [](const ReportFile& a, const ReportFile& b) { return a.name < b.name; });
  return out;
}

Result<std::ifstream> JobReports::Open(const std::string& job_id, const std::string& name) const {
  const std::vector<ReportFile> files = List(job_id);
  const bool listed = std::any_of(files.begin(), files.end(),
                                  [&](const ReportFile& file) { return file.name == name; });
  if (!listed) {
    return Status::NotFound("job " + job_id + " has no report file \"" + name + "\"");
  }
  std::ifstream in(root_ / job_id / name, std::ios::binary);
  if (!in) return Status::IoError("job " + job_id + ": cannot read report file \"" + name + "\"");
  return in;
}

void JobReports::Remove(const std::string& job_id) const {
  if (!store::CheckResourceId(job_id, store::kJobIdPrefix, "job id").ok()) return;
  std::error_code ignored;
  fs::remove_all(root_ / job_id, ignored);
}

}  // namespace softid::server
