#!/usr/bin/env bash
# Installs the dependencies, builds everything and runs the whole test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
bash deploy/build.sh
build_dir=${SOFTID_BUILD_DIR:-build}
# The container tests (label "container": build and run the image with podman, and the
# multi-node compose file with podman-compose, 15-20 minutes each) run only when asked for:
# SOFTID_TEST_CONTAINER=1.
exclude=(-LE container)
[ "${SOFTID_TEST_CONTAINER:-0}" = 1 ] && exclude=()
ctest --test-dir "$build_dir" --output-on-failure -j "$(nproc)" "${exclude[@]}"
