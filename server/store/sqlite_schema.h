// The SQLite job store's schema and its versioning. The version lives in PRAGMA user_version and
// a marker in PRAGMA application_id identifies the file as ours. Opening applies the missing
// migrations in one transaction; a database newer than this build is refused rather than
// modified, because an older binary cannot know what a newer schema's invariants are.
#pragma once

#include <cstdint>

#include "core/common/status.h"
#include "server/store/sqlite_database.h"

namespace softid::server::store {

// The schema version this build writes and understands.
inline constexpr int kSqliteSchemaVersion = 8;
// "SFID" in ASCII, stored in the database header so `file` and we can tell the file apart from
// other SQLite databases.
inline constexpr int32_t kSqliteApplicationId = 0x53464944;

// Brings the database to kSqliteSchemaVersion inside one BEGIN IMMEDIATE transaction (so two
// processes opening a new database at once do not both create it).
// FailedPrecondition if the database's schema is newer than kSqliteSchemaVersion, or if it is not
// a softid job store (another application id, or tables without a version).
Status MigrateSqliteSchema(SqliteDatabase& db);

// PRAGMA user_version.
Result<int> ReadSchemaVersion(SqliteDatabase& db);

}  // namespace softid::server::store
