"""Generated gRPC stubs of proto/proto/crossroads/v1; do not edit.

Regenerate with scripts/gen-python-grpc.sh. Only crossroads.service uses
them: its public API is dataclasses, not these messages.
"""
