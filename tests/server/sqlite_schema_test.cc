#include "server/store/sqlite_schema.h"

#include <gtest/gtest.h>

#include <set>

#include "server/store/sqlite_job_store.h"
#include "tests/server/temp_dir.h"

namespace softid::server::store {
namespace {

using testing::TempDir;

Result<int64_t> QueryInt(SqliteDatabase& db, const std::string& sql) {
  SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt, db.Prepare(sql));
  SOFTID_ASSIGN_OR_RETURN(const bool has_row, stmt.Step());
  if (!has_row) return Status::Internal("no row for " + sql);
  return stmt.ColumnInt64(0);
}

// A new database gets every table (STRICT), the current user_version and our application_id.
TEST(SqliteSchema, CreatesVersionedStrictSchema) {
  TempDir dir;
  Result<SqliteDatabase> db = SqliteDatabase::Open(dir.path() / "jobs.db");
  ASSERT_TRUE(db.ok());
  ASSERT_TRUE(MigrateSqliteSchema(*db).ok());
  EXPECT_EQ(*ReadSchemaVersion(*db), kSqliteSchemaVersion);
  EXPECT_EQ(*QueryInt(*db, "PRAGMA application_id"), kSqliteApplicationId);

  Result<SqliteStatement> tables = db->Prepare(
      "SELECT name, strict FROM pragma_table_list WHERE schema = 'main' AND name NOT LIKE "
      "'sqlite_%' ORDER BY name");
  ASSERT_TRUE(tables.ok());
  std::set<std::string> names;
  while (*tables->Step()) {
    names.insert(tables->ColumnText(0));
    EXPECT_EQ(tables->ColumnInt64(1), 1) << tables->ColumnText(0) << " is not STRICT";
  }
  EXPECT_EQ(names, (std::set<std::string>{"captures", "checkpoints", "jobs", "progress",
                                          "start_tasks", "tokens"}));

  // STRICT and CHECK constraints hold: a bad state and a non-integer are refused.
  EXPECT_TRUE(db->Exec("INSERT INTO captures (id, request_id, manifest, created_at) VALUES "
                       "('cap-1', NULL, '[]', 0)")
                  .ok());
  const Status bad_state = db->Exec(
      "INSERT INTO jobs (id, capture_id, config, state, created_at) "
      "VALUES ('job-1', 'cap-1', '{}', 'PAUSED', 0)");
  EXPECT_NE(bad_state.message().find("CHECK constraint failed"), std::string::npos)
      << bad_state.message();
  const Status bad_type = db->Exec(
      "INSERT INTO jobs (id, capture_id, config, state, created_at) "
      "VALUES ('job-1', 'cap-1', '{}', 'QUEUED', 'yesterday')");
  EXPECT_NE(bad_type.message().find("cannot store TEXT value in INTEGER column"), std::string::npos)
      << bad_type.message();
  const Status orphan = db->Exec(
      "INSERT INTO jobs (id, capture_id, config, state, created_at) "
      "VALUES ('job-2', 'cap-missing', '{}', 'QUEUED', 0)");
  EXPECT_NE(orphan.message().find("FOREIGN KEY constraint failed"), std::string::npos)
      << orphan.message();
}

// Migrating an up-to-date database changes nothing.
TEST(SqliteSchema, MigrationIsIdempotent) {
  TempDir dir;
  Result<SqliteDatabase> db = SqliteDatabase::Open(dir.path() / "jobs.db");
  ASSERT_TRUE(db.ok());
  ASSERT_TRUE(MigrateSqliteSchema(*db).ok());
  const int64_t objects = *QueryInt(*db, "SELECT count(*) FROM sqlite_schema");
  ASSERT_TRUE(MigrateSqliteSchema(*db).ok());
  EXPECT_EQ(*QueryInt(*db, "SELECT count(*) FROM sqlite_schema"), objects);
  EXPECT_EQ(*ReadSchemaVersion(*db), kSqliteSchemaVersion);
}

// A database written by a newer build is refused, untouched, with a message saying why.
TEST(SqliteSchema, RefusesNewerSchema) {
  TempDir dir;
  const auto path = dir.path() / "jobs.db";
  {
    Result<SqliteDatabase> db = SqliteDatabase::Open(path);
    ASSERT_TRUE(db.ok());
    ASSERT_TRUE(MigrateSqliteSchema(*db).ok());
    ASSERT_TRUE(db->Exec("PRAGMA user_version = " + std::to_string(kSqliteSchemaVersion + 1)).ok());
  }
  const Result<std::unique_ptr<SqliteJobStore>> store = SqliteJobStore::Open(path);
  ASSERT_FALSE(store.ok());
  EXPECT_EQ(store.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(store.status().message(),
            path.string() + ": database schema version " +
                std::to_string(kSqliteSchemaVersion + 1) + " is newer than this build supports (" +
                std::to_string(kSqliteSchemaVersion) +
                "); it was written by a newer softid. Refusing to open it; run a newer "
                "softid-server");
  Result<SqliteDatabase> db = SqliteDatabase::Open(path);
  ASSERT_TRUE(db.ok());
  EXPECT_EQ(*ReadSchemaVersion(*db), kSqliteSchemaVersion + 1);
}

// A version 1 database (before released_attempts and the progress' start columns) is migrated in
// place: its jobs are kept and read with no released attempts.
TEST(SqliteSchema, MigratesVersion1Jobs) {
  TempDir dir;
  const auto path = dir.path() / "jobs.db";
  {
    Result<SqliteDatabase> db = SqliteDatabase::Open(path);
    ASSERT_TRUE(db.ok());
    ASSERT_TRUE(MigrateSqliteSchema(*db).ok());
    // Back to the version 1 layout: versions 2 to 7 only added these columns, tables and indexes.
    ASSERT_TRUE(db->Exec("DROP TABLE start_tasks").ok());
    ASSERT_TRUE(db->Exec("DROP INDEX jobs_by_derived_capture").ok());
    ASSERT_TRUE(db->Exec("ALTER TABLE jobs DROP COLUMN derived_capture_id").ok());
    ASSERT_TRUE(db->Exec("ALTER TABLE captures DROP COLUMN format").ok());
    ASSERT_TRUE(db->Exec("ALTER TABLE jobs DROP COLUMN released_attempts").ok());
    for (const char* column : {"start", "num_starts", "remaining_s"}) {
      ASSERT_TRUE(db->Exec(std::string("ALTER TABLE progress DROP COLUMN ") + column).ok());
    }
    ASSERT_TRUE(db->Exec("DROP INDEX captures_by_owner").ok());
    ASSERT_TRUE(db->Exec("DROP INDEX captures_by_creation").ok());
    ASSERT_TRUE(db->Exec("DROP INDEX captures_by_request").ok());
    ASSERT_TRUE(db->Exec("DROP INDEX jobs_by_request").ok());
    ASSERT_TRUE(db->Exec("ALTER TABLE captures DROP COLUMN station_request_id").ok());
    ASSERT_TRUE(db->Exec("ALTER TABLE jobs DROP COLUMN station_request_id").ok());
    ASSERT_TRUE(db->Exec("DROP INDEX jobs_by_owner").ok());
    ASSERT_TRUE(db->Exec("DROP TABLE tokens").ok());
    ASSERT_TRUE(db->Exec("ALTER TABLE jobs DROP COLUMN owner").ok());
    ASSERT_TRUE(db->Exec("ALTER TABLE captures DROP COLUMN owner").ok());
    ASSERT_TRUE(db->Exec("PRAGMA user_version = 1").ok());
    ASSERT_TRUE(
        db->Exec("INSERT INTO captures VALUES ('cap-0123456789abcdef', NULL, '[]', 0)").ok());
    ASSERT_TRUE(db->Exec("INSERT INTO jobs (id, request_id, capture_id, config, state, attempts, "
                         "created_at) VALUES ('job-0123456789abcdef', 'retry-7', "
                         "'cap-0123456789abcdef', '{}', 'QUEUED', 2, 0)")
                    .ok());
  }
  Result<std::unique_ptr<SqliteJobStore>> store = SqliteJobStore::Open(path);
  ASSERT_TRUE(store.ok()) << store.status().ToString();
  const Result<Job> job = (*store)->GetJob("job-0123456789abcdef");
  ASSERT_TRUE(job.ok()) << job.status().ToString();
  EXPECT_EQ(job->attempts, 2);
  EXPECT_EQ(job->released_attempts, 0);
  EXPECT_EQ(job->owner, "");
  EXPECT_EQ(job->request_id, "retry-7");  // moved to the per-station key (schema 5)
  EXPECT_TRUE(*(*store)->HasJobWithRequestId("retry-7", ""));
  EXPECT_EQ(job->derived_capture_id, "");
  ASSERT_TRUE((*store)->Close().ok());
  Result<SqliteDatabase> db = SqliteDatabase::Open(path);
  ASSERT_TRUE(db.ok());
  EXPECT_EQ(*ReadSchemaVersion(*db), kSqliteSchemaVersion);
  // Schema 6: captures stored before it are captures, not recordings.
  Result<SqliteStatement> format = db->Prepare("SELECT format FROM captures");
  ASSERT_TRUE(format.ok());
  ASSERT_TRUE(*format->Step());
  EXPECT_EQ(format->ColumnText(0), "softid-capture/1");
}

// Some other application's SQLite file is not adopted.
TEST(SqliteSchema, RefusesForeignDatabases) {
  TempDir dir;
  {
    Result<SqliteDatabase> db = SqliteDatabase::Open(dir.path() / "other.db");
    ASSERT_TRUE(db.ok());
    ASSERT_TRUE(db->Exec("CREATE TABLE notes (text TEXT)").ok());
    Result<SqliteDatabase> tagged = SqliteDatabase::Open(dir.path() / "tagged.db");
    ASSERT_TRUE(tagged.ok());
    ASSERT_TRUE(tagged->Exec("PRAGMA application_id = 42").ok());
  }
  const auto untagged = SqliteJobStore::Open(dir.path() / "other.db");
  ASSERT_FALSE(untagged.ok());
  EXPECT_NE(untagged.status().message().find("not a softid job store (it has tables"),
            std::string::npos)
      << untagged.status().message();
  const auto tagged = SqliteJobStore::Open(dir.path() / "tagged.db");
  ASSERT_FALSE(tagged.ok());
  EXPECT_NE(tagged.status().message().find("not a softid job store (application_id 42)"),
            std::string::npos)
      << tagged.status().message();
}

}  // namespace
}  // namespace softid::server::store
