#include "server/store/sqlite_database.h"

#include <gtest/gtest.h>

#include <cmath>

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

// Opening applies WAL, the chosen synchronous level, busy_timeout and foreign keys.
TEST(SqliteDatabase, OpenAppliesConnectionSettings) {
  TempDir dir;
  SqliteOptions options;
  options.sync_mode = SyncMode::kFull;
  options.busy_timeout = std::chrono::milliseconds(1234);
  Result<SqliteDatabase> db = SqliteDatabase::Open(dir.path() / "a.db", options);
  ASSERT_TRUE(db.ok()) << db.status().ToString();
  {
    Result<SqliteStatement> stmt = db->Prepare("PRAGMA journal_mode");
    ASSERT_TRUE(stmt.ok());
    ASSERT_TRUE(*stmt->Step());
    EXPECT_EQ(stmt->ColumnText(0), "wal");
  }
  EXPECT_EQ(*QueryInt(*db, "PRAGMA synchronous"), 2);  // FULL
  EXPECT_EQ(*QueryInt(*db, "PRAGMA busy_timeout"), 1234);
  EXPECT_EQ(*QueryInt(*db, "PRAGMA foreign_keys"), 1);

  Result<SqliteDatabase> normal = SqliteDatabase::Open(dir.path() / "b.db");
  ASSERT_TRUE(normal.ok());
  EXPECT_EQ(*QueryInt(*normal, "PRAGMA synchronous"), 1);  // NORMAL
}

// kMustExist does not create a database: a missing file is NotFound naming the path.
TEST(SqliteDatabase, MustExistReportsMissingFile) {
  TempDir dir;
  SqliteOptions options;
  options.open_mode = OpenMode::kMustExist;
  const Result<SqliteDatabase> db = SqliteDatabase::Open(dir.path() / "missing.db", options);
  ASSERT_FALSE(db.ok());
  EXPECT_EQ(db.status().code(), StatusCode::kNotFound);
  EXPECT_NE(db.status().message().find("missing.db: cannot open database"), std::string::npos)
      << db.status().message();
  EXPECT_FALSE(std::filesystem::exists(dir.path() / "missing.db"));
}

// Errors carry the database path, the action, the SQL and SQLite's message.
TEST(SqliteDatabase, ErrorsNameSqlAndPath) {
  TempDir dir;
  Result<SqliteDatabase> db = SqliteDatabase::Open(dir.path() / "e.db");
  ASSERT_TRUE(db.ok());
  const Result<SqliteStatement> bad = db->Prepare("SELEKT 1");
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kInternal);
  EXPECT_EQ(bad.status().message(),
            (dir.path() / "e.db").string() + ": prepare `SELEKT 1`: near \"SELEKT\": syntax error");

  ASSERT_TRUE(db->Exec("CREATE TABLE t (a INTEGER PRIMARY KEY) STRICT").ok());
  ASSERT_TRUE(db->Exec("INSERT INTO t VALUES (1)").ok());
  Result<SqliteStatement> insert = db->Prepare("INSERT INTO t VALUES (?1)");
  ASSERT_TRUE(insert.ok());
  ASSERT_TRUE(insert->Bind(1).ok());
  const Status duplicate = insert->Run();
  EXPECT_NE(
      duplicate.message().find("step `INSERT INTO t VALUES (?1)`: UNIQUE constraint failed: t.a"),
      std::string::npos)
      << duplicate.message();
}

// Bound values read back unchanged; NaN and std::nullopt are NULL.
TEST(SqliteStatement, BindAndReadBack) {
  TempDir dir;
  Result<SqliteDatabase> db = SqliteDatabase::Open(dir.path() / "b.db");
  ASSERT_TRUE(db.ok());
  ASSERT_TRUE(
      db->Exec("CREATE TABLE t (i INTEGER, d REAL, s TEXT, n TEXT, o INTEGER) STRICT").ok());
  Result<SqliteStatement> insert = db->Prepare("INSERT INTO t VALUES (?1, ?2, ?3, ?4, ?5)");
  ASSERT_TRUE(insert.ok());
  const std::optional<int64_t> none;
  ASSERT_TRUE(insert->Bind(int64_t{1} << 40, 2.5, std::string("text"), std::nullopt, none).ok());
  ASSERT_TRUE(insert->Run().ok());
  insert->Reset();
  ASSERT_TRUE(insert->Bind(-3, std::nan(""), "", std::optional<std::string>("x"), 7).ok());
  ASSERT_TRUE(insert->Run().ok());

  Result<SqliteStatement> select = db->Prepare("SELECT i, d, s, n, o FROM t ORDER BY rowid");
  ASSERT_TRUE(select.ok());
  ASSERT_TRUE(*select->Step());
  EXPECT_EQ(select->ColumnInt64(0), int64_t{1} << 40);
  EXPECT_EQ(select->ColumnDouble(1), 2.5);
  EXPECT_EQ(select->ColumnText(2), "text");
  EXPECT_TRUE(select->IsNull(3));
  EXPECT_EQ(select->ColumnOptionalInt64(4), std::nullopt);
  ASSERT_TRUE(*select->Step());
  EXPECT_EQ(select->ColumnInt64(0), -3);
  EXPECT_TRUE(select->IsNull(1));
  EXPECT_TRUE(std::isnan(select->ColumnDouble(1)));
  EXPECT_EQ(select->ColumnText(2), "");
  EXPECT_FALSE(select->IsNull(2));
  EXPECT_EQ(select->ColumnOptionalText(3), "x");
  EXPECT_EQ(select->ColumnOptionalInt64(4), 7);
  EXPECT_FALSE(*select->Step());
}

// A transaction rolls back when dropped uncommitted, and keeps its writes once committed.
TEST(SqliteTransaction, RollsBackUnlessCommitted) {
  TempDir dir;
  Result<SqliteDatabase> db = SqliteDatabase::Open(dir.path() / "t.db");
  ASSERT_TRUE(db.ok());
  ASSERT_TRUE(db->Exec("CREATE TABLE t (a INTEGER) STRICT").ok());
  {
    Result<SqliteTransaction> transaction = SqliteTransaction::Begin(*db);
    ASSERT_TRUE(transaction.ok());
    ASSERT_TRUE(db->Exec("INSERT INTO t VALUES (1)").ok());
    EXPECT_FALSE(db->autocommit());
  }
  EXPECT_TRUE(db->autocommit());
  EXPECT_EQ(*QueryInt(*db, "SELECT count(*) FROM t"), 0);
  {
    Result<SqliteTransaction> transaction = SqliteTransaction::Begin(*db);
    ASSERT_TRUE(transaction.ok());
    ASSERT_TRUE(db->Exec("INSERT INTO t VALUES (2)").ok());
    ASSERT_TRUE(transaction->Commit().ok());
    EXPECT_EQ(transaction->Commit().code(), StatusCode::kFailedPrecondition);
  }
  EXPECT_EQ(*QueryInt(*db, "SELECT count(*) FROM t"), 1);
}

// BEGIN IMMEDIATE takes the write lock: a second connection's BEGIN IMMEDIATE waits out its
// busy_timeout and then fails with IoError, while plain reads still work (WAL).
TEST(SqliteTransaction, ImmediateTakesTheWriteLock) {
  TempDir dir;
  Result<SqliteDatabase> first = SqliteDatabase::Open(dir.path() / "l.db");
  ASSERT_TRUE(first.ok());
  ASSERT_TRUE(first->Exec("CREATE TABLE t (a INTEGER) STRICT").ok());
  SqliteOptions impatient;
  impatient.busy_timeout = std::chrono::milliseconds(50);
  Result<SqliteDatabase> second = SqliteDatabase::Open(dir.path() / "l.db", impatient);
  ASSERT_TRUE(second.ok());

  Result<SqliteTransaction> held = SqliteTransaction::Begin(*first);
  ASSERT_TRUE(held.ok());
  const Result<SqliteTransaction> blocked = SqliteTransaction::Begin(*second);
  ASSERT_FALSE(blocked.ok());
  EXPECT_EQ(blocked.status().code(), StatusCode::kIoError);
  EXPECT_NE(blocked.status().message().find("database is locked"), std::string::npos)
      << blocked.status().message();
  EXPECT_EQ(*QueryInt(*second, "SELECT count(*) FROM t"), 0);
  ASSERT_TRUE(held->Commit().ok());
  EXPECT_TRUE(SqliteTransaction::Begin(*second).ok());
}

// Close refuses while a statement is alive (a leak would otherwise go unnoticed), then succeeds.
TEST(SqliteDatabase, CloseReportsLiveStatements) {
  TempDir dir;
  Result<SqliteDatabase> db = SqliteDatabase::Open(dir.path() / "c.db");
  ASSERT_TRUE(db.ok());
  {
    Result<SqliteStatement> stmt = db->Prepare("SELECT 1");
    ASSERT_TRUE(stmt.ok());
    const Status closed = db->Close();
    EXPECT_EQ(closed.code(), StatusCode::kInternal);
    EXPECT_NE(closed.message().find("still alive"), std::string::npos);
    EXPECT_TRUE(db->is_open());
  }
  EXPECT_TRUE(db->Close().ok());
  EXPECT_FALSE(db->is_open());
  EXPECT_TRUE(db->Close().ok());
  EXPECT_EQ(db->Exec("SELECT 1").code(), StatusCode::kFailedPrecondition);
}

}  // namespace
}  // namespace softid::server::store
