#!/usr/bin/env bash
# Usage: service_benchmark.sh BUILD_DIR
# The service past one machine, timed with real softid-server processes on loopback:
#  1. Fan-out: one 8-start job (Young's modulus of the torus drop, one thread per start), from
#     submission to SUCCEEDED, on a server whose starts all run in the job's worker, and with
#     --fan-out-starts on 1, 2 and 4 workers. Prints the times and the speed-up over the first.
#  2. A worker's death to its job running again: a PostgreSQL store (SOFTID_TEST_POSTGRES_URL, as
#     tests/server/with_postgres.sh sets it; skipped without), an API and two worker processes
#     with --lease-seconds L; the worker running the job is killed (kill -9) and the time until
#     the other starts it (its log's "RUNNING" line for the job) is printed, for L = 5 and 15.
# Run it as:  bash tests/server/with_postgres.sh bash tests/benchmarks/service_benchmark.sh build
set -euo pipefail

build_dir=$(cd "${1:?usage: service_benchmark.sh BUILD_DIR}" && pwd)
server_bin=$build_dir/server/softid-server
client_bin=$build_dir/client/softid
lab_bin=$build_dir/core/lab/softid-lab
work=$(mktemp -d /tmp/softid-service-bench.XXXXXX)
pids=()
cleanup() {
  for pid in "${pids[@]}"; do kill -KILL "$pid" 2>/dev/null || true; done
  rm -rf "$work"
}
trap cleanup EXIT

now() { date +%s.%N; }

# Starts softid-server NAME ARGS... with its log in $work/NAME.log; sets `address`.
start_server() {
  local name=$1
  shift
  rm -f "$work/$name.port"
  "$server_bin" --listen localhost:0 --port-file "$work/$name.port" "$@" >"$work/$name.log" 2>&1 &
  pids+=($!)
  echo $! >"$work/$name.pid"
  for _ in $(seq 300); do
    [ -s "$work/$name.port" ] && break
    sleep 0.1
  done
  [ -s "$work/$name.port" ] || { echo "softid-server $name did not start" >&2; exit 1; }
  address="localhost:$(cat "$work/$name.port")"
}

# SIGTERM, then waits until the process has gone.
stop_server() {
  local pid
  pid=$(cat "$work/$1.pid")
  kill -TERM "$pid" 2>/dev/null || return 0
  wait "$pid" 2>/dev/null || true
}

"$lab_bin" synth --scene torus-drop --out "$work/capture" >/dev/null
cat >"$work/job.json" <<'JSON'
{
  "fit": ["youngs_modulus"],
  "initial": {"youngs_modulus": {"min": 1e4, "max": 2e5}},
  "fixed": {"poisson_ratio": 0.35, "mass_damping": 0.1, "stiffness_damping": 0.01,
            "ground": {"normal": [0, 0, 1], "offset": 0}},
  "cells": 12, "substeps": 4, "frames": {"first": 0, "last": 20},
  "starts": 8, "max_iterations": 8, "threads": 1, "uncertainty": false
}
JSON

# Seconds from submission to the end of the job (into `seconds`), on a fresh server with ARGS.
time_job() {
  local name=$1
  shift
  start_server "$name" --data "$work/$name" "$@"
  local begin end
  begin=$(now)
  "$client_bin" --server "$address" --json submit "$work/capture" --config "$work/job.json" \
    --wait >"$work/$name.out"
  end=$(now)
  grep -q SUCCEEDED "$work/$name.out" || { echo "$name: the job did not succeed" >&2; exit 1; }
  stop_server "$name"
  seconds=$(awk -v a="$begin" -v b="$end" 'BEGIN { print b - a }')
}

echo "== fan-out of an 8-start job ($(nproc) cores)"
printf '%-34s %9s %9s\n' "server" "seconds" "speed-up"
time_job alone --workers 1
base=$seconds
printf '%-34s %9.1f %9.2f\n' "1 worker, starts in the job" "$base" 1
for workers in 1 2 4; do
  time_job "fan$workers" --workers "$workers" --fan-out-starts
  t=$seconds
  printf '%-34s %9.1f %9.2f\n' "$workers worker(s), --fan-out-starts" "$t" "$(awk -v a="$base" -v b="$t" 'BEGIN { print a / b }')"
done

if [ -z "${SOFTID_TEST_POSTGRES_URL:-}" ]; then
  echo "== worker death to rerun: skipped (no SOFTID_TEST_POSTGRES_URL; run under with_postgres.sh)"
  exit 0
fi
echo "== a worker's death to its job running again (PostgreSQL store)"
printf '%-16s %9s\n' "lease [s]" "seconds"
for lease in 5 15; do
  common=(--store "$SOFTID_TEST_POSTGRES_URL" --data "$work/shared" --lease-seconds "$lease")
  start_server "api$lease" "${common[@]}" --role api
  api=$address
  start_server "a$lease" "${common[@]}" --role worker --workers 1
  submitted=$("$client_bin" --server "$api" --json submit "$work/capture" --config "$work/job.json")
  job=$(sed -n 's/.*"id":"\(job-[0-9a-f]*\)".*/\1/p' <<<"$submitted")
  until grep -q "job $job: RUNNING on" "$work/a$lease.log"; do sleep 0.05; done
  start_server "b$lease" "${common[@]}" --role worker --workers 1
  kill -KILL "$(cat "$work/a$lease.pid")"
  killed=$(now)
  wait "$(cat "$work/a$lease.pid")" 2>/dev/null || true
  until grep -q "job $job: RUNNING on" "$work/b$lease.log"; do sleep 0.05; done
  rerun=$(now)
  printf '%-16s %9.1f\n' "$lease" "$(awk -v a="$killed" -v b="$rerun" 'BEGIN { print b - a }')"
  "$client_bin" --server "$api" cancel "$job" >/dev/null
  stop_server "b$lease"
  stop_server "api$lease"
done
