#!/usr/bin/env bash
# Usage: packages_test.sh BUILD_DIR CPACK
# The Debian packages as a station or a server host gets them: builds softid-client and
# softid-server with CPack from the built tree, checks their names, dependencies (from
# dpkg-shlibdeps) and contents, then unpacks the client alone and asks the built server for its
# health with it over a real connection.
set -euo pipefail

build_dir=$(cd "$1" && pwd)
cpack_bin=$2
tmp=$(mktemp -d /tmp/softid-packages.XXXXXX)
server_pid=""
cleanup() {
  if [ -n "$server_pid" ]; then kill -TERM "$server_pid" 2>/dev/null || true; fi
  wait 2>/dev/null || true
  rm -rf "$tmp"
}
trap cleanup EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
command -v dpkg-deb >/dev/null && command -v dpkg-shlibdeps >/dev/null ||
  { echo "SKIP: dpkg-deb or dpkg-shlibdeps missing (dpkg-dev)"; exit 77; }

(cd "$build_dir" && "$cpack_bin" -G DEB -B "$tmp/out" >"$tmp/cpack.log" 2>&1) ||
  { cat "$tmp/cpack.log" >&2; fail "cpack failed"; }
client_deb=$(ls "$tmp"/out/softid-client_*.deb 2>/dev/null | head -n 1)
server_deb=$(ls "$tmp"/out/softid-server_*.deb 2>/dev/null | head -n 1)
[ -n "$client_deb" ] || fail "no softid-client package in: $(ls "$tmp/out")"
[ -n "$server_deb" ] || fail "no softid-server package in: $(ls "$tmp/out")"

expect_field() {  # DEB FIELD EXTENDED-REGEX
  local value
  value=$(dpkg-deb -f "$1" "$2")
  grep -Eq -- "$3" <<<"$value" || fail "$(basename "$1"): $2 = '$value' does not match /$3/"
}
expect_file() {  # DEB PATH
  dpkg-deb -c "$1" | awk '{print $NF}' | grep -qx -- "$2" || fail "$(basename "$1") lacks $2"
}
expect_field "$client_deb" Package '^softid-client$'
expect_field "$server_deb" Package '^softid-server$'
expect_field "$client_deb" Architecture '^amd64$|^arm64$'
expect_field "$client_deb" Depends 'libgrpc\+\+'
expect_field "$client_deb" Depends 'libprotobuf'
expect_field "$server_deb" Depends 'libceres|libcholmod'
expect_field "$server_deb" Depends 'libsqlite3'
expect_file "$client_deb" ./usr/bin/softid
expect_file "$client_deb" ./usr/share/softid/proto/softid/v1/softid.proto
expect_file "$server_deb" ./usr/bin/softid-server
expect_file "$server_deb" ./usr/bin/softid-lab
# A station's package carries none of the numerical stack.
if dpkg-deb -f "$client_deb" Depends | grep -Eq 'ceres|cholmod|opencv|embree|assimp|openblas'; then
  fail "softid-client depends on the numerical stack: $(dpkg-deb -f "$client_deb" Depends)"
fi
if dpkg-deb -c "$client_deb" | grep -q softid-server; then fail "softid-client holds the server"; fi

dpkg-deb -x "$client_deb" "$tmp/station"
client=$tmp/station/usr/bin/softid
"$client" --help >/dev/null || fail "the unpacked client does not run"
"$build_dir/server/softid-server" --listen localhost:0 --port-file "$tmp/port" --data "$tmp/data" \
  --workers 0 >"$tmp/server.log" 2>&1 &
server_pid=$!
for _ in $(seq 100); do [ -s "$tmp/port" ] && break; sleep 0.1; done
[ -s "$tmp/port" ] || { cat "$tmp/server.log" >&2; fail "softid-server did not start"; }
"$client" --server "localhost:$(cat "$tmp/port")" --retry-for 5 health | grep -q SERVING ||
  fail "the unpacked client got no SERVING from the server"
echo "ok: softid-client and softid-server packages built, checked, and the client works unpacked"
