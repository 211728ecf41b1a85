#!/usr/bin/env bash
# Usage: dockerfile_test.sh SOURCE_DIR
# No Docker engine runs here, so the Dockerfile is checked as text for what the deployment relies
# on: a bookworm build stage that uses the CI dependency script, a bookworm-slim runtime stage
# with the runtime package list, a non-root user, the data volume, a HEALTHCHECK through
# `softid health`, tini as PID 1 (from a listed package), TLS and tokens on; the compose file
# builds it and turns neither off.
set -euo pipefail

source_dir=$1
dockerfile=$source_dir/deploy/Dockerfile
compose=$source_dir/deploy/docker-compose.yml
multi=$source_dir/deploy/docker-compose.multi.yml
list=$source_dir/deploy/runtime-packages.txt
failed=0

expect() {  # DESCRIPTION EXTENDED-REGEX FILE
  if ! grep -Eq -- "$2" "$3"; then
    echo "FAIL: $(basename "$3"): $1 (no line matches /$2/)" >&2
    failed=1
  fi
}

[ -f "$dockerfile" ] || { echo "FAIL: $dockerfile is missing" >&2; exit 1; }
[ "$(grep -Ec '^FROM ' "$dockerfile")" -eq 2 ] || { echo "FAIL: expected two stages" >&2; failed=1; }
expect "build stage on debian:bookworm" '^FROM debian:bookworm AS build$' "$dockerfile"
expect "build stage uses the CI dependency script" '^RUN .*bash deploy/install-deps\.sh' "$dockerfile"
expect "runtime stage on debian:bookworm-slim" '^FROM debian:bookworm-slim$' "$dockerfile"
expect "runtime packages come from the list" '^COPY deploy/runtime-packages\.txt ' "$dockerfile"
# Packages marked [libs only]: apt skips them, the build stage copies their loaded libraries.
expect "apt skips packages marked [libs only]" '^ && sed -e .*libs only\\\]/d' "$dockerfile"
expect "the build stage copies the marked packages' loaded libraries" 'bash deploy/copy-loaded-libs\.sh deploy/runtime-packages\.txt /opt/softid/lib' "$dockerfile"
expect "those libraries go into the runtime stage" '^COPY --from=build /opt/softid/lib/ ' "$dockerfile"
expect "the runtime stage checks that every loaded library is there" "ldd /usr/local/bin/softid-server .*grep 'not found'" "$dockerfile"
expect "binaries come from the build stage" '^COPY --from=build ' "$dockerfile"
expect "a data volume" '^VOLUME .*/var/lib/softid' "$dockerfile"
expect "the server's data directory is the volume" 'SOFTID_DATA=/var/lib/softid' "$dockerfile"
expect "health checked with the client" 'CMD \[.*"softid", "--retry-for", "0", "--timeout", "3", "health"\]' \
  "$dockerfile"
expect "TLS on by default (self-signed)" 'SOFTID_TLS_SELF_SIGNED=true' "$dockerfile"
expect "the client in the image trusts that certificate" 'SOFTID_TLS_CA=/var/lib/softid/tls/server.crt' \
  "$dockerfile"
if grep -Eq 'SOFTID_ALLOW_INSECURE|--allow-insecure' "$dockerfile" "$compose" "$multi"; then
  echo "FAIL: the image or compose file serves plain text on the network (allow-insecure)" >&2
  failed=1
fi
if grep -Eq 'SOFTID_AUTH=none|--auth none|SOFTID_AUTH: *"?none' "$dockerfile" "$compose" "$multi"; then
  echo "FAIL: the image or compose file turns API tokens off" >&2
  failed=1
fi
expect "tini as PID 1" '^ENTRYPOINT \["/usr/bin/tini", "--", "softid-server"\]' "$dockerfile"
expect "tini is installed" '^tini([[:space:]]|#|$)' "$list"

# The last USER wins: it must name a user other than root.
user=$(awk '$1 == "USER" {u = $2} END {print u}' "$dockerfile")
case "${user%%:*}" in
  "" ) echo "FAIL: Dockerfile: no USER: the server would run as root" >&2; failed=1 ;;
  root | 0 ) echo "FAIL: Dockerfile: USER $user is root" >&2; failed=1 ;;
esac
# Every file the Dockerfile copies from the context exists.
while read -r source; do
  [ -e "$source_dir/$source" ] || { echo "FAIL: Dockerfile copies $source, which is missing" >&2; failed=1; }
done < <(awk '$1 == "COPY" && $2 !~ /^--/ && $2 != "." {print $2}' "$dockerfile")

expect "compose builds deploy/Dockerfile" 'dockerfile: deploy/Dockerfile' "$compose"
# The multi-node file: PostgreSQL, an API role and a worker role on one store and one volume.
expect "multi: a PostgreSQL 15 service" 'image: postgres:15' "$multi"
expect "multi: an API process" 'SOFTID_ROLE: api' "$multi"
expect "multi: worker processes" 'SOFTID_ROLE: worker' "$multi"
expect "multi: the shared store" 'SOFTID_STORE: postgresql://' "$multi"
[ "$(grep -Ec 'softid-data:/var/lib/softid' "$multi")" -eq 2 ] ||
  { echo "FAIL: multi: the API and the workers must mount one data volume" >&2; failed=1; }
[ "$(grep -Ec 'condition: service_healthy' "$multi")" -eq 2 ] ||
  { echo "FAIL: multi: the API waits for the database and the workers for the API" >&2; failed=1; }
expect "compose keeps the data on a volume" ':/var/lib/softid' "$compose"

[ "$failed" -eq 0 ] || exit 1
echo "ok: Dockerfile and compose file have every part the deployment relies on"
