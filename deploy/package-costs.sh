#!/usr/bin/env bash
# Usage: package-costs.sh IMAGE [BASE_IMAGE] [TOP]
# What each package of deploy/runtime-packages.txt costs in IMAGE (an image built with apt from
# that list; default base debian:bookworm-slim): its installed size, plus the packages apt pulled
# in only as its dependencies that are not on the list, i.e. that the binaries never load (the
# list is the ldd closure), followed through further such packages. Sizes are dpkg's
# Installed-Size (KiB, shown as MiB); packages already in BASE_IMAGE cost nothing. Prints the TOP
# (default 15) rows as a Markdown table, then the totals. SOFTID_PACKAGE_LIST names another list
# (an older one, for an image built from it). Needs podman (or PODMAN="docker") and python3.
set -euo pipefail

image=$1
base=${2:-docker.io/library/debian:bookworm-slim}
top=${3:-15}
list=${SOFTID_PACKAGE_LIST:-$(cd "$(dirname "$0")" && pwd)/runtime-packages.txt}
engine=${PODMAN:-podman --runtime runc}
tmp=$(mktemp -d /tmp/softid-package-costs.XXXXXX)
trap 'rm -rf "$tmp"' EXIT

# shellcheck disable=SC2016 # dpkg-query's ${...} fields, not shell expansions
format='${Package}\t${Installed-Size}\t${Provides}\t${Pre-Depends}\t${Depends}\n'
$engine run --rm --entrypoint dpkg-query "$image" -W -f="$format" >"$tmp/image.tsv"
$engine run --rm --entrypoint dpkg-query "$base" -W -f='${Package}\n' >"$tmp/base.txt"

python3 - "$tmp/image.tsv" "$tmp/base.txt" "$list" "$top" <<'PY'
import re, sys
image_tsv, base_txt, list_txt, top = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
name_of = lambda spec: re.split(r'[ (:]', spec.strip())[0]
packages = {}
for line in open(image_tsv):
    name, size, provides, pre, depends = line.rstrip('\n').split('\t')
    packages[name] = {'size': int(size or 0), 'provides': [name_of(p) for p in provides.split(',') if p.strip()],
                      'depends': [d for d in (pre + ',' + depends).split(',') if d.strip()]}
providers = {}
for name, p in packages.items():
    for virtual in p['provides']:
        providers.setdefault(virtual, name)
def resolve(alternatives):  # the first alternative that is installed
    for alternative in alternatives.split('|'):
        name = name_of(alternative)
        if name in packages: return name
        if name in providers: return providers[name]
for p in packages.values():
    p['edges'] = [x for x in map(resolve, p['depends']) if x]
base = {line.strip() for line in open(base_txt)}
listed, marked = [], set()
for line in open(list_txt):
    name = re.sub(r'#.*', '', line).strip()
    if not name: continue
    listed.append(name)
    if '[libs only]' in line: marked.add(name)
on_list = set(listed)
def not_loaded(name):  # dependencies off the list and off the base, followed through such packages
    seen, stack = set(), list(packages[name]['edges'])
    while stack:
        x = stack.pop()
        if x in seen or x in on_list or x in base: continue
        seen.add(x); stack.extend(packages[x]['edges'])
    return seen
mib = lambda kib: kib / 1024
rows = []
for name in listed:
    if name not in packages or name in base: continue
    chain = not_loaded(name)
    own = packages[name]['size']
    rows.append((own + sum(packages[x]['size'] for x in chain), name, own, chain))
rows.sort(reverse=True)
print('| package | own MiB | dependencies the binaries never load, MiB (largest) | total MiB |')
print('| --- | ---: | --- | ---: |')
for total, name, own, chain in rows[:top]:
    largest = sorted(chain, key=lambda x: -packages[x]['size'])[:3]
    detail = ', '.join(f"{x} {mib(packages[x]['size']):.1f}" for x in largest)
    mark = ' [libs only]' if name in marked else ''
    print(f"| {name}{mark} | {mib(own):.1f} | {mib(sum(packages[x]['size'] for x in chain)):.1f}"
          f"{': ' + detail if detail else ''} | {mib(total):.1f} |")
added = [x for x in packages if x not in base]
off_list = [x for x in added if x not in on_list]
print(f"\n{len(added)} packages over the base, {mib(sum(packages[x]['size'] for x in added)):.0f} MiB installed;"
      f" {len(off_list)} of them off the list ({mib(sum(packages[x]['size'] for x in off_list)):.0f} MiB)")
PY
