// The kept reports of finished jobs: moved in, listed with sizes and media types, served only by
// the names listed (never a path out of the job's folder, never through a link), removed.
#include "server/job_reports.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "tests/server/temp_dir.h"

namespace softid::server {
namespace {

namespace fs = std::filesystem;
using store::testing::TempDir;

constexpr char kJob[] = "job-0123456789abcdef";

void WriteFile(const fs::path& path, const std::string& bytes) {
  fs::create_directories(path.parent_path());
  std::ofstream(path, std::ios::binary) << bytes;
}

TEST(JobReports, KeepListOpenRemove) {
  TempDir dir;
  const JobReports reports(dir.path() / "reports");
  const fs::path drawn = dir.path() / "work" / "report";
  WriteFile(drawn / "surface_overlay.png", "png bytes");
  WriteFile(drawn / "diagnosis" / "residual_per_frame.png", "more png bytes");
  WriteFile(dir.path() / "secret.txt", "not the report's");
  fs::create_symlink(dir.path() / "secret.txt", drawn / "link.png");
  ASSERT_TRUE(reports.Keep(kJob, drawn).ok());
  EXPECT_FALSE(fs::exists(drawn));

  const std::vector<ReportFile> files = reports.List(kJob);
  ASSERT_EQ(files.size(), 2u);  // the link is no file of the report
  EXPECT_EQ(files[0].name, "diagnosis/residual_per_frame.png");
  EXPECT_EQ(files[0].size_bytes, 14);
  EXPECT_EQ(files[1].name, "surface_overlay.png");
  EXPECT_EQ(files[1].media_type, "image/png");

  Result<std::ifstream> in = reports.Open(kJob, "surface_overlay.png");
  ASSERT_TRUE(in.ok()) << in.status().ToString();
  std::string bytes((std::istreambuf_iterator<char>(*in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(bytes, "png bytes");
  for (const std::string& name :
       {"link.png", "../../secret.txt", "/etc/passwd", "", "diagnosis", "./surface_overlay.png"}) {
    EXPECT_EQ(reports.Open(kJob, name).status().code(), StatusCode::kNotFound) << name;
  }
  reports.Remove(kJob);
  EXPECT_TRUE(reports.List(kJob).empty());
  EXPECT_TRUE(fs::exists(dir.path() / "secret.txt"));
}

TEST(JobReports, RefusesMalformedJobIdsAndReplacesAnEarlierReport) {
  TempDir dir;
  const JobReports reports(dir.path() / "reports");
  WriteFile(dir.path() / "a" / "old.png", "old");
  EXPECT_EQ(reports.Keep("../job-0123456789abcdef", dir.path() / "a").code(),
            StatusCode::kInvalidArgument);
  EXPECT_TRUE(reports.List("..").empty());
  ASSERT_TRUE(reports.Keep(kJob, dir.path() / "a").ok());
  WriteFile(dir.path() / "b" / "new.png", "new");
  ASSERT_TRUE(reports.Keep(kJob, dir.path() / "b").ok());
  const std::vector<ReportFile> files = reports.List(kJob);
  ASSERT_EQ(files.size(), 1u);
  EXPECT_EQ(files[0].name, "new.png");
}

}  // namespace
}  // namespace softid::server
