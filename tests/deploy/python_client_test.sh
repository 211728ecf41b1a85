#!/usr/bin/env bash
# Usage: python_client_test.sh SOURCE_DIR BUILD_DIR CMAKE
# A second language proves the API as documented: installs the client component (the .proto files
# under share/softid/proto), generates the Python modules from that installed copy with
# clients/python/generate.sh, and runs clients/python/softid_client.py against the real
# softid-server with a station token: upload a synthetic capture, a small job, watch, result.
set -euo pipefail

source_dir=$(cd "$1" && pwd)
build_dir=$(cd "$2" && pwd)
cmake_bin=$3
python=${SOFTID_PYTHON:-/usr/bin/python3}
tmp=$(mktemp -d /tmp/softid-python.XXXXXX)
server_pid=""
cleanup() {
  if [ -n "$server_pid" ]; then kill -TERM "$server_pid" 2>/dev/null || true; fi
  wait 2>/dev/null || true
  rm -rf "$tmp"
}
trap cleanup EXIT
fail() {
  echo "FAIL: $*" >&2
  [ -f "$tmp/server.log" ] && tail -n 20 "$tmp/server.log" >&2
  exit 1
}
"$python" -c "import grpc, google.protobuf" 2>/dev/null ||
  { echo "SKIP: $python lacks grpc or protobuf (python3-grpcio, python3-protobuf)"; exit 77; }

"$cmake_bin" --install "$build_dir" --component client --prefix "$tmp/prefix" >/dev/null
bash "$source_dir/clients/python/generate.sh" "$tmp/prefix/share/softid/proto" "$tmp/gen" >/dev/null

"$build_dir/core/lab/softid-lab" synth --scene torus-drop --out "$tmp/capture" >/dev/null 2>&1 ||
  fail "softid-lab synth"
cat >"$tmp/job.json" <<'JSON'
{"fit": ["youngs_modulus"], "initial": {"youngs_modulus": {"min": 2e4, "max": 1e5}},
 "fixed": {"poisson_ratio": 0.35, "ground": {"normal": [0, 0, 1], "offset": 0}},
 "cells": 10, "substeps": 4, "frames": {"first": 0, "last": 24}, "starts": 1, "max_iterations": 2}
JSON
server=$build_dir/server/softid-server
token=$("$server" tokens create --data "$tmp/data" --station python-station | head -n 1)
"$server" --listen localhost:0 --port-file "$tmp/port" --data "$tmp/data" --workers 1 \
  --auth token >"$tmp/server.log" 2>&1 &
server_pid=$!
for _ in $(seq 100); do [ -s "$tmp/port" ] && break; sleep 0.1; done
[ -s "$tmp/port" ] || fail "softid-server did not start"

client=("$python" "$source_dir/clients/python/softid_client.py" --server "localhost:$(cat "$tmp/port")")
export SOFTID_PYTHON_GEN=$tmp/gen
if "${client[@]}" "$tmp/capture" --config "$tmp/job.json" --out "$tmp/none.json" >"$tmp/anon.log" 2>&1; then
  fail "a call without a token succeeded"
fi
grep -q UNAUTHENTICATED "$tmp/anon.log" || fail "without a token: $(cat "$tmp/anon.log")"
"${client[@]}" --token "$token" "$tmp/capture" --config "$tmp/job.json" --out "$tmp/result.json" \
  >"$tmp/client.log" 2>&1 || { cat "$tmp/client.log" >&2; fail "the Python client failed"; }
grep -q "iteration 2/2" "$tmp/client.log" || fail "no progress watched: $(cat "$tmp/client.log")"
"$python" - "$tmp/result.json" <<'PY' || fail "result.json: $(head -c 400 "$tmp/result.json")"
import json, sys
result = json.load(open(sys.argv[1]))
assert result["format"] == "softid-result/1", result["format"]
value = result["parameters"]["youngs_modulus"]["value"]
assert 2e4 / 10 < value < 1e5 * 10, value
PY
echo "ok: the Python client uploaded, watched and fetched a result through the documented API"
