#include "server/store/postgres_schema.h"

#include <array>
#include <string>
#include <string_view>

namespace softid::server::store {
namespace {

// Held (transaction-scoped) while migrating: "SFID" in ASCII, then 1. Advisory locks are per
// database, so stores in other schemas of the same database only wait for each other's migration.
constexpr std::string_view kMigrationLock = "SELECT pg_advisory_xact_lock(5999030708281737217)";

// kMigrations[v] takes the schema from version v to v + 1. Never edit a released entry: add one.
//
// Conventions, chosen to read and compare exactly like the SQLite store: timestamps are BIGINT
// microseconds since the Unix epoch (UTC), as Timestamp keeps them; JSON columns are JSON (kept as
// written; JSONB would reorder keys and rewrite numbers); enumerations are TEXT with a CHECK
// listing the values. Request ids are unique per owner (UNIQUE treats NULL, "no request id", as
// distinct).
constexpr std::array<std::string_view, kPostgresSchemaVersion> kMigrations = {
    // 0 -> 1: the initial schema (the SQLite schema's version 6).
    R"sql(
CREATE TABLE softid_schema_version (
  one_row  BOOLEAN PRIMARY KEY DEFAULT TRUE CHECK (one_row),
  version  INTEGER NOT NULL
);

CREATE TABLE captures (
  id                  TEXT PRIMARY KEY,
  station_request_id  TEXT,
  owner               TEXT NOT NULL DEFAULT '',
  format              TEXT NOT NULL DEFAULT 'softid-capture/1'
                      CHECK (format IN ('softid-capture/1', 'softid-recording/1')),
  manifest            JSON NOT NULL,  -- [{path, sha256, size}]
  created_at          BIGINT NOT NULL,
  UNIQUE (owner, station_request_id)
);
CREATE INDEX captures_by_owner ON captures (owner, created_at, id);
CREATE INDEX captures_by_creation ON captures (created_at, id);

CREATE TABLE jobs (
  id                  TEXT PRIMARY KEY,
  station_request_id  TEXT,
  owner               TEXT NOT NULL DEFAULT '',
  capture_id          TEXT NOT NULL REFERENCES captures (id),
  -- The capture the job's ingest made from its recording.
  derived_capture_id  TEXT REFERENCES captures (id),
  config              JSON NOT NULL,
  state               TEXT NOT NULL
                      CHECK (state IN ('QUEUED', 'RUNNING', 'SUCCEEDED', 'FAILED', 'CANCELLED')),
  cancel_requested    BOOLEAN NOT NULL DEFAULT FALSE,
  attempts            INTEGER NOT NULL DEFAULT 0 CHECK (attempts >= 0),
  -- Claims handed back by a graceful shutdown: not held against max_attempts.
  released_attempts   INTEGER NOT NULL DEFAULT 0 CHECK (released_attempts >= 0),
  error               TEXT NOT NULL DEFAULT '',
  created_at          BIGINT NOT NULL,
  started_at          BIGINT,
  finished_at         BIGINT,
  lease_owner         TEXT,
  lease_expires_at    BIGINT,
  result              JSON,
  -- A RUNNING job always has a lease; no other state has one.
  CHECK ((state = 'RUNNING') = (lease_owner IS NOT NULL AND lease_expires_at IS NOT NULL)),
  UNIQUE (owner, station_request_id)
);
-- Claiming (oldest QUEUED first) and listing by state both walk this index in order.
CREATE INDEX jobs_by_state ON jobs (state, created_at, id);
-- Listing all jobs in creation order (the keyset pagination key).
CREATE INDEX jobs_by_creation ON jobs (created_at, id);
CREATE INDEX jobs_by_owner ON jobs (owner, created_at, id);
-- Foreign keys need an index on the child column, or deleting a capture scans jobs.
CREATE INDEX jobs_by_capture ON jobs (capture_id);
CREATE INDEX jobs_by_derived_capture ON jobs (derived_capture_id);

CREATE TABLE progress (
  job_id         TEXT NOT NULL REFERENCES jobs (id) ON DELETE CASCADE,
  seq            BIGINT NOT NULL CHECK (seq >= 1),  -- 1, 2, 3, ... per job
  attempt        INTEGER NOT NULL,
  event          TEXT NOT NULL CHECK (event IN ('iteration', 'state')),
  iteration      INTEGER NOT NULL CHECK (iteration >= 0),
  start          INTEGER NOT NULL DEFAULT 0 CHECK (start >= 0),
  num_starts     INTEGER NOT NULL DEFAULT 1 CHECK (num_starts >= 1),
  cost           DOUBLE PRECISION,  -- NULL when not available (NaN)
  gradient_norm  DOUBLE PRECISION,
  parameters     JSON,
  elapsed_s      DOUBLE PRECISION NOT NULL,  -- seconds since the attempt started
  remaining_s    DOUBLE PRECISION,
  state          TEXT CHECK (state IN ('QUEUED', 'RUNNING', 'SUCCEEDED', 'FAILED', 'CANCELLED')),
  message        TEXT NOT NULL DEFAULT '',
  created_at     BIGINT NOT NULL,
  PRIMARY KEY (job_id, seq)
);

CREATE TABLE checkpoints (
  job_id      TEXT PRIMARY KEY REFERENCES jobs (id) ON DELETE CASCADE,
  attempt     INTEGER NOT NULL,
  data        JSON NOT NULL,
  updated_at  BIGINT NOT NULL
);

-- Per-station API tokens: only their secrets' hashes.
CREATE TABLE tokens (
  id             TEXT PRIMARY KEY,
  station        TEXT NOT NULL,
  admin          BOOLEAN NOT NULL DEFAULT FALSE,
  secret_sha256  TEXT NOT NULL UNIQUE,
  created_at     BIGINT NOT NULL,
  expires_at     BIGINT,
  revoked_at     BIGINT
);
)sql",
    // 1 -> 2: a job's starts as tasks any worker can claim (fan-out; start_task.h).
    R"sql(
CREATE TABLE start_tasks (
  job_id            TEXT NOT NULL REFERENCES jobs (id) ON DELETE CASCADE,
  idx               INTEGER NOT NULL CHECK (idx >= 0),
  state             TEXT NOT NULL CHECK (state IN ('QUEUED', 'RUNNING', 'DONE')),
  attempts          INTEGER NOT NULL DEFAULT 0 CHECK (attempts >= 0),
  lease_owner       TEXT,
  lease_expires_at  BIGINT,
  result            JSON,
  created_at        BIGINT NOT NULL,
  PRIMARY KEY (job_id, idx),
  -- A RUNNING task always has a lease, and only a DONE one a result.
  CHECK ((state = 'RUNNING') = (lease_owner IS NOT NULL AND lease_expires_at IS NOT NULL)),
  CHECK ((state = 'DONE') = (result IS NOT NULL))
);
-- Claiming walks the tasks not DONE in creation order.
CREATE INDEX start_tasks_by_state ON start_tasks (state, created_at, job_id, idx);
)sql",
    // 2 -> 3: batches of other fits (the diagnosis' refits) as tasks beside the job's starts.
    R"sql(
ALTER TABLE start_tasks ADD COLUMN batch TEXT NOT NULL DEFAULT '';
ALTER TABLE start_tasks ADD COLUMN input JSON;
)sql",
};

// The number of tables in the connection's current schema.
Result<int64_t> CountTables(PostgresConnection& db) {
  SOFTID_ASSIGN_OR_RETURN(
      PostgresResult tables,
      db.Query("SELECT count(*) FROM pg_catalog.pg_tables WHERE schemaname = current_schema()"));
  return tables.Int64(0, 0);
}

// Applies kMigrations[from..] and records the new version; inside the caller's transaction.
Status Migrate(PostgresConnection& db, int from) {
  for (int v = from; v < kPostgresSchemaVersion; ++v) {
    SOFTID_RETURN_IF_ERROR(
        db.Exec(kMigrations[static_cast<size_t>(v)])
            .WithContext("migrating schema to version " + std::to_string(v + 1)));
  }
  SOFTID_ASSIGN_OR_RETURN(PostgresResult updated, db.Query(R"sql(
      INSERT INTO softid_schema_version (version) VALUES ($1)
      ON CONFLICT (one_row) DO UPDATE SET version = excluded.version)sql",
                                                           kPostgresSchemaVersion));
  (void)updated;
  return Status::Ok();
}

}  // namespace

Result<int> ReadPostgresSchemaVersion(PostgresConnection& db) {
  SOFTID_ASSIGN_OR_RETURN(PostgresResult exists,
                          db.Query("SELECT to_regclass('softid_schema_version') IS NOT NULL"));
  if (!exists.Bool(0, 0)) return 0;
  SOFTID_ASSIGN_OR_RETURN(PostgresResult version,
                          db.Query("SELECT version FROM softid_schema_version"));
  if (version.rows() == 0) return 0;
  return static_cast<int>(version.Int64(0, 0));
}

Status MigratePostgresSchema(PostgresConnection& db) {
  const std::string& where = db.where();
  // READ COMMITTED: once the lock is ours, the next statements see what a migration that held it
  // before us committed.
  SOFTID_RETURN_IF_ERROR(db.Exec("BEGIN ISOLATION LEVEL READ COMMITTED"));
  Status status = [&]() -> Status {
    SOFTID_RETURN_IF_ERROR(db.Exec(kMigrationLock));
    SOFTID_ASSIGN_OR_RETURN(const int version, ReadPostgresSchemaVersion(db));
    if (version > kPostgresSchemaVersion) {
      return Status::FailedPrecondition(
          where + ": database schema version " + std::to_string(version) +
          " is newer than this build supports (" + std::to_string(kPostgresSchemaVersion) +
          "); it was written by a newer softid. Refusing to open it; run a newer softid-server");
    }
    if (version == 0) {
      SOFTID_ASSIGN_OR_RETURN(const int64_t tables, CountTables(db));
      if (tables > 0) {
        return Status::FailedPrecondition(
            where + ": not a softid job store (its schema has " + std::to_string(tables) +
            " table(s) but no softid_schema_version); use an empty database or schema");
      }
    }
    if (version == kPostgresSchemaVersion) return Status::Ok();
    return Migrate(db, version);
  }();
  if (!status.ok()) {
    (void)db.Exec("ROLLBACK");
    return status;
  }
  return db.Exec("COMMIT");
}

}  // namespace softid::server::store
