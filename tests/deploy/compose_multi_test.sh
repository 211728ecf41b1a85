#!/usr/bin/env bash
# Usage: compose_multi_test.sh SOURCE_DIR BUILD_DIR
# Past one machine for real: runs deploy/docker-compose.multi.yml with podman-compose (Debian's
# 1.0.3; no Docker engine here): PostgreSQL, the API process and two workers from the image of
# deploy/Dockerfile, on one data volume. From the host, with the host's client and a station
# token made in the API container, a torus-drop job SUCCEEDS; the logs show that a worker
# container ran it and that the API container never fitted. Every container exits 0 when
# stopped (SIGTERM for the softid services, the database image's own stop signal for PostgreSQL).
# podman-compose 1.0.3 ignores depends_on conditions, so the services are brought up in the
# order those conditions ask for (deploy/README.md says the same for operators).
# No registry is reachable: when no postgres:15 image is present, one is built from Debian's
# postgresql-15 (tests/deploy/postgres/) and tagged postgres:15, the name the compose file uses.
# Prepares podman (idempotent); removes the containers, volumes, network and images it made,
# unless SOFTID_COMPOSE_KEEP=1. SOFTID_COMPOSE_IMAGE=TAG uses an image already built from
# deploy/Dockerfile instead of building one (the build takes 15-20 minutes on 2 cores; the rest
# about a minute); SOFTID_CONTAINER_KEEP_CACHE=1 keeps the build's layers, as in container_test.sh
# (run after it, the build then takes seconds). Exit 77 (CTest: skipped) when podman or
# podman-compose cannot be installed or run.
set -euo pipefail

source_dir=$(cd "$1" && pwd)
build_dir=$(cd "$2" && pwd)
client=$build_dir/client/softid
lab=$build_dir/core/lab/softid-lab
podman=(podman --runtime runc)
compose_file=$source_dir/deploy/docker-compose.multi.yml
project=softid-multi-test-$$
# The names the compose file uses.
image=localhost/softid:latest
postgres_image=docker.io/library/postgres:15
reuse=${SOFTID_COMPOSE_IMAGE:-}
keep=${SOFTID_COMPOSE_KEEP:-0}

skip() { echo "SKIP: $*"; exit 77; }
fail() {
  echo "FAIL: $*" >&2
  for service in postgres api worker; do
    for name in $(containers "$service"); do
      echo "--- $name" >&2
      "${podman[@]}" logs "$name" 2>&1 | tail -n 20 >&2 || true
    done
  done
  exit 1
}
containers() {  # SERVICE: the names of its containers
  "${podman[@]}" ps -a --format '{{.Names}}' --filter "label=io.podman.compose.project=$project" \
    --filter "label=com.docker.compose.service=$1" 2>/dev/null | sort
}

[ "$(id -u)" -eq 0 ] || skip "needs root to install and run podman"
[ -x "$client" ] && [ -x "$lab" ] || skip "softid and softid-lab are not built in $build_dir"

# shellcheck source=tests/deploy/podman_prepare.sh
source "$(dirname "$0")/podman_prepare.sh"

tmp=$(mktemp -d /tmp/softid-compose.XXXXXX)
# podman-compose runs podman itself: this configuration gives those calls runc as well (the
# settings prepare_podman writes to /etc/containers/containers.conf, read from here instead).
export CONTAINERS_CONF=$tmp/containers.conf
printf '[containers]\ndefault_ulimits = []\n\n[engine]\nruntime = "runc"\n' >"$CONTAINERS_CONF"
port=$((20000 + RANDOM % 30000))
export SOFTID_PUBLISH_PORT=$port
compose=(podman-compose -p "$project" -f "$compose_file")
made_postgres_image=0
made_image=0
previous_image=""

cleanup() {
  if [ "$keep" = 1 ]; then
    echo "kept (SOFTID_COMPOSE_KEEP=1): project $project, port $port; remove with:"
    echo "  podman-compose -p $project -f $compose_file down -v; podman network rm ${project}_default"
    return
  fi
  local ids
  ids=$("${podman[@]}" ps -aq --filter "label=io.podman.compose.project=$project" 2>/dev/null || true)
  [ -z "$ids" ] || "${podman[@]}" rm -f -t 0 $ids >/dev/null 2>&1 || true
  ids=$("${podman[@]}" volume ls -q --filter "label=io.podman.compose.project=$project" 2>/dev/null || true)
  [ -z "$ids" ] || "${podman[@]}" volume rm -f $ids >/dev/null 2>&1 || true
  "${podman[@]}" network rm -f "${project}_default" >/dev/null 2>&1 || true
  if [ "$made_postgres_image" = 1 ]; then
    "${podman[@]}" rmi -f "$postgres_image" >/dev/null 2>&1 || true
  fi
  # The compose file's image name: removed if built here, untagged if it names a reused image,
  # and given back to the image it named before the test.
  if [ "$made_image" = 1 ]; then
    "${podman[@]}" rmi "$image" >/dev/null 2>&1 || true
    if [ -z "$reuse" ] && [ "${SOFTID_CONTAINER_KEEP_CACHE:-0}" != 1 ]; then
      "${podman[@]}" image prune -f >/dev/null 2>&1 || true
    fi
  fi
  if [ -n "$previous_image" ]; then "${podman[@]}" tag "$previous_image" "$image" || true; fi
  rm -rf "$tmp"
}
trap cleanup EXIT

if ! command -v podman-compose >/dev/null || [ ! -x /usr/lib/cni/dnsname ]; then
  # dnsname: containers on a compose network find each other by service name (postgres).
  apt_install_or_skip podman-compose golang-github-containernetworking-plugin-dnsname
fi
prepare_podman
podman-compose version >/dev/null 2>&1 || skip "podman-compose does not run"
previous_image=$("${podman[@]}" image inspect -f '{{.Id}}' "$image" 2>/dev/null || true)

if [ -n "$reuse" ]; then
  echo "== the image: $reuse (SOFTID_COMPOSE_IMAGE)"
  "${podman[@]}" image exists "$reuse" || fail "no image $reuse"
  "${podman[@]}" tag "$reuse" "$image"
  made_image=1
else
  echo "== build the image (deploy/Dockerfile) as $image"
  build_start=$(date +%s)
  made_image=1
  nice -n 15 "${podman[@]}" build --format docker --network host --pull=never -q \
    -f "$source_dir/deploy/Dockerfile" -t "$image" "$source_dir" >"$tmp/build.log" 2>&1 ||
    { tail -n 40 "$tmp/build.log" >&2; fail "podman build failed"; }
  echo "built in $(($(date +%s) - build_start)) s"
fi
if "${podman[@]}" image exists "$postgres_image"; then
  echo "== PostgreSQL: the local $postgres_image"
else
  echo "== PostgreSQL: no $postgres_image here; building one from Debian's postgresql-15"
  made_postgres_image=1
  nice -n 15 "${podman[@]}" build --format docker --network host --pull=never -q \
    -t "$postgres_image" "$source_dir/tests/deploy/postgres" >"$tmp/postgres-build.log" 2>&1 ||
    { tail -n 40 "$tmp/postgres-build.log" >&2; fail "building the PostgreSQL image failed"; }
fi

# depends_on with conditions, by hand: the database accepts connections before the API starts,
# and the API has made the TLS certificate in the shared volume before the workers start.
echo "== podman-compose up: postgres, then api, then worker (x2)"
"${compose[@]}" up -d postgres >"$tmp/up-postgres.log" 2>&1 ||
  { cat "$tmp/up-postgres.log" >&2; fail "podman-compose up postgres"; }
postgres=$(containers postgres)
[ -n "$postgres" ] || fail "no postgres container"
for _ in $(seq 120); do
  "${podman[@]}" exec "$postgres" pg_isready -U softid -d softid >/dev/null 2>&1 && break
  sleep 0.5
done
"${podman[@]}" exec "$postgres" pg_isready -U softid -d softid || fail "PostgreSQL is not ready"

"${compose[@]}" up -d api >"$tmp/up-api.log" 2>&1 ||
  { cat "$tmp/up-api.log" >&2; fail "podman-compose up api"; }
api=$(containers api)
[ -n "$api" ] || fail "no api container"
for _ in $(seq 100); do
  "${podman[@]}" exec "$api" test -s /var/lib/softid/tls/server.crt 2>/dev/null && break
  sleep 0.2
done
"${podman[@]}" exec "$api" cat /var/lib/softid/tls/server.crt >"$tmp/softid.crt" ||
  fail "no self-signed certificate in the data volume"
softid=("$client" --server "localhost:$port" --retry-for 0 --timeout 10 --tls-ca "$tmp/softid.crt")
for _ in $(seq 100); do
  "${softid[@]}" health >/dev/null 2>&1 && break
  sleep 0.2
done
"${softid[@]}" health || fail "the API's health over TLS on port $port"

"${compose[@]}" up -d >"$tmp/up.log" 2>&1 || { cat "$tmp/up.log" >&2; fail "podman-compose up"; }
mapfile -t workers < <(containers worker)
[ "${#workers[@]}" -eq 2 ] || fail "expected 2 worker containers, found ${#workers[@]}: ${workers[*]}"
for worker in "${workers[@]}"; do
  for _ in $(seq 50); do
    "${podman[@]}" healthcheck run "$worker" >/dev/null 2>&1 && break
    sleep 0.2
  done
  "${podman[@]}" healthcheck run "$worker" >/dev/null 2>&1 || fail "$worker is not healthy"
done
"${podman[@]}" healthcheck run "$api" >/dev/null 2>&1 || fail "$api is not healthy"
echo "running: $postgres $api ${workers[*]}"

echo "== a station's job through the API"
token=$("${podman[@]}" exec "$api" softid-server tokens create --station lab-1 |
  grep -o 'softid_[A-Za-z0-9_-]*' | head -n 1)
[ -n "$token" ] || fail "tokens create printed no token"
"$lab" synth --scene torus-drop --out "$tmp/capture" >/dev/null
# Through the first impact (frame ~20): before it, free fall shows nothing E moves.
cat >"$tmp/job.json" <<'JSON'
{"fit": ["youngs_modulus"], "initial": {"youngs_modulus": {"min": 2e4, "max": 1e5}},
 "fixed": {"poisson_ratio": 0.35, "ground": {"normal": [0, 0, 1], "offset": 0}},
 "cells": 10, "substeps": 4, "frames": {"first": 0, "last": 24}, "starts": 1, "max_iterations": 2}
JSON
station=("${softid[@]}" --token "$token")
job_start=$(date +%s)
submitted=$("${station[@]}" --json submit "$tmp/capture" --config "$tmp/job.json")
job=$(sed -n 's/.*"id":"\(job-[0-9a-f]*\)".*/\1/p' <<<"$submitted")
[ -n "$job" ] || fail "no job id in: $submitted"
"${station[@]}" watch "$job" >/dev/null || fail "watching $job"
final=$("${station[@]}" --json status "$job")
grep -q '"state":"SUCCEEDED"' <<<"$final" || fail "$job did not succeed: $final"
echo "$job SUCCEEDED in $(($(date +%s) - job_start)) s"

echo "== who ran it (logs)"
# Logs to files first: `podman logs | grep -q` fails under pipefail when grep stops reading early.
for name in "$api" "${workers[@]}"; do "${podman[@]}" logs "$name" >"$tmp/$name.log" 2>&1; done
ran_on=()
for worker in "${workers[@]}"; do
  if grep -q "job $job: RUNNING on" "$tmp/$worker.log"; then ran_on+=("$worker"); fi
done
[ "${#ran_on[@]}" -ge 1 ] || fail "no worker container logged running $job"
grep -q "job $job: SUCCEEDED" "$tmp/${ran_on[0]}.log" || fail "${ran_on[0]} did not log $job SUCCEEDED"
if grep -Eq "RUNNING on|job $job: SUCCEEDED" "$tmp/$api.log"; then
  fail "the API container ran a fit"
fi
grep -q "job $job: QUEUED" "$tmp/$api.log" || fail "the API container did not log taking $job"
echo "ran on ${ran_on[*]}; the API only took the job"

echo "== stop (SIGTERM to the softid services): every container exits 0"
"${compose[@]}" stop -t 30 >"$tmp/stop.log" 2>&1 || { cat "$tmp/stop.log" >&2; fail "podman-compose stop"; }
for name in "$api" "${workers[@]}" "$postgres"; do
  status=$("${podman[@]}" inspect -f '{{.State.ExitCode}}' "$name")
  [ "$status" = 0 ] || fail "$name exited with $status"
done
"${podman[@]}" logs "$api" >"$tmp/$api.log" 2>&1
grep -q "shut down" "$tmp/$api.log" || fail "$api did not log its shutdown"
if [ "$keep" != 1 ]; then
  "${compose[@]}" down -v >"$tmp/down.log" 2>&1 || { cat "$tmp/down.log" >&2; fail "podman-compose down"; }
  [ -z "$("${podman[@]}" ps -aq --filter "label=io.podman.compose.project=$project")" ] ||
    fail "podman-compose down left containers"
fi
echo "ok: the multi-node compose file runs with podman-compose: a worker ran the job, the API" \
  "took it, every container stopped with exit code 0"
