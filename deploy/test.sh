#!/usr/bin/env bash
# Installs the dependencies, builds everything and runs the whole test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
bash deploy/build.sh
build_dir=${SOFTID_BUILD_DIR:-build}
# The container test (label "container": builds and runs the image with podman, 15-20 minutes)
# runs only when asked for: SOFTID_TEST_CONTAINER=1.
exclude=(-LE container)
[ "${SOFTID_TEST_CONTAINER:-0}" = 1 ] && exclude=()
ctest --test-dir "$build_dir" --output-on-failure -j "$(nproc)" "${exclude[@]}"
