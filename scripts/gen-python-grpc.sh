#!/usr/bin/env bash
# Regenerates the Python gRPC stubs of proto/proto/crossroads/v1 (messages,
# type stubs, service stubs) into python/crossroads/service/_proto, or into
# the folder given, with their imports of each other made package-relative
# (protoc writes `from crossroads.v1 import schema_pb2`, which would name
# the Python package crossroads). Needs grpcio-tools at the version the
# committed stubs were made with (GRPC_GENERATED_VERSION in them), else the
# output differs; PYTHON picks the interpreter (default: .venv's, else
# python3).
#
#   scripts/gen-python-grpc.sh            # rewrite the committed stubs
#   scripts/gen-python-grpc.sh /tmp/out   # write them elsewhere (the test)
set -euo pipefail

repo="$(cd "$(dirname "$0")/.." && pwd)"
out="${1:-$repo/python/crossroads/service/_proto}"
py="${PYTHON:-python3}"
if [ -z "${PYTHON:-}" ] && [ -x "$repo/.venv/bin/python3" ]; then
    py="$repo/.venv/bin/python3"
fi

tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
(
    cd "$repo/proto/proto"
    "$py" -m grpc_tools.protoc -I . \
        --python_out="$tmp" --pyi_out="$tmp" --grpc_python_out="$tmp" \
        crossroads/v1/schema.proto crossroads/v1/replay.proto crossroads/v1/learner.proto
)
mkdir -p "$out"
for f in "$tmp"/crossroads/v1/*.py "$tmp"/crossroads/v1/*.pyi; do
    sed -E 's/^from crossroads\.v1 import /from . import /' "$f" > "$out/$(basename "$f")"
done
cat > "$out/__init__.py" <<'PY'
"""Generated gRPC stubs of proto/proto/crossroads/v1; do not edit.

Regenerate with scripts/gen-python-grpc.sh. Only crossroads.service uses
them: its public API is dataclasses, not these messages.
"""
PY
