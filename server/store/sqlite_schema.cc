#include "server/store/sqlite_schema.h"

#include <array>
#include <string>
#include <string_view>

namespace softid::server::store {
namespace {

// kMigrations[v] takes the schema from version v to v + 1. Never edit a released entry: add one.
//
// Conventions: STRICT tables; timestamps are INTEGER microseconds since the Unix epoch (UTC); JSON
// columns are TEXT checked with json_valid; enumerations are TEXT with a CHECK listing the values,
// so that the database stays readable with the sqlite3 shell.
constexpr std::array<std::string_view, kSqliteSchemaVersion> kMigrations = {
    // 0 -> 1: the initial schema.
    R"sql(
CREATE TABLE captures (
  id          TEXT PRIMARY KEY NOT NULL,
  request_id  TEXT UNIQUE,  -- NULL when the client gave none; UNIQUE ignores NULLs
  manifest    TEXT NOT NULL CHECK (json_valid(manifest)),  -- [{path, sha256, size}]
  created_at  INTEGER NOT NULL
) STRICT;

CREATE TABLE jobs (
  id                TEXT PRIMARY KEY NOT NULL,
  request_id        TEXT UNIQUE,
  capture_id        TEXT NOT NULL REFERENCES captures (id),
  config            TEXT NOT NULL CHECK (json_valid(config)),
  state             TEXT NOT NULL
                    CHECK (state IN ('QUEUED', 'RUNNING', 'SUCCEEDED', 'FAILED', 'CANCELLED')),
  cancel_requested  INTEGER NOT NULL DEFAULT 0 CHECK (cancel_requested IN (0, 1)),
  attempts          INTEGER NOT NULL DEFAULT 0 CHECK (attempts >= 0),
  error             TEXT NOT NULL DEFAULT '',
  created_at        INTEGER NOT NULL,
  started_at        INTEGER,
  finished_at       INTEGER,
  lease_owner       TEXT,
  lease_expires_at  INTEGER,
  result            TEXT CHECK (result IS NULL OR json_valid(result)),
  -- A RUNNING job always has a lease; no other state has one.
  CHECK ((state = 'RUNNING') = (lease_owner IS NOT NULL AND lease_expires_at IS NOT NULL))
) STRICT;
-- Claiming (oldest QUEUED first) and listing by state both walk this index in order.
CREATE INDEX jobs_by_state ON jobs (state, created_at, id);
-- Listing all jobs in creation order (the keyset pagination key).
CREATE INDEX jobs_by_creation ON jobs (created_at, id);
-- Foreign keys need an index on the child column, or deleting a capture scans jobs.
CREATE INDEX jobs_by_capture ON jobs (capture_id);

CREATE TABLE progress (
  job_id         TEXT NOT NULL REFERENCES jobs (id) ON DELETE CASCADE,
  seq            INTEGER NOT NULL CHECK (seq >= 1),  -- 1, 2, 3, ... per job
  attempt        INTEGER NOT NULL,
  event          TEXT NOT NULL CHECK (event IN ('iteration', 'state')),
  iteration      INTEGER NOT NULL CHECK (iteration >= 0),
  cost           REAL,           -- NULL when not available (NaN)
  gradient_norm  REAL,
  parameters     TEXT CHECK (parameters IS NULL OR json_valid(parameters)),
  elapsed_s      REAL NOT NULL,  -- seconds since the attempt started
  state          TEXT CHECK (state IN ('QUEUED', 'RUNNING', 'SUCCEEDED', 'FAILED', 'CANCELLED')),
  message        TEXT NOT NULL DEFAULT '',
  created_at     INTEGER NOT NULL,
  PRIMARY KEY (job_id, seq)
) STRICT, WITHOUT ROWID;

CREATE TABLE checkpoints (
  job_id      TEXT PRIMARY KEY NOT NULL REFERENCES jobs (id) ON DELETE CASCADE,
  attempt     INTEGER NOT NULL,
  data        TEXT NOT NULL CHECK (json_valid(data)),
  updated_at  INTEGER NOT NULL
) STRICT;
)sql",
    // 1 -> 2: claims handed back by a graceful shutdown, not held against max_attempts.
    R"sql(
ALTER TABLE jobs ADD COLUMN released_attempts INTEGER NOT NULL DEFAULT 0
  CHECK (released_attempts >= 0);
)sql",
    // 2 -> 3: which of a job's random starts an iteration belongs to, and the fit's estimate of
    // the time left (watch displays).
    R"sql(
ALTER TABLE progress ADD COLUMN start INTEGER NOT NULL DEFAULT 0 CHECK (start >= 0);
ALTER TABLE progress ADD COLUMN num_starts INTEGER NOT NULL DEFAULT 1 CHECK (num_starts >= 1);
ALTER TABLE progress ADD COLUMN remaining_s REAL;
)sql",
    // 3 -> 4: per-station API tokens (only their secrets' hashes) and the station owning each
    // capture and job ('' for those created without authentication).
    R"sql(
ALTER TABLE captures ADD COLUMN owner TEXT NOT NULL DEFAULT '';
ALTER TABLE jobs ADD COLUMN owner TEXT NOT NULL DEFAULT '';
CREATE INDEX jobs_by_owner ON jobs (owner, created_at, id);
CREATE TABLE tokens (
  id             TEXT PRIMARY KEY NOT NULL,
  station        TEXT NOT NULL,
  admin          INTEGER NOT NULL DEFAULT 0 CHECK (admin IN (0, 1)),
  secret_sha256  TEXT NOT NULL UNIQUE,
  created_at     INTEGER NOT NULL,
  expires_at     INTEGER,
  revoked_at     INTEGER
) STRICT;
)sql",
    // 4 -> 5: listing captures (ListCaptures), a station's or all, in creation order; and request
    // ids per station, so that two stations may use the same key and none can learn another's.
    // Schema 1's column-level UNIQUE on request_id cannot be dropped without rebuilding the
    // tables, so the key moves to station_request_id (unique per owner) and request_id stays NULL.
    R"sql(
CREATE INDEX captures_by_owner ON captures (owner, created_at, id);
CREATE INDEX captures_by_creation ON captures (created_at, id);
ALTER TABLE captures ADD COLUMN station_request_id TEXT;
ALTER TABLE jobs ADD COLUMN station_request_id TEXT;
UPDATE captures SET station_request_id = request_id, request_id = NULL WHERE request_id IS NOT NULL;
UPDATE jobs SET station_request_id = request_id, request_id = NULL WHERE request_id IS NOT NULL;
CREATE UNIQUE INDEX captures_by_request ON captures (owner, station_request_id);
CREATE UNIQUE INDEX jobs_by_request ON jobs (owner, station_request_id);
)sql",
    // 5 -> 6: raw recordings next to captures (a capture's folder format), and the capture a
    // job's ingest made from its recording. Existing captures are all softid-capture/1. The store
    // keeps derived_capture_id pointing at a capture in its transactions (SetDerivedCapture checks
    // the capture exists, DeleteCapture refuses one a job names), as a foreign key would; a
    // foreign key column could not be dropped again (ALTER TABLE DROP COLUMN refuses it).
    R"sql(
ALTER TABLE captures ADD COLUMN format TEXT NOT NULL DEFAULT 'softid-capture/1'
  CHECK (format IN ('softid-capture/1', 'softid-recording/1'));
ALTER TABLE jobs ADD COLUMN derived_capture_id TEXT;
CREATE INDEX jobs_by_derived_capture ON jobs (derived_capture_id);
)sql",
    // 6 -> 7: a job's starts as tasks any worker can claim (fan-out; start_task.h).
    R"sql(
CREATE TABLE start_tasks (
  job_id            TEXT NOT NULL REFERENCES jobs (id) ON DELETE CASCADE,
  idx               INTEGER NOT NULL CHECK (idx >= 0),
  state             TEXT NOT NULL CHECK (state IN ('QUEUED', 'RUNNING', 'DONE')),
  attempts          INTEGER NOT NULL DEFAULT 0 CHECK (attempts >= 0),
  lease_owner       TEXT,
  lease_expires_at  INTEGER,
  result            TEXT CHECK (result IS NULL OR json_valid(result)),
  created_at        INTEGER NOT NULL,
  PRIMARY KEY (job_id, idx),
  -- A RUNNING task always has a lease, and only a DONE one a result.
  CHECK ((state = 'RUNNING') = (lease_owner IS NOT NULL AND lease_expires_at IS NOT NULL)),
  CHECK ((state = 'DONE') = (result IS NOT NULL))
) STRICT, WITHOUT ROWID;
-- Claiming walks the tasks not DONE in creation order.
CREATE INDEX start_tasks_by_state ON start_tasks (state, created_at, job_id, idx);
)sql",
    // 7 -> 8: batches of other fits (the diagnosis' refits) as tasks beside the job's starts.
    R"sql(
ALTER TABLE start_tasks ADD COLUMN batch TEXT NOT NULL DEFAULT '';
ALTER TABLE start_tasks ADD COLUMN input TEXT CHECK (input IS NULL OR json_valid(input));
)sql",
};

Result<int64_t> ReadPragma(SqliteDatabase& db, std::string_view pragma) {
  SOFTID_ASSIGN_OR_RETURN(SqliteStatement stmt, db.Prepare("PRAGMA " + std::string(pragma)));
  SOFTID_ASSIGN_OR_RETURN(const bool has_row, stmt.Step());
  if (!has_row) return Status::Internal("PRAGMA " + std::string(pragma) + " returned no row");
  return stmt.ColumnInt64(0);
}

}  // namespace

Result<int> ReadSchemaVersion(SqliteDatabase& db) {
  SOFTID_ASSIGN_OR_RETURN(const int64_t version, ReadPragma(db, "user_version"));
  return static_cast<int>(version);
}

Status MigrateSqliteSchema(SqliteDatabase& db) {
  const std::string where = db.path().string();
  SOFTID_ASSIGN_OR_RETURN(SqliteTransaction transaction, SqliteTransaction::Begin(db));
  SOFTID_ASSIGN_OR_RETURN(const int version, ReadSchemaVersion(db));
  SOFTID_ASSIGN_OR_RETURN(const int64_t application_id, ReadPragma(db, "application_id"));

  if (version > kSqliteSchemaVersion) {
    return Status::FailedPrecondition(
        where + ": database schema version " + std::to_string(version) +
        " is newer than this build supports (" + std::to_string(kSqliteSchemaVersion) +
        "); it was written by a newer softid. Refusing to open it; run a newer softid-server");
  }
  if (application_id != 0 && application_id != kSqliteApplicationId) {
    return Status::FailedPrecondition(where + ": not a softid job store (application_id " +
                                      std::to_string(application_id) + ")");
  }
  if (version == 0) {
    SOFTID_ASSIGN_OR_RETURN(SqliteStatement objects,
                            db.Prepare("SELECT count(*) FROM sqlite_schema"));
    SOFTID_ASSIGN_OR_RETURN(const bool has_row, objects.Step());
    if (has_row && objects.ColumnInt64(0) > 0) {
      return Status::FailedPrecondition(
          where + ": not a softid job store (it has tables but no schema version)");
    }
  }
  for (int v = version; v < kSqliteSchemaVersion; ++v) {
    SOFTID_RETURN_IF_ERROR(
        db.Exec(kMigrations[static_cast<size_t>(v)])
            .WithContext("migrating schema to version " + std::to_string(v + 1)));
  }
  if (version != kSqliteSchemaVersion) {
    SOFTID_RETURN_IF_ERROR(
        db.Exec("PRAGMA user_version = " + std::to_string(kSqliteSchemaVersion)));
    SOFTID_RETURN_IF_ERROR(
        db.Exec("PRAGMA application_id = " + std::to_string(kSqliteApplicationId)));
  }
  return transaction.Commit();
}

}  // namespace softid::server::store
