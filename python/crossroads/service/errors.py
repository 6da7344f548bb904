"""Errors of the service clients: one class per gRPC status the servers
answer, under :class:`CrossroadsError`, so a caller catches what it can
handle (``except NotFound``) without knowing gRPC.

=====================  =======================================================
``Unauthenticated``    a guarded call without the token, or with another one
``PermissionDenied``   refused by the server for this caller
``NotFound``           an unknown checkpoint; no weights published yet
``InvalidArgument``    a request the server rejects, naming the field
``FailedPrecondition`` the server cannot do this now (no checkpoint directory,
                       no snapshot directory, another network's checkpoint)
``ResourceExhausted``  a batch or message above the server's limits
``DeadlineExceeded``   the call (or the replay's rate limiter) took too long
``Unavailable``        the server cannot be reached, or is shutting down
``ServerError``        the server failed (INTERNAL, DATA_LOSS, UNKNOWN)
=====================  =======================================================

Any other status is a plain :class:`CrossroadsError`. Each carries ``code``
(the status name, e.g. ``"NOT_FOUND"``) and ``details`` (the server's
message).
"""

from __future__ import annotations

from typing import Dict, Optional, Type

import grpc


class CrossroadsError(Exception):
    """A call to a crossroads server failed."""

    def __init__(self, details: str, code: str = "UNKNOWN", method: Optional[str] = None) -> None:
        self.code = code
        self.details = details
        self.method = method
        where = f" ({method})" if method else ""
        super().__init__(f"{code}{where}: {details}")


class Unauthenticated(CrossroadsError):
    """The call needs the server's bearer token, or carried another one."""


class PermissionDenied(CrossroadsError):
    """The server refuses this caller."""


class NotFound(CrossroadsError):
    """What the call names does not exist."""


class InvalidArgument(CrossroadsError):
    """The server rejected the request; the details name the field."""


class FailedPrecondition(CrossroadsError):
    """The server cannot do this in its present state or configuration."""


class ResourceExhausted(CrossroadsError):
    """A request or response above a limit."""


class DeadlineExceeded(CrossroadsError):
    """The call took longer than its deadline."""


class Unavailable(CrossroadsError):
    """The server cannot be reached or is shutting down; retrying may help."""


class ServerError(CrossroadsError):
    """The server failed while handling the call."""


_BY_CODE: Dict[grpc.StatusCode, Type[CrossroadsError]] = {
    grpc.StatusCode.UNAUTHENTICATED: Unauthenticated,
    grpc.StatusCode.PERMISSION_DENIED: PermissionDenied,
    grpc.StatusCode.NOT_FOUND: NotFound,
    grpc.StatusCode.INVALID_ARGUMENT: InvalidArgument,
    grpc.StatusCode.FAILED_PRECONDITION: FailedPrecondition,
    grpc.StatusCode.RESOURCE_EXHAUSTED: ResourceExhausted,
    grpc.StatusCode.DEADLINE_EXCEEDED: DeadlineExceeded,
    grpc.StatusCode.UNAVAILABLE: Unavailable,
    grpc.StatusCode.INTERNAL: ServerError,
    grpc.StatusCode.DATA_LOSS: ServerError,
    grpc.StatusCode.UNKNOWN: ServerError,
}


def from_rpc_error(e: grpc.RpcError, method: Optional[str] = None) -> CrossroadsError:
    """The typed error of a failed gRPC call."""
    code = e.code() if hasattr(e, "code") else grpc.StatusCode.UNKNOWN
    details = (e.details() if hasattr(e, "details") else None) or str(e)
    cls = _BY_CODE.get(code, CrossroadsError)
    return cls(details, code.name if code is not None else "UNKNOWN", method)
