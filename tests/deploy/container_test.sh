#!/usr/bin/env bash
# Usage: container_test.sh SOURCE_DIR BUILD_DIR
# The image for real: builds deploy/Dockerfile with podman (a Docker-compatible engine from
# Debian; no daemon), runs it as an operator would (image defaults, a port published on the
# host's loopback, a host folder as the data volume), and checks from the host with the host's
# client: TLS is on with the certificate the server made (plain text and a stranger's CA are
# refused), calls without a token are UNAUTHENTICATED, a station token made with `podman exec`
# submits a torus-drop job that SUCCEEDS, the image's HEALTHCHECK passes, the key is private and
# the data owned by the image's user, and `podman stop` (SIGTERM through tini) exits 0.
# Prepares podman (idempotent); removes what it made. The image is built in Docker format: OCI
# images have no HEALTHCHECK.
# Takes 15-30 minutes on 2 cores (the image build dominates; SOFTID_CONTAINER_KEEP_CACHE=1 keeps
# the build's layers for the next run). Exit 77 (CTest: skipped) when podman cannot be installed
# or run here.
set -euo pipefail

source_dir=$(cd "$1" && pwd)
build_dir=$(cd "$2" && pwd)
client=$build_dir/client/softid
lab=$build_dir/core/lab/softid-lab
podman=(podman --runtime runc)
image=localhost/softid-container-test:latest
name=softid-container-test-$$

skip() { echo "SKIP: $*"; exit 77; }
fail() {
  echo "FAIL: $*" >&2
  "${podman[@]}" logs "$name" 2>&1 | tail -n 30 >&2 || true
  exit 1
}

[ "$(id -u)" -eq 0 ] || skip "needs root to install and run podman"
[ -x "$client" ] && [ -x "$lab" ] || skip "softid and softid-lab are not built in $build_dir"

# shellcheck source=tests/deploy/podman_prepare.sh
source "$(dirname "$0")/podman_prepare.sh"

tmp=$(mktemp -d /tmp/softid-container.XXXXXX)
cleanup() {
  "${podman[@]}" rm -f -t 0 "$name" >/dev/null 2>&1 || true
  "${podman[@]}" rmi -f "$image" >/dev/null 2>&1 || true
  # The build's intermediate layers too, unless kept to make the next run faster.
  if [ "${SOFTID_CONTAINER_KEEP_CACHE:-0}" != 1 ]; then
    "${podman[@]}" image prune -f >/dev/null 2>&1 || true
  fi
  rm -rf "$tmp"
}
trap cleanup EXIT

prepare_podman
echo "== build the image (deploy/Dockerfile)"
build_start=$(date +%s)
"${podman[@]}" build --format docker --network host --pull=never -q -f "$source_dir/deploy/Dockerfile" \
  -t "$image" "$source_dir" >"$tmp/build.log" 2>&1 ||
  { tail -n 40 "$tmp/build.log" >&2; fail "podman build failed"; }
echo "built in $(($(date +%s) - build_start)) s"

echo "== run it with the image's defaults"
mkdir -p "$tmp/data"
chown 10001:10001 "$tmp/data"
port=$((20000 + RANDOM % 30000))
"${podman[@]}" run -d --name "$name" -p "127.0.0.1:$port:50051" -v "$tmp/data:/var/lib/softid" \
  -e SOFTID_WORKERS=1 -e SOFTID_TLS_HOSTNAMES=softid.test.example "$image" >/dev/null ||
  fail "podman run failed"
for _ in $(seq 100); do
  [ -s "$tmp/data/tls/server.crt" ] && break
  sleep 0.2
done
[ -s "$tmp/data/tls/server.crt" ] || fail "no self-signed certificate in the data volume"
cp "$tmp/data/tls/server.crt" "$tmp/softid.crt"
softid=("$client" --server "localhost:$port" --retry-for 0 --timeout 10)
tls=(--tls-ca "$tmp/softid.crt")
for _ in $(seq 50); do
  "${softid[@]}" "${tls[@]}" health >/dev/null 2>&1 && break
  sleep 0.2
done
"${softid[@]}" "${tls[@]}" health || fail "health over TLS with the server's certificate"

echo "== TLS and tokens are on"
if "${softid[@]}" health >/dev/null 2>&1; then fail "plain text was accepted"; fi
openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -days 1 \
  -subj /CN=stranger -keyout "$tmp/stranger.key" -out "$tmp/stranger.crt" >/dev/null 2>&1
if "${softid[@]}" --tls-ca "$tmp/stranger.crt" health >/dev/null 2>&1; then
  fail "a client trusting another CA connected"
fi
set +e
unauthenticated=$("${softid[@]}" "${tls[@]}" list 2>&1)
set -e
grep -q "UNAUTHENTICATED" <<<"$unauthenticated" || fail "list without a token: $unauthenticated"
token=$("${podman[@]}" exec "$name" softid-server tokens create --station lab-1 |
  grep -o 'softid_[A-Za-z0-9_-]*' | head -n 1)
[ -n "$token" ] || fail "tokens create printed no token"
openssl x509 -noout -text -in "$tmp/softid.crt" | grep -q "DNS:softid.test.example" ||
  fail "the certificate does not name SOFTID_TLS_HOSTNAMES"

echo "== a station's job"
"$lab" synth --scene torus-drop --out "$tmp/capture" >/dev/null
# Through the first impact (frame ~20): before it, free fall shows nothing E moves.
cat >"$tmp/job.json" <<'JSON'
{"fit": ["youngs_modulus"], "initial": {"youngs_modulus": {"min": 2e4, "max": 1e5}},
 "fixed": {"poisson_ratio": 0.35, "ground": {"normal": [0, 0, 1], "offset": 0}},
 "cells": 10, "substeps": 4, "frames": {"first": 0, "last": 24}, "starts": 1, "max_iterations": 2}
JSON
station=("${softid[@]}" "${tls[@]}" --token "$token")
submitted=$("${station[@]}" --json submit "$tmp/capture" --config "$tmp/job.json")
job=$(sed -n 's/.*"id":"\(job-[0-9a-f]*\)".*/\1/p' <<<"$submitted")
[ -n "$job" ] || fail "no job id in: $submitted"
"${station[@]}" watch "$job" >/dev/null || fail "watching $job"
"${station[@]}" --json status "$job" | grep -q '"state":"SUCCEEDED"' || fail "$job did not succeed"

echo "== health check, files, SIGTERM"
"${podman[@]}" healthcheck run "$name" || fail "the image's HEALTHCHECK failed"
[ "$(stat -c '%u %a' "$tmp/data/tls/server.key")" = "10001 600" ] ||
  fail "key: $(stat -c '%u %a' "$tmp/data/tls/server.key"), expected owner 10001, mode 600"
[ "$(stat -c '%u' "$tmp/data/softid.db")" = 10001 ] || fail "softid.db not owned by 10001"
"${podman[@]}" stop -t 30 "$name" >/dev/null
status=$("${podman[@]}" inspect -f '{{.State.ExitCode}}' "$name")
[ "$status" = 0 ] || fail "softid-server exited with $status on SIGTERM"
echo "ok: the image serves TLS with tokens, runs a station's job, and stops cleanly"
