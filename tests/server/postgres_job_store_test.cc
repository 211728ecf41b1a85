// What only the PostgreSQL store has (the shared contract is job_store_conformance_test.cc): its
// URL handling, the libpq layer's values, the schema's versioning, its pool of connections and
// its reconnection. Suites named Postgres* need the server tests/server/with_postgres.sh starts;
// StoreUrl needs none.
#include "server/store/postgres_job_store.h"

#include <gtest/gtest.h>

#include <cmath>
#include <thread>
#include <vector>

#include "server/store/open_store.h"
#include "server/store/postgres_connection.h"
#include "server/store/postgres_schema.h"
#include "server/store/sha256.h"
#include "tests/server/postgres_test_server.h"
#include "tests/server/temp_dir.h"

namespace softid::server::store {
namespace {

using testing::TempDir;

TEST(StoreUrl, RedactsThePassword) {
  EXPECT_EQ(RedactPostgresUrl("postgresql://softid:s3cret@db:5432/softid"),
            "postgresql://softid:****@db:5432/softid");
  EXPECT_EQ(RedactPostgresUrl("postgres://db/softid?sslmode=require&password=s3cret&x=1"),
            "postgres://db/softid?sslmode=require&password=****&x=1");
  EXPECT_EQ(RedactPostgresUrl("postgresql://softid@db/softid"), "postgresql://softid@db/softid");
  // An '@' after the host is no password separator.
  EXPECT_EQ(RedactPostgresUrl("postgresql://db/a@b"), "postgresql://db/a@b");
  EXPECT_TRUE(IsPostgresUrl("postgresql://db/softid"));
  EXPECT_TRUE(IsPostgresUrl("postgres://db/softid"));
  EXPECT_FALSE(IsPostgresUrl("sqlite:///var/lib/softid"));
}

// Nothing listens on port 1: the error names the URL without its password, and says why.
TEST(StoreUrl, UnreachableServerNamesTheFlagAndUrl) {
  const Result<OpenedStore> store =
      OpenStore("postgresql://softid:s3cret@127.0.0.1:1/softid", TempDir().path());
  ASSERT_FALSE(store.ok());
  EXPECT_EQ(store.status().code(), StatusCode::kIoError);
  const std::string& message = store.status().message();
  EXPECT_EQ(
      message.rfind("--store postgresql://softid:****@127.0.0.1:1/softid: cannot connect: ", 0), 0u)
      << message;
  EXPECT_NE(message.find("Connection refused"), std::string::npos) << message;
  EXPECT_EQ(message.find("s3cret"), std::string::npos) << message;
}

TEST(StoreUrl, MalformedUrlIsInvalidArgument) {
  const Result<PostgresConnection> connection =
      PostgresConnection::Connect("postgresql://softid:s3cret@db/softid?no_such_option=1");
  ASSERT_FALSE(connection.ok());
  EXPECT_EQ(connection.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(connection.status().message(),
            "postgresql://softid:****@db/softid?no_such_option=1: not a valid PostgreSQL URL: "
            "invalid URI query parameter: \"no_such_option\"");

  const Result<OpenedStore> other = OpenStore("mysql://root:pw@db/softid", TempDir().path());
  ASSERT_FALSE(other.ok());
  EXPECT_EQ(other.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(other.status().message(),
            "--store mysql://root:****@db/softid: must be a postgresql:// URL (leave --store out "
            "for the SQLite database under --data)");
}

// A database of its own per test, dropped at the end.
class PostgresJobStoreTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (const std::optional<std::string> why = testing::PostgresUnavailable()) {
      GTEST_SKIP() << *why;
    }
    Result<std::string> url = testing::TestDatabase(key_.path().string());
    ASSERT_TRUE(url.ok()) << url.status().ToString();
    url_ = *url;
  }
  void TearDown() override {
    if (url_.empty()) return;
    const Status dropped = testing::DropTestDatabase(key_.path().string());
    EXPECT_TRUE(dropped.ok()) << dropped.ToString();
  }

  PostgresConnection Connect() {
    Result<PostgresConnection> connection = PostgresConnection::Connect(url_);
    EXPECT_TRUE(connection.ok()) << connection.status().ToString();
    return std::move(connection).value();
  }

  TempDir key_;  // names the database
  std::string url_;
};

// Parameters travel apart from the SQL and come back as they went: doubles to the last bit, NaN
// as NULL, infinities, text with quotes; bytes that PostgreSQL text cannot hold become U+FFFD.
TEST_F(PostgresJobStoreTest, ValuesRoundTrip) {
  PostgresConnection db = Connect();
  Result<PostgresResult> rows = db.Query(
      "SELECT $1::float8, $2::float8, $3::float8, $4::float8, $5::text, $6::text, "
      "$7::bigint, $8::boolean",
      0.1 + 0.2, std::nan(""), -INFINITY, 4.9e-324, "it's; DROP TABLE x; --",
      std::string("bad \xff byte and \0 nul", 20), int64_t{-9'007'199'254'740'993}, true);
  ASSERT_TRUE(rows.ok()) << rows.status().ToString();
  EXPECT_EQ(rows->Double(0, 0), 0.1 + 0.2);
  EXPECT_TRUE(rows->IsNull(0, 1));
  EXPECT_TRUE(std::isnan(rows->Double(0, 1)));
  EXPECT_EQ(rows->Double(0, 2), -INFINITY);
  EXPECT_EQ(rows->Double(0, 3), 4.9e-324);
  EXPECT_EQ(rows->Text(0, 4), "it's; DROP TABLE x; --");
  EXPECT_EQ(rows->Text(0, 5), "bad \xEF\xBF\xBD byte and \xEF\xBF\xBD nul");
  EXPECT_EQ(rows->Int64(0, 6), -9'007'199'254'740'993);
  EXPECT_TRUE(rows->Bool(0, 7));

  const Result<PostgresResult> bad = db.Query("SELECT * FROM no_such_table WHERE id = $1", "x");
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kInternal);
  EXPECT_NE(bad.status().message().find("relation \"no_such_table\" does not exist"),
            std::string::npos)
      << bad.status().message();
  EXPECT_NE(bad.status().message().find("(SQLSTATE 42P01)"), std::string::npos);
  EXPECT_EQ(db.last_sqlstate(), "42P01");
}

// Opening migrates a new database once; reopening finds the version and changes nothing.
TEST_F(PostgresJobStoreTest, SchemaIsVersioned) {
  ASSERT_TRUE(PostgresJobStore::Open(url_).ok());
  PostgresConnection db = Connect();
  EXPECT_EQ(*ReadPostgresSchemaVersion(db), kPostgresSchemaVersion);
  Result<std::unique_ptr<PostgresJobStore>> again = PostgresJobStore::Open(url_);
  ASSERT_TRUE(again.ok()) << again.status().ToString();
  EXPECT_EQ(*ReadPostgresSchemaVersion(db), kPostgresSchemaVersion);
}

// A schema written by a newer build is refused, not modified.
TEST_F(PostgresJobStoreTest, RefusesANewerSchema) {
  ASSERT_TRUE(PostgresJobStore::Open(url_).ok());
  PostgresConnection db = Connect();
  ASSERT_TRUE(db.Exec("UPDATE softid_schema_version SET version = 99").ok());
  const Result<std::unique_ptr<PostgresJobStore>> store = PostgresJobStore::Open(url_);
  ASSERT_FALSE(store.ok());
  EXPECT_EQ(store.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(store.status().message().find(
                "database schema version 99 is newer than this build supports (" +
                std::to_string(kPostgresSchemaVersion) + ")"),
            std::string::npos)
      << store.status().message();
  EXPECT_EQ(*ReadPostgresSchemaVersion(db), 99);
}

// A database that holds someone else's tables is not taken over.
TEST_F(PostgresJobStoreTest, RefusesADatabaseOfAnotherApplication) {
  PostgresConnection db = Connect();
  ASSERT_TRUE(db.Exec("CREATE TABLE invoices (id INTEGER PRIMARY KEY)").ok());
  const Result<std::unique_ptr<PostgresJobStore>> store = PostgresJobStore::Open(url_);
  ASSERT_FALSE(store.ok());
  EXPECT_EQ(store.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(store.status().message().find("not a softid job store (its schema has 1 table(s)"),
            std::string::npos)
      << store.status().message();
  EXPECT_EQ(*ReadPostgresSchemaVersion(db), 0);
}

// Servers starting together on a new database: one migrates, the others wait and find it done.
TEST_F(PostgresJobStoreTest, ConcurrentOpensMigrateOnce) {
  constexpr int kNumThreads = 4;
  std::vector<Status> opened(kNumThreads);
  std::vector<std::thread> threads;
  for (int t = 0; t < kNumThreads; ++t) {
    threads.emplace_back([&, t] { opened[t] = PostgresJobStore::Open(url_).status(); });
  }
  for (std::thread& thread : threads) thread.join();
  for (const Status& status : opened) EXPECT_TRUE(status.ok()) << status.ToString();
  PostgresConnection db = Connect();
  EXPECT_EQ(*ReadPostgresSchemaVersion(db), kPostgresSchemaVersion);
}

// More threads than connections: the calls wait for a connection and all succeed.
TEST_F(PostgresJobStoreTest, ThreadsShareASmallPool) {
  PostgresJobStoreOptions options;
  options.max_connections = 1;
  Result<std::unique_ptr<PostgresJobStore>> store = PostgresJobStore::Open(url_, options);
  ASSERT_TRUE(store.ok()) << store.status().ToString();
  Result<Capture> capture =
      (*store)->CreateCapture({{"capture.json", Sha256::Hex("pool"), 10}}, "");
  ASSERT_TRUE(capture.ok()) << capture.status().ToString();
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&] {
      for (int i = 0; i < 5; ++i) {
        const Result<Job> job = (*store)->CreateJob(capture->id, nlohmann::json::object(), "");
        EXPECT_TRUE(job.ok()) << job.status().ToString();
      }
    });
  }
  for (std::thread& thread : threads) thread.join();
  EXPECT_EQ(*(*store)->CountJobs(JobState::kQueued), 20);
  options.max_connections = 0;
  EXPECT_EQ(PostgresJobStore::Open(url_, options).status().message(),
            "max_connections = 0: must be at least 1");
}

// The server closing the store's connections (a restart, an administrator) costs nothing but a
// reconnection: the next call succeeds on a new connection.
TEST_F(PostgresJobStoreTest, ReconnectsAfterTheServerClosedItsConnections) {
  Result<std::unique_ptr<PostgresJobStore>> store = PostgresJobStore::Open(url_);
  ASSERT_TRUE(store.ok()) << store.status().ToString();
  ASSERT_TRUE((*store)->CountJobs(std::nullopt).ok());
  PostgresConnection admin = Connect();
  Result<PostgresResult> killed = admin.Query(
      "SELECT count(pg_terminate_backend(pid)) FROM pg_stat_activity "
      "WHERE datname = current_database() AND pid <> pg_backend_pid()");
  ASSERT_TRUE(killed.ok()) << killed.status().ToString();
  EXPECT_GE(killed->Int64(0, 0), 1);
  const Result<int64_t> count = (*store)->CountJobs(std::nullopt);
  ASSERT_TRUE(count.ok()) << count.status().ToString();
  EXPECT_EQ(*count, 0);
}

// The store needs no superuser: a role that owns its database (and so, from PostgreSQL 15 on, the
// public schema) creates the tables and runs a job through its life.
TEST_F(PostgresJobStoreTest, RunsAsAnOrdinaryRole) {
  const std::string role = testing::TestDatabaseName(key_.path().string() + "/role");
  const std::string database = testing::TestDatabaseName(key_.path().string());
  PostgresConnection admin = Connect();
  // Identifiers cannot be parameters; both are "softid_t_" and hex digits.
  ASSERT_TRUE(admin.Exec("CREATE ROLE " + role + " LOGIN NOSUPERUSER").ok());
  ASSERT_TRUE(admin.Exec("ALTER DATABASE " + database + " OWNER TO " + role).ok());
  const size_t user_start = url_.find("://") + 3;
  const std::string url =
      url_.substr(0, user_start) + role + url_.substr(url_.find('@', user_start));
  {
    Result<std::unique_ptr<PostgresJobStore>> store = PostgresJobStore::Open(url);
    ASSERT_TRUE(store.ok()) << store.status().ToString();
    Result<Capture> capture =
        (*store)->CreateCapture({{"capture.json", Sha256::Hex("role"), 10}}, "take-1", "lab-1");
    ASSERT_TRUE(capture.ok()) << capture.status().ToString();
    Result<std::optional<Job>> job =
        (*store)->CreateJobBounded(capture->id, nlohmann::json::object(), "job-1", 5, "lab-1");
    ASSERT_TRUE(job.ok() && job->has_value()) << job.status().ToString();
    Result<std::optional<Job>> claimed =
        (*store)->ClaimNextJob("worker-1", std::chrono::seconds(30));
    ASSERT_TRUE(claimed.ok() && claimed->has_value()) << claimed.status().ToString();
    ASSERT_TRUE((*store)->CompleteJob((**job).id, {{"ok", true}}).ok());
    EXPECT_EQ((*store)->GetJob((**job).id)->state, JobState::kSucceeded);
  }
  // The database goes first (a role that owns one cannot be dropped), and with it the connection
  // `admin` had to it.
  ASSERT_TRUE(testing::DropTestDatabase(key_.path().string()).ok());
  Result<PostgresConnection> server = PostgresConnection::Connect(*testing::TestPostgresUrl());
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  const Status dropped = server->Exec("DROP ROLE " + role);
  EXPECT_TRUE(dropped.ok()) << dropped.ToString();
}

}  // namespace
}  // namespace softid::server::store
