#!/usr/bin/env bash
# Usage: lab_commands_test.sh BUILD_DIR
# softid-lab as a user meets it: every subcommand answers --help with an example; bad input (an
# unknown scene, a missing folder, a config key that does not exist, a bad flag value) is refused
# with a non-zero exit and a message naming what was wrong; and a small synth -> fit -> diagnose
# round trip writes its files (making the output folder): result.json with the fitted value, its
# unit and its uncertainty, the report's PNGs, diagnosis.json.
set -euo pipefail

lab=$(cd "${1:?usage: lab_commands_test.sh BUILD_DIR}" && pwd)/core/lab/softid-lab
[ -x "$lab" ] || { echo "SKIP: $lab is not built"; exit 77; }
work=$(mktemp -d /tmp/softid-lab-test.XXXXXX)
trap 'rm -rf "$work"' EXIT

fail() { echo "FAIL: $*" >&2; exit 1; }
# Runs softid-lab ARGS...; it must fail and its output must contain EXPECTED.
refuses() {
  local expected=$1
  shift
  local out status=0
  out=$("$lab" "$@" 2>&1) || status=$?
  [ "$status" -ne 0 ] || fail "softid-lab $* exited 0"
  grep -qF -- "$expected" <<<"$out" || fail "softid-lab $*: no '$expected' in: $out"
}

for command in synth simulate modes bench ingest fit diagnose prove-diagnosis prove-ingest reproduce; do
  help=$("$lab" "$command" --help) || fail "$command --help exited non-zero"
  grep -q "softid-lab $command" <<<"$help" || fail "$command --help shows no example"
done

refuses "no-such-scene" synth --scene no-such-scene --out "$work/x"
refuses "$work/missing" fit "$work/missing" -o "$work/r.json"
refuses "--cameras" synth --cameras zero --out "$work/x"
refuses "--modes" modes --scene bar-hanging --modes 0
refuses "--grid-orientation" modes --scene bar-hanging --grid-orientation sideways

# The clamped bar's lowest modes: no rigid ones, ascending, and E fitted to a reference frequency.
"$lab" modes --scene bar-hanging --cells 8 --modes 3 --reference-hz 1 -o "$work/modes.json" \
  >"$work/modes.log" 2>&1 || fail "modes: $(tail -5 "$work/modes.log")"
python3 - "$work/modes.json" <<'PY' || fail "modes.json"
import json, sys
m = json.load(open(sys.argv[1]))
f = m["frequencies_hz"]
assert m["rigid_modes"] == 0 and len(f) == 3 and 0 < f[0] <= f[1] <= f[2], m
assert abs(m["expected_fitted_youngs_modulus"] - m["youngs_modulus"] / f[0] ** 2) < 1e-9 * m["youngs_modulus"], m
PY

"$lab" synth --scene torus-drop --duration 0.2 --cameras 1 --width 40 --height 40 --cells 8 \
  --substeps 2 --out "$work/capture" >/dev/null 2>&1 || fail "synth"
[ -f "$work/capture/capture.json" ] && [ -f "$work/capture/truth.json" ] || fail "synth wrote no capture"

cat >"$work/bad.json" <<'JSON'
{"fit": ["youngs_modulus"], "no_such_key": 1}
JSON
refuses "no_such_key" fit "$work/capture" --config "$work/bad.json" -o "$work/r.json"

cat >"$work/job.json" <<'JSON'
{"fit": ["youngs_modulus"], "initial": {"youngs_modulus": {"min": 1e4, "max": 1e5}},
 "fixed": {"ground": {"normal": [0, 0, 1], "offset": 0}},
 "cells": 8, "substeps": 2, "starts": 1, "max_iterations": 4, "threads": 1}
JSON
"$lab" fit "$work/capture" --config "$work/job.json" -o "$work/result.json" >"$work/fit.log" 2>&1 ||
  fail "fit: $(tail -5 "$work/fit.log")"
python3 - "$work/result.json" <<'PY' || fail "result.json"
import json, math, sys
r = json.load(open(sys.argv[1]))
e = r["parameters"]["youngs_modulus"]
assert r["format"] == "softid-result/1", r["format"]
assert e["unit"] == "Pa" and e["value"] > 0, e
assert math.isfinite(e["standard_uncertainty"]) and e["standard_uncertainty"] > 0, e
assert r["cost"]["final"] < r["cost"]["initial"], r["cost"]
assert len(r["report"]["files"]) == 3, r["report"]
PY
for png in "$work"/report/*.png; do
  [ "$(head -c 4 "$png" | tail -c 3)" = "PNG" ] || fail "$png is not a PNG"
done

# -o into a folder that does not exist yet: made, as the report's is.
"$lab" diagnose "$work/capture" --config "$work/job.json" -o "$work/new/diagnosis.json" \
  >"$work/diagnose.log" 2>&1 || fail "diagnose: $(tail -5 "$work/diagnose.log")"
python3 -c "import json,sys; d=json.load(open(sys.argv[1])); assert 'decision' in d, list(d)" \
  "$work/new/diagnosis.json" || fail "diagnosis.json has no decision"
touch "$work/file"
refuses "cannot create its folder $work/file/sub" fit "$work/capture" --config "$work/job.json" \
  -o "$work/file/sub/result.json" --no-report
# A reproduce row's result records the grid and time step its starts were fitted on.
"$lab" reproduce table1 --quick --starts 1 --max-iterations 1 --cells 6 --substeps 2 \
  --out "$work/reproduce" >"$work/reproduce.log" 2>&1 || true  # one iteration misses the target
python3 - "$work"/reproduce/table1-*.json <<'PY' || fail "reproduce row: $(tail -5 "$work/reproduce.log")"
import json, sys
row = [f for f in sys.argv[1:] if not f.endswith("summary.json")][0]
r = json.load(open(row))
assert r["grid"]["cells"] == 6 and r["grid"]["cell_size_m"] > 0, r["grid"]
assert r["time_step"]["substeps"] == 2, r["time_step"]
PY
echo "softid-lab commands: ok"
