#!/usr/bin/env bash
# Installs the dependencies and builds softid (Release) into ${SOFTID_BUILD_DIR:-build}.
set -euo pipefail
cd "$(dirname "$0")/.."
bash deploy/install-deps.sh
build_dir=${SOFTID_BUILD_DIR:-build}
cmake -S . -B "$build_dir" -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$build_dir" -j "$(nproc)"
