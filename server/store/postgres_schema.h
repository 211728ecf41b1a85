// The PostgreSQL job store's schema and its versioning. The version lives in the one-row table
// softid_schema_version of the connection's schema (search_path). Opening applies the missing
// migrations in one transaction; a database newer than this build is refused rather than modified,
// because an older binary cannot know what a newer schema's invariants are.
//
// The PostgreSQL schema is versioned on its own (it starts at 1 with the equivalent of the SQLite
// schema's version 6): the two never migrate into each other.
#pragma once

#include "core/common/status.h"
#include "server/store/postgres_connection.h"

namespace softid::server::store {

// The schema version this build writes and understands.
inline constexpr int kPostgresSchemaVersion = 3;

// Brings the database to kPostgresSchemaVersion inside one transaction that holds an advisory lock,
// so two processes starting on a new database at once do not both create the tables (the second
// waits, then finds them). FailedPrecondition if the schema is newer than kPostgresSchemaVersion,
// or if the schema holds tables but no version (not a softid job store).
Status MigratePostgresSchema(PostgresConnection& db);

// The version recorded in softid_schema_version; 0 when the table does not exist.
Result<int> ReadPostgresSchemaVersion(PostgresConnection& db);

}  // namespace softid::server::store
