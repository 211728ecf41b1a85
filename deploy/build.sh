#!/usr/bin/env bash
# Installs the dependencies and builds softid (Release) into ${SOFTID_BUILD_DIR:-build}: every
# target, or only the targets named as arguments (e.g. softid-server softid softid-lab).
set -euo pipefail
cd "$(dirname "$0")/.."
bash deploy/install-deps.sh
build_dir=${SOFTID_BUILD_DIR:-build}
cmake -S . -B "$build_dir" -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
if [ "$#" -gt 0 ]; then
  cmake --build "$build_dir" -j "$(nproc)" --target "$@"
else
  cmake --build "$build_dir" -j "$(nproc)"
fi
