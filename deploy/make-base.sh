#!/usr/bin/env bash
# Makes a local Debian base image for deploy/Dockerfile on machines that
# cannot pull from a registry: debootstrap a minimal Debian root from a
# Debian mirror, then `docker import` it.
#
#   deploy/make-base.sh [TAG]        (default crossroads-base:bookworm)
#
# Environment: SUITE (bookworm), MIRROR (http://deb.debian.org/debian).
# Idempotent: an existing image with the tag is left alone. Needs root (or
# fakeroot-free sudo) for debootstrap; installs debootstrap with apt-get
# when it is missing.
set -euo pipefail

tag="${1:-crossroads-base:bookworm}"
suite="${SUITE:-bookworm}"
mirror="${MIRROR:-http://deb.debian.org/debian}"

die() { echo "make-base: error: $*" >&2; exit 1; }
say() { echo "make-base: $*" >&2; }

command -v docker >/dev/null || die "docker is required"
if docker image inspect "$tag" >/dev/null 2>&1; then
    say "$tag already exists"
    exit 0
fi
if ! command -v debootstrap >/dev/null; then
    [[ $(id -u) == 0 ]] || die "debootstrap is missing; install it (apt-get install debootstrap) or run as root"
    say "installing debootstrap"
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq debootstrap >/dev/null
fi
[[ $(id -u) == 0 ]] || die "debootstrap needs root"

root="$(mktemp -d "${TMPDIR:-/tmp}/crossroads-base.XXXXXX")"
trap 'rm -rf "$root"' EXIT
# minbase: dpkg, apt, bash, coreutils, libstdc++ (which the binary needs);
# ca-certificates for HTTPS endpoints. libgomp comes with libtorch.
say "debootstrap $suite from $mirror (a few minutes)"
debootstrap --variant=minbase --include=ca-certificates "$suite" "$root" "$mirror" >&2
rm -rf "$root"/var/cache/apt/archives/*.deb "$root"/var/lib/apt/lists/*
say "importing as $tag"
tar -C "$root" -c . | docker import \
    --change 'ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin' \
    --change 'CMD ["/bin/bash"]' \
    - "$tag" >/dev/null
docker image inspect "$tag" --format "make-base: $tag {{.Size}} bytes" >&2
