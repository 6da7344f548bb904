"""Clients of the crossroads servers over gRPC: :class:`LearnerClient`
(weights, checkpoints) and :class:`ReplayClient` (the prioritized replay),
with TLS and the bearer token, typed errors
(:mod:`crossroads.service.errors`) and dataclasses
(:mod:`crossroads.service.types`). Needs the ``grpc`` extra.

    from crossroads.service import LearnerClient

    with LearnerClient("https://learner:50052", ca_file="ca.pem", token_file="token") as learner:
        for weights in learner.subscribe_weights():
            net = weights.to_torch()
"""

from .errors import (
    CrossroadsError,
    DeadlineExceeded,
    FailedPrecondition,
    InvalidArgument,
    NotFound,
    PermissionDenied,
    ResourceExhausted,
    ServerError,
    Unauthenticated,
    Unavailable,
)
from .learner import LearnerClient
from .replay import ReplayClient
from .types import (
    CheckpointInfo,
    InsertAck,
    JoinedActor,
    LearnerStatus,
    NetworkSpec,
    ObservationLayout,
    PriorityUpdate,
    RateLimiterInfo,
    RestoredCheckpoint,
    Sample,
    SnapshotInfo,
    TableInfo,
    TransitionBatch,
    Weights,
)

__all__ = [
    "CheckpointInfo",
    "CrossroadsError",
    "DeadlineExceeded",
    "FailedPrecondition",
    "InsertAck",
    "InvalidArgument",
    "JoinedActor",
    "LearnerClient",
    "LearnerStatus",
    "NetworkSpec",
    "NotFound",
    "ObservationLayout",
    "PermissionDenied",
    "PriorityUpdate",
    "RateLimiterInfo",
    "ReplayClient",
    "ResourceExhausted",
    "RestoredCheckpoint",
    "Sample",
    "ServerError",
    "SnapshotInfo",
    "TableInfo",
    "TransitionBatch",
    "Unauthenticated",
    "Unavailable",
    "Weights",
]
