#!/usr/bin/env bash
# The main job end to end on the embedded defaults: install, build, synthesise a depth capture of
# the torus-drop scene, and show where it went and what is in it.
set -euo pipefail
cd "$(dirname "$0")/.."
bash deploy/build.sh
build_dir=${SOFTID_BUILD_DIR:-build}
out=${SOFTID_OUT:-$(mktemp -d /tmp/softid-capture.XXXXXX)}
"$build_dir/core/lab/softid-lab" synth --scene torus-drop --out "$out"
echo
echo "files:"
(cd "$out" && ls -d capture.json truth.json object.obj preview.png cam*/ && echo "frames per camera: $(ls cam0 | wc -l)")
