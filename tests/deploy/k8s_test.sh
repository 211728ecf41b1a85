#!/usr/bin/env bash
# Usage: k8s_test.sh SOURCE_DIR
# No cluster runs here, so deploy/k8s is checked offline: every manifest against the Kubernetes
# and KEDA schemas carried by the npm packages kubernetes-models and @kubernetes-models/keda
# (tests/deploy/k8s/package.json pins them), installed into a temporary folder, plus what the
# deployment relies on (tests/deploy/k8s/validate.mjs). Exit 77 (SKIPPED) without node and npm or
# when the npm registry cannot be reached.
set -euo pipefail

source_dir=$1
command -v node > /dev/null && command -v npm > /dev/null ||
  { echo "k8s_test: node and npm are needed to check the manifests; skipped" >&2; exit 77; }
work=$(mktemp -d /tmp/softid-k8s.XXXXXX)
trap 'rm -rf "$work"' EXIT
cp "$source_dir/tests/deploy/k8s/package.json" "$source_dir/tests/deploy/k8s/validate.mjs" "$work/"
if ! (cd "$work" && timeout 300 npm install --no-audit --no-fund --loglevel=error > npm.log 2>&1); then
  echo "k8s_test: npm install failed (registry unreachable?); skipped:" >&2
  tail -5 "$work/npm.log" >&2
  exit 77
fi
node "$work/validate.mjs" "$source_dir/deploy/k8s"
