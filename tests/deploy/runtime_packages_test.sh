#!/usr/bin/env bash
# Usage: runtime_packages_test.sh SOURCE_DIR BUILD_DIR
# The runtime image installs only deploy/runtime-packages.txt. Proves without a Docker engine
# that this is enough: installs the binaries to a temporary prefix, resolves every shared library
# they load (ldd), finds the Debian package that ships it (dpkg -S), and requires that package to
# be on the list; and every package marked [libs only] (the image takes just its loaded libraries)
# must ship one of them. Exit 77 (CTest skip) only when ldd or dpkg is missing (not a Debian
# system).
set -euo pipefail

source_dir=$1
build_dir=$2
cmake_bin=${CMAKE:-cmake}
list=$source_dir/deploy/runtime-packages.txt
dockerfile=$source_dir/deploy/Dockerfile

skip() { echo "SKIP: $*"; exit 77; }
fail() { echo "FAIL: $*" >&2; exit 1; }

command -v ldd >/dev/null || skip "ldd not found"
command -v dpkg >/dev/null || skip "dpkg not found (not a Debian system)"
[ -f "$list" ] || fail "$list is missing"
grep -q '^COPY deploy/runtime-packages.txt ' "$dockerfile" ||
  fail "$dockerfile does not install deploy/runtime-packages.txt"

declare -A listed=()
while read -r package; do
  [ -n "$package" ] && listed[$package]=1
done < <(sed -e 's/#.*//' -e 's/[[:space:]]//g' "$list")
[ "${#listed[@]}" -gt 0 ] || fail "$list lists no package"

prefix=$(mktemp -d /tmp/softid-runtime-packages.XXXXXX)
trap 'rm -rf "$prefix"' EXIT
"$cmake_bin" --install "$build_dir" --prefix "$prefix" >/dev/null

declare -A libraries=()  # path -> the binaries that load it
for binary in softid-server softid softid-lab; do
  path=$prefix/bin/$binary
  [ -x "$path" ] || fail "cmake --install did not install bin/$binary"
  ldd_out=$(ldd "$path")
  if grep -q 'not found' <<<"$ldd_out"; then
    fail "$binary: unresolved libraries:"$'\n'"$(grep 'not found' <<<"$ldd_out")"
  fi
  # "libx.so.1 => /lib/.../libx.so.1 (0x...)" or "/lib64/ld-linux-x86-64.so.2 (0x...)";
  # linux-vdso has no file.
  while read -r library; do
    libraries[$library]+="$binary "
  done < <(awk '$2 == "=>" && $3 ~ /^\// {print $3} $1 ~ /^\// {print $1}' <<<"$ldd_out")
done

# Where dpkg may know a library under: as ldd printed it, its resolved target (alternatives
# symlinks such as libblas.so.3 belong to no package), and the /usr-merged twin of each.
candidates() {
  local path=$1 real
  real=$(readlink -f "$path")
  printf '%s\n' "$path" "$real" "/usr$path" "/usr$real" "${path#/usr}" "${real#/usr}"
}
# One dpkg -S for every candidate (it reads its file lists once, not once per path):
# "libfoo1:amd64: /path" or "pkg1, pkg2: /path" -> owner[/path] = libfoo1.
declare -A owner=()
while IFS= read -r line; do
  package=${line%%: /*}
  package=${package%%,*}
  owner[${line#*: }]=${package%%:*}
done < <(for library in "${!libraries[@]}"; do candidates "$library"; done | sort -u |
  xargs dpkg -S 2>/dev/null || true)

declare -A needed=()
missing=0
for library in "${!libraries[@]}"; do
  package=""
  while read -r candidate; do
    if [ -n "${owner[$candidate]:-}" ]; then
      package=${owner[$candidate]}
      break
    fi
  done < <(candidates "$library")
  if [ -z "$package" ]; then
    echo "FAIL: ${libraries[$library]}: no Debian package ships $library" >&2
    missing=1
    continue
  fi
  needed[$package]=1
  if [ -z "${listed[$package]:-}" ]; then
    echo "FAIL: ${libraries[$library]}load $library from package $package, which" \
      "deploy/runtime-packages.txt does not list" >&2
    missing=1
  fi
done

# Every listed package must exist in bookworm: installed here, or known to apt.
declare -A installed=()
while read -r package status; do
  [ "$status" = installed ] && installed[$package]=1
done < <(dpkg-query -W -f='${Package} ${db:Status-Status}\n' "${!listed[@]}" 2>/dev/null || true)
# Without package lists (a machine that ran `rm -rf /var/lib/apt/lists/*`) apt knows only what
# is installed: then packages not installed here cannot be checked.
apt_lists=no
if compgen -G '/var/lib/apt/lists/*_Packages*' >/dev/null; then apt_lists=yes; fi
for package in "${!listed[@]}"; do
  [ -n "${installed[$package]:-}" ] && continue
  if [ "$apt_lists" = no ]; then
    echo "note: $package is not installed here and apt has no package lists to check it"
  elif ! apt-cache show --no-all-versions "$package" >/dev/null 2>&1; then
    echo "FAIL: deploy/runtime-packages.txt lists $package, which is neither installed nor" \
      "known to apt" >&2
    missing=1
  fi
done
[ "$missing" -eq 0 ] || exit 1

unused=()
for package in "${!listed[@]}"; do
  [ -n "${needed[$package]:-}" ] || unused+=("$package")
done
echo "ok: the ${#needed[@]} packages that ship the binaries' libraries are all listed"

# The image installs the packages marked [libs only] as just their loaded libraries: each mark
# must still name a package that ships one (deploy/copy-loaded-libs.sh fails otherwise).
bash "$source_dir/deploy/copy-loaded-libs.sh" "$list" "$prefix/libs-only" \
  "$prefix/bin/softid-server" "$prefix/bin/softid" "$prefix/bin/softid-lab" ||
  fail "deploy/copy-loaded-libs.sh failed on the installed binaries"
if [ "${#unused[@]}" -gt 0 ]; then
  echo "listed but not loaded by a binary (tools, or worth removing): ${unused[*]}"
fi
