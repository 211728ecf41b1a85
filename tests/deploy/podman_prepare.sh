# Sourced by the container tests (container_test.sh, compose_multi_test.sh): podman made ready to
# build and run softid's image on these machines. The caller defines the array
# podman=(podman --runtime runc ...) and skip() (exit 77: CTest's "skipped").

# Installs Debian packages, or skips the test when that fails.
apt_install_or_skip() {
  DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "$@" >/dev/null ||
    skip "cannot install $*"
}

# Idempotent: podman and runc installed, runc allowed to start containers here, and the Debian
# base images the Dockerfile names present.
prepare_podman() {
  if ! command -v podman >/dev/null || ! command -v debootstrap >/dev/null; then
    apt_install_or_skip podman runc uidmap fuse-overlayfs slirp4netns debootstrap
  fi
  # runc cannot raise RLIMIT_NOFILE on these machines.
  if ! grep -qs 'default_ulimits' /etc/containers/containers.conf; then
    mkdir -p /etc/containers
    printf '[containers]\ndefault_ulimits = []\n' >>/etc/containers/containers.conf
  fi
  # No registry is reachable: the base images come from Debian's own packages.
  if ! "${podman[@]}" image exists docker.io/library/debian:bookworm; then
    local mirror rootfs
    mirror=$(sed -n 's/^URIs: *//p' /etc/apt/sources.list.d/*.sources 2>/dev/null | head -n 1)
    mirror=${mirror:-http://deb.debian.org/debian}
    rootfs=$(mktemp -d /tmp/softid-rootfs.XXXXXX)
    debootstrap --variant=minbase bookworm "$rootfs" "$mirror" >/dev/null ||
      skip "debootstrap could not make a base image"
    tar -C "$rootfs" -c . | "${podman[@]}" import - docker.io/library/debian:bookworm >/dev/null
    rm -rf "$rootfs"
  fi
  "${podman[@]}" image exists docker.io/library/debian:bookworm-slim ||
    "${podman[@]}" tag docker.io/library/debian:bookworm docker.io/library/debian:bookworm-slim
}
