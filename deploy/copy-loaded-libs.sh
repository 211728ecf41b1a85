#!/usr/bin/env bash
# Usage: copy-loaded-libs.sh PACKAGE_LIST OUT_DIR BINARY...
# Run in the image's build stage. Some packages of deploy/runtime-packages.txt are marked
# "[libs only]": installing them with apt would pull in large dependency chains the binaries never
# load (Mesa's GLX driver with LLVM, VTK's MPI and Tk modules, PROJ's data). For those packages
# this copies only the shared libraries that ldd shows for BINARY... and that the package ships,
# into OUT_DIR under the name the loader looks for; the runtime stage installs the rest with apt.
# Fails when a marked package ships none of the loaded libraries (the mark is stale).
set -euo pipefail

list=$1
out=$2
shift 2

declare -A marked=() copied=()
while read -r package; do
  [ -n "$package" ] && marked[$package]=1
done < <(grep -E '#.*\[libs only\]' "$list" | sed -e 's/#.*//' -e 's/[[:space:]]//g')
[ "${#marked[@]}" -gt 0 ] || { echo "copy-loaded-libs: no package is marked [libs only]" >&2; exit 0; }
mkdir -p "$out"

ldd_out=$(ldd "$@")
if grep -q 'not found' <<<"$ldd_out"; then
  echo "copy-loaded-libs: unresolved libraries:" >&2
  grep 'not found' <<<"$ldd_out" >&2
  exit 1
fi
while read -r library; do
  real=$(readlink -f "$library")
  # dpkg knows a file under /usr/lib or /lib (merged /usr): "libfoo1:amd64: /usr/lib/...".
  owner=$(dpkg -S "$real" 2>/dev/null || dpkg -S "${real#/usr}" 2>/dev/null || true)
  package=${owner%%: /*}
  package=${package%%,*}
  package=${package%%:*}
  [ -n "$package" ] && [ -n "${marked[$package]:-}" ] || continue
  cp -L "$library" "$out/$(basename "$library")"
  copied[$package]=1
done < <(awk '$2 == "=>" && $3 ~ /^\// {print $3}' <<<"$ldd_out" | sort -u)

for package in "${!marked[@]}"; do
  if [ -z "${copied[$package]:-}" ]; then
    echo "copy-loaded-libs: $package is marked [libs only] but ships no library the binaries load" >&2
    exit 1
  fi
done
echo "copy-loaded-libs: $(find "$out" -type f | wc -l) libraries from ${#copied[@]} packages," \
  "$(du -sm "$out" | cut -f1) MB"
