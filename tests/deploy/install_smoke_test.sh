#!/usr/bin/env bash
# Usage: install_smoke_test.sh BUILD_DIR
# What the container does, without a Docker engine: installs the binaries to a temporary prefix,
# runs the installed softid-server as an unprivileged user (nobody, via setpriv, when this runs
# as root) on a fresh data directory, checks `softid health`, starts a job, sends SIGTERM while
# it runs, and requires exit status 0 with the job QUEUED again (nothing left RUNNING: the next
# start must find nothing to recover). Exit 77 (CTest skip) only when no tool can drop privileges.
set -euo pipefail

build_dir=$1
cmake_bin=${CMAKE:-cmake}

skip() { echo "SKIP: $*"; exit 77; }
fail() {
  echo "FAIL: $*" >&2
  [ -f "${tmp:-}/server.log" ] && { echo "--- server log" >&2; cat "$tmp/server.log" >&2; }
  exit 1
}

run_as=()
if [ "$(id -u)" -eq 0 ]; then
  user=nobody
  group=$(id -gn "$user") || skip "no user $user to drop privileges to"
  if command -v setpriv >/dev/null; then
    # setpriv execs: the pid we get is the server's own, so signals reach it directly.
    run_as=(setpriv --reuid="$user" --regid="$group" --clear-groups --)
  elif command -v runuser >/dev/null; then
    run_as=(runuser -u "$user" --)
  else
    skip "running as root and neither setpriv nor runuser is available"
  fi
fi

tmp=$(mktemp -d /tmp/softid-install-smoke.XXXXXX)
server_pid=""
cleanup() {
  if [ -n "$server_pid" ] && kill -0 "$server_pid" 2>/dev/null; then
    kill -KILL "$server_pid" 2>/dev/null || true
    wait "$server_pid" 2>/dev/null || true
  fi
  rm -rf "$tmp"
}
trap cleanup EXIT
# mktemp -d is private to its creator; the unprivileged user must reach the prefix.
chmod 755 "$tmp"

"$cmake_bin" --install "$build_dir" --prefix "$tmp/prefix" >/dev/null
bin=$tmp/prefix/bin
for binary in softid-server softid softid-lab; do
  [ -x "$bin/$binary" ] || fail "cmake --install did not install bin/$binary"
done

# The server's folder: owned by the unprivileged user; the data directory inside it is created
# by the server itself, as on a fresh volume.
mkdir "$tmp/run"
if [ "${#run_as[@]}" -gt 0 ]; then chown "$user:$group" "$tmp/run"; fi
data=$tmp/run/data

start_server() {  # WORKERS
  rm -f "$tmp/run/port"
  "${run_as[@]}" "$bin/softid-server" --listen localhost:0 --port-file "$tmp/run/port" \
    --data "$data" --workers "$1" >>"$tmp/server.log" 2>&1 &
  server_pid=$!
  for _ in $(seq 300); do
    [ -s "$tmp/run/port" ] && break
    kill -0 "$server_pid" 2>/dev/null || fail "softid-server exited at start"
    sleep 0.1
  done
  [ -s "$tmp/run/port" ] || fail "softid-server wrote no port file within 30 s"
  softid=("$bin/softid" --server "localhost:$(cat "$tmp/run/port")" --timeout 5)
  local uid
  uid=$(awk '/^Uid:/ {print $2}' "/proc/$server_pid/status")
  [ "$uid" -ne 0 ] || fail "softid-server runs as root"
}

stop_server() {  # SIGTERM, then exit status 0 within 30 s
  kill -TERM "$server_pid"
  for _ in $(seq 300); do
    kill -0 "$server_pid" 2>/dev/null || break
    sleep 0.1
  done
  kill -0 "$server_pid" 2>/dev/null && fail "softid-server still runs 30 s after SIGTERM"
  local status=0
  wait "$server_pid" || status=$?
  server_pid=""
  [ "$status" -eq 0 ] || fail "softid-server exited with status $status after SIGTERM"
}

json_field() {  # FIELD JSON: the value of a string field of a flat JSON object
  sed -n "s/.*\"$1\":\"\([^\"]*\)\".*/\1/p" <<<"$2"
}

# A tiny capture, and a job long enough to be running when SIGTERM arrives.
"$bin/softid-lab" synth --scene torus-drop --out "$tmp/capture" --duration 0.25 --cameras 1 \
  --width 40 --height 40 --cells 8 >"$tmp/synth.log" 2>&1 ||
  fail "softid-lab synth failed: $(cat "$tmp/synth.log")"
cat >"$tmp/job.json" <<'JSON'
{"fit": ["youngs_modulus"], "cells": 8, "starts": 8, "threads": 1, "max_iterations": 200}
JSON

start_server 1
health=$("${softid[@]}" --retry-for 10 health) || fail "softid health failed"
[ "$health" = SERVING ] || fail "softid health said '$health'"
owner=$(stat -c %U "$data/softid.db")
if [ "${#run_as[@]}" -gt 0 ] && [ "$owner" != "$user" ]; then
  fail "softid.db belongs to $owner, not $user"
fi

submitted=$("${softid[@]}" --json submit "$tmp/capture" --config "$tmp/job.json")
job=$(json_field id "$submitted")
[ -n "$job" ] || fail "no job id in: $submitted"
state=""
for _ in $(seq 600); do
  state=$(json_field state "$("${softid[@]}" --json status "$job")")
  [ "$state" = RUNNING ] && break
  [ "$state" = QUEUED ] || fail "job $job is $state before SIGTERM"
  sleep 0.1
done
[ "$state" = RUNNING ] || fail "job $job did not start within 60 s"
stop_server

# A second start with no workers: nothing was left RUNNING (else it would log "recovered") and
# the job waits in the queue for its next start.
start_server 0
[ "$(grep -c 'recovered' "$tmp/server.log")" -eq 0 ] || fail "the restart found jobs left RUNNING"
running=$("${softid[@]}" --json list --state RUNNING)
[ "$running" = "[]" ] || fail "jobs RUNNING after the restart: $running"
state=$(json_field state "$("${softid[@]}" --json status "$job")")
[ "$state" = QUEUED ] || fail "job $job is $state after SIGTERM, not QUEUED"
stop_server
echo "ok: installed server ran as $(if [ "${#run_as[@]}" -gt 0 ]; then echo "$user"; else id -un; fi)," \
  "served health, and exited 0 on SIGTERM with job $job QUEUED again"
