#!/usr/bin/env bash
# Installs the dependencies and builds softid (Release) into ${SOFTID_BUILD_DIR:-build}: every
# target, or only the targets named as arguments (e.g. softid-server softid softid-lab).
# SOFTID_CPU_LEVEL (default auto: x86-64-v3 when this machine has it) sets -march; x86-64 builds
# binaries for any x86-64 host.
set -euo pipefail
cd "$(dirname "$0")/.."
bash deploy/install-deps.sh
build_dir=${SOFTID_BUILD_DIR:-build}
cmake -S . -B "$build_dir" -G Ninja -DCMAKE_BUILD_TYPE=Release \
  -DSOFTID_CPU_LEVEL="${SOFTID_CPU_LEVEL:-auto}" >/dev/null
if [ "$#" -gt 0 ]; then
  cmake --build "$build_dir" -j "$(nproc)" --target "$@"
else
  cmake --build "$build_dir" -j "$(nproc)"
fi
