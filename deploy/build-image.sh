#!/usr/bin/env bash
# Builds the crossroads image from this checkout: the release binary
# (stripped) and .libtorch/lib staged into a small build context, on the
# base image BASE (default: the local crossroads-base:bookworm, made by
# deploy/make-base.sh when missing).
#
#   deploy/build-image.sh [TAG]     (default crossroads:latest)
#
# CROSSROADS_BIN=PATH takes that binary instead of building the release one
# (the tests use their debug build, so CI compiles one profile only).
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
tag="${1:-crossroads:latest}"
base="${BASE:-crossroads-base:bookworm}"
say() { echo "build-image: $*" >&2; }

if [[ "$base" == crossroads-base:* ]]; then
    "$repo/deploy/make-base.sh" "$base"
fi
bin="${CROSSROADS_BIN:-}"
if [[ -z "$bin" ]]; then
    make -C "$repo" build >&2
    bin="$repo/target/release/crossroads"
fi
[[ -x "$bin" ]] || { echo "build-image: error: no executable at $bin" >&2; exit 1; }
ctx="$(mktemp -d "${TMPDIR:-/tmp}/crossroads-image.XXXXXX")"
trap 'rm -rf "$ctx"' EXIT
cp "$bin" "$ctx/crossroads"
strip "$ctx/crossroads"
cp -a "$repo/.libtorch/lib" "$ctx/lib"
say "building $tag on $base"
docker build -q -f "$repo/deploy/Dockerfile" --build-arg "BASE=$base" -t "$tag" "$ctx" >&2
docker image inspect "$tag" --format "build-image: $tag {{.Size}} bytes" >&2
