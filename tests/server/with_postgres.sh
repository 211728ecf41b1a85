#!/usr/bin/env bash
# Usage: with_postgres.sh COMMAND [ARGS...]
# Runs COMMAND against a throw-away PostgreSQL 15 server of its own: initdb in a temporary folder,
# the server on a free loopback port with its unix socket in that folder, and the URL of an empty
# database in SOFTID_TEST_POSTGRES_URL. The server is stopped and the folder removed when COMMAND
# ends, whatever its exit status; COMMAND's exit status is this script's.
#
# PostgreSQL refuses to run as root, and CI runs as root: then initdb and the server run as an
# unprivileged user owning the folder (SOFTID_TEST_POSTGRES_USER, default nobody; if that user does
# not exist, a system user softid-pg-test made for it); otherwise as the caller. Without the
# PostgreSQL 15 binaries (Debian: postgresql-15) COMMAND runs without the variable, and the
# PostgreSQL tests skip (GTEST_SKIP) saying so.
set -euo pipefail

if [ "$#" -eq 0 ]; then
  echo "usage: $0 COMMAND [ARGS...]" >&2
  exit 2
fi

bin_dir=${SOFTID_TEST_POSTGRES_BIN:-/usr/lib/postgresql/15/bin}
if [ ! -x "$bin_dir/initdb" ] || [ ! -x "$bin_dir/pg_ctl" ]; then
  # ctest reports the test as skipped on this line (SKIP_REGULAR_EXPRESSION).
  echo "with_postgres: PostgreSQL 15 not found in $bin_dir (install postgresql-15): skipping"
  unset SOFTID_TEST_POSTGRES_URL
  exec "$@"
fi

run_as=()
if [ "$(id -u)" -eq 0 ]; then
  pg_user=${SOFTID_TEST_POSTGRES_USER:-nobody}
  # A minimal image may lack nobody: a system user of our own, without a home or a shell.
  if ! id "$pg_user" >/dev/null 2>&1; then
    pg_user=softid-pg-test
    id "$pg_user" >/dev/null 2>&1 ||
      useradd --system --no-create-home --shell /usr/sbin/nologin "$pg_user"
  fi
  run_as=(runuser -u "$pg_user" --)
fi

root=$(mktemp -d /tmp/softid-postgres.XXXXXX)
data=$root/data
log=$root/server.log

stop_server() {
  if [ -f "$data/postmaster.pid" ]; then
    "${run_as[@]}" "$bin_dir/pg_ctl" stop -D "$data" -m immediate -w >/dev/null 2>&1 || true
  fi
  rm -rf "$root"
}
trap stop_server EXIT
trap 'exit 130' INT
trap 'exit 143' TERM

if [ "${#run_as[@]}" -gt 0 ]; then chown "$pg_user" "$root"; fi
chmod 700 "$root"
"${run_as[@]}" "$bin_dir/initdb" -D "$data" -U postgres --auth=trust --encoding=UTF8 \
  --locale=C.UTF-8 --no-sync >"$root/initdb.log" 2>&1 || {
  cat "$root/initdb.log" >&2
  echo "with_postgres: initdb failed" >&2
  exit 1
}

# A free port: bind port 0 and release it. Another process could take it before the server
# binds, so a failed start is tried again on another port.
free_port() {
  python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'
}

port=
for _ in 1 2 3; do
  candidate=$(free_port)
  # fsync off: a test server's data need not survive power loss, and commits are ~10x faster.
  if "${run_as[@]}" "$bin_dir/pg_ctl" start -D "$data" -l "$log" -w -t 60 -s \
    -o "-p $candidate -k $root -c listen_addresses=127.0.0.1 -c fsync=off \
-c synchronous_commit=off -c full_page_writes=off -c max_connections=200" >/dev/null 2>&1; then
    port=$candidate
    break
  fi
done
if [ -z "$port" ]; then
  cat "$log" >&2 || true
  echo "with_postgres: the server did not start" >&2
  exit 1
fi

# If this script is killed outright (SIGKILL: a ctest timeout), no trap runs: a watchdog stops the
# server once this script's process is gone. Its output goes nowhere, so it never holds a pipe
# that a caller waits on.
(
  while kill -0 $$ 2>/dev/null; do sleep 1; done
  stop_server
) </dev/null >/dev/null 2>&1 &

"${run_as[@]}" "$bin_dir/psql" -h "$root" -p "$port" -U postgres -d postgres -qAt -v ON_ERROR_STOP=1 \
  -c "CREATE DATABASE softid_test" >/dev/null
export SOFTID_TEST_POSTGRES_URL="postgresql://postgres@127.0.0.1:$port/softid_test"
echo "with_postgres: PostgreSQL 15 on port $port ($root)"

status=0
"$@" || status=$?
exit "$status"
