// The sweep of blobs no capture lists: all of them at a single node's start; only those older than
// the age given on a shared data directory (a younger one may be an upload about to commit); never
// one a capture lists.
#include "server/orphan_blobs.h"

#include <gtest/gtest.h>
#include <spdlog/sinks/null_sink.h>

#include <filesystem>

#include "server/store/sqlite_job_store.h"
#include "tests/server/temp_dir.h"

namespace softid::server {
namespace {

namespace fs = std::filesystem;
using store::testing::TempDir;

TEST(OrphanBlobs, OnlyUnlistedBlobsOlderThanTheAgeGo) {
  TempDir dir;
  Result<std::unique_ptr<store::SqliteJobStore>> jobs =
      store::SqliteJobStore::Open(dir.path() / "softid.db");
  ASSERT_TRUE(jobs.ok()) << jobs.status().ToString();
  Result<store::BlobStore> blobs = store::BlobStore::Open(dir.path());
  ASSERT_TRUE(blobs.ok()) << blobs.status().ToString();
  const std::string listed = *blobs->Put("listed and old");
  const std::string old_orphan = *blobs->Put("old orphan");
  const std::string young_orphan = *blobs->Put("young orphan");
  ASSERT_TRUE((*jobs)->CreateCapture({{"capture.json", listed, 14}}, "").ok());
  for (const std::string& sha256 : {listed, old_orphan}) {
    fs::last_write_time(*blobs->PathOf(sha256),
                        fs::file_time_type::clock::now() - std::chrono::hours(2));
  }
  const auto log =
      std::make_shared<spdlog::logger>("test", std::make_shared<spdlog::sinks::null_sink_mt>());

  EXPECT_EQ(RemoveOrphanBlobs(**jobs, *blobs, std::chrono::hours(1), log), 1);
  EXPECT_TRUE(blobs->Has(listed));
  EXPECT_FALSE(blobs->Has(old_orphan));
  EXPECT_TRUE(blobs->Has(young_orphan));
  // At a single node's start every orphan goes.
  EXPECT_EQ(RemoveOrphanBlobs(**jobs, *blobs, std::chrono::seconds(0), log), 1);
  EXPECT_FALSE(blobs->Has(young_orphan));
  EXPECT_TRUE(blobs->Has(listed));
}

}  // namespace
}  // namespace softid::server
