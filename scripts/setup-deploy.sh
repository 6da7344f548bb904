#!/usr/bin/env bash
# Installs what the deployment tests (tests/it/deploy.rs) use besides Docker
# itself: debootstrap (for the local base image), Debian's prometheus and
# promtool, kubectl (its built-in kustomize renders deploy/k8s), and ip and
# iptables for the fault suite's network partitions; then
# makes the local base image (deploy/make-base.sh). Idempotent: present
# tools and an existing base image are left alone. Without a reachable
# Docker engine it says so and stops; the tests then fail, naming it, when
# CROSSROADS_REQUIRE_DOCKER=1 (as `make test` sets).
#
#   scripts/setup-deploy.sh
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
say() { echo "setup-deploy: $*" >&2; }

missing=()
command -v debootstrap >/dev/null || missing+=(debootstrap)
command -v promtool >/dev/null && command -v prometheus >/dev/null || missing+=(prometheus)
command -v kubectl >/dev/null || missing+=(kubernetes-client)
# The fault suite's partitions (tests/it/faults.rs): namespaces and iptables.
command -v ip >/dev/null || missing+=(iproute2)
command -v iptables >/dev/null || missing+=(iptables)
if ((${#missing[@]})); then
    if [[ $(id -u) != 0 ]]; then
        say "missing ${missing[*]}; install them with apt-get (needs root)"
        exit 1
    fi
    say "installing ${missing[*]}"
    export DEBIAN_FRONTEND=noninteractive
    apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null 2>&1 || {
        apt-get update -qq >/dev/null
        apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
    }
fi

if ! docker info >/dev/null 2>&1; then
    say "no Docker engine reachable (docker info failed); the compose test needs one"
    exit 0
fi
"$repo/deploy/make-base.sh"
say "ready"
