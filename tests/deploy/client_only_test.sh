#!/usr/bin/env bash
# Usage: client_only_test.sh SOURCE_DIR CMAKE
# A capture station's build: configures with -DSOFTID_CLIENT_ONLY=ON in a fresh folder and builds
# the client, then checks that neither the configure nor the binary touched the numerical stack
# (no Eigen, CHOLMOD, Ceres, Embree, OpenCV or assimp in the cache or in ldd) and that it runs.
set -euo pipefail

source_dir=$(cd "$1" && pwd)
cmake_bin=$2
tmp=$(mktemp -d /tmp/softid-client-only.XXXXXX)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }

generator=()
command -v ninja >/dev/null && generator=(-G Ninja)
"$cmake_bin" -S "$source_dir" -B "$tmp/build" "${generator[@]}" -DSOFTID_CLIENT_ONLY=ON \
  >"$tmp/configure.log" 2>&1 || { cat "$tmp/configure.log" >&2; fail "configure failed"; }
"$cmake_bin" --build "$tmp/build" --target softid -j "$(nproc)" >"$tmp/build.log" 2>&1 ||
  { tail -n 40 "$tmp/build.log" >&2; fail "build failed"; }

for package in Eigen3 Ceres embree assimp OpenCV Cholmod GTest benchmark; do
  if grep -Eq "^${package}_DIR:|^${package}_FOUND" "$tmp/build/CMakeCache.txt"; then
    fail "the client-only configure looked for $package"
  fi
done
client=$tmp/build/client/softid
libraries=$(ldd "$client")
if grep -Eiq 'ceres|cholmod|opencv|embree|assimp|openblas|spdlog' <<<"$libraries"; then
  fail "the client links the numerical stack:
$libraries"
fi
"$client" --help | grep -q "submit" || fail "the client-only softid does not run"
echo "ok: the client builds alone ($(wc -l <<<"$libraries") shared libraries, none numerical)"
