"""What the clients return and take: plain dataclasses, converted from and
to the wire at the clients' boundary (no protobuf type is in the API)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, Optional, Tuple

import numpy as np

from ..weights import NetworkSpec, ObservationLayout, WeightsFile, read_weights

__all__ = [
    "CheckpointInfo",
    "InsertAck",
    "JoinedActor",
    "LearnerStatus",
    "NetworkSpec",
    "ObservationLayout",
    "PriorityUpdate",
    "RateLimiterInfo",
    "RestoredCheckpoint",
    "Sample",
    "SnapshotInfo",
    "TableInfo",
    "TransitionBatch",
    "Weights",
]


@dataclass(frozen=True)
class Weights:
    """One published version of the learner's online network."""

    #: Strictly increasing over the learner's life, across restores and restarts.
    version: int
    #: Learner update step the weights come from.
    update_step: int
    spec: NetworkSpec
    #: The weights file's bytes (safetensors, with the spec and version in
    #: its metadata).
    safetensors: bytes = field(repr=False)
    #: When the learner published them, Unix milliseconds.
    published_unix_ms: int

    def read(self) -> WeightsFile:
        """The tensors as numpy arrays (see :func:`crossroads.weights.read_weights`)."""
        return read_weights(self.safetensors)

    def to_torch(self, device=None):
        """The network in PyTorch (needs the ``torch`` extra); see
        :func:`crossroads.torch.load_weights`."""
        from ..torch import load_weights

        return load_weights(self.safetensors, device=device)

    def save(self, path) -> Path:
        """Writes the weights file to ``path``; returns it."""
        path = Path(path)
        path.write_bytes(self.safetensors)
        return path


@dataclass(frozen=True)
class CheckpointInfo:
    """One stored checkpoint as the learner lists it."""

    #: Folder name under the checkpoint directory, e.g. ``ckpt-000012000``.
    id: str
    update_step: int
    weights_version: int
    created_unix_ms: int
    size_bytes: int
    scenario: str
    #: The latest greedy evaluation, e.g. ``success_rate``.
    eval_metrics: Dict[str, float]
    #: Whether it is the checkpoint kept as best by evaluation.
    best: bool
    #: The files it holds.
    files: Tuple[str, ...]


@dataclass(frozen=True)
class RestoredCheckpoint:
    checkpoint: CheckpointInfo
    #: The version under which the restored weights were published.
    weights_version: int


@dataclass(frozen=True)
class LearnerStatus:
    update_step: int
    weights_version: int
    loss: float
    mean_q: float
    updates_per_second: float
    uptime_seconds: float
    scenario: str
    #: Latest checkpoint id, ``None`` if none.
    latest_checkpoint: Optional[str]
    #: The learner's effective configuration, as TOML.
    config_toml: str = field(repr=False)


@dataclass
class TransitionBatch:
    """n-step transitions, struct-of-arrays: row ``i`` of every column is
    transition ``i``; its state and next state are rows
    ``observation_index[i]`` and ``next_observation_index[i]`` of
    ``observations`` (each distinct observation once, ``[n, layout.size]``
    float32 in the simulator's layout)."""

    layout: ObservationLayout
    num_actions: int
    observations: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    discounts: np.ndarray
    priorities: np.ndarray
    observation_index: np.ndarray
    next_observation_index: np.ndarray

    @classmethod
    def from_transitions(
        cls,
        layout: ObservationLayout,
        num_actions: int,
        states,
        actions,
        rewards,
        next_states,
        discounts,
        priorities=None,
    ) -> "TransitionBatch":
        """A batch of ``n`` transitions from their states and next states
        (``[n, layout.size]`` each); ``priorities`` default to 1."""
        states = np.asarray(states, dtype=np.float32)
        next_states = np.asarray(next_states, dtype=np.float32)
        n = len(states)
        if priorities is None:
            priorities = np.ones(n, dtype=np.float32)
        return cls(
            layout=layout,
            num_actions=num_actions,
            observations=np.concatenate([states, next_states]).reshape(2 * n, -1),
            actions=np.asarray(actions, dtype=np.uint32),
            rewards=np.asarray(rewards, dtype=np.float32),
            discounts=np.asarray(discounts, dtype=np.float32),
            priorities=np.asarray(priorities, dtype=np.float32),
            observation_index=np.arange(n, dtype=np.uint32),
            next_observation_index=np.arange(n, 2 * n, dtype=np.uint32),
        )

    def __len__(self) -> int:
        return len(self.actions)

    def states(self) -> np.ndarray:
        """Each transition's state, ``[n, layout.size]``."""
        return self.observations[self.observation_index]

    def next_states(self) -> np.ndarray:
        """Each transition's next state, ``[n, layout.size]``."""
        return self.observations[self.next_observation_index]


@dataclass(frozen=True)
class InsertAck:
    #: Transitions stored from the batch.
    inserted: int
    #: Table size after the insert.
    table_size: int


@dataclass
class Sample:
    """A prioritized sample: the items (drawn with replacement), their keys
    for :meth:`ReplayClient.update_priorities`, their importance weights
    and the priorities they had."""

    keys: np.ndarray
    weights: np.ndarray
    priorities: np.ndarray
    batch: TransitionBatch


@dataclass(frozen=True)
class PriorityUpdate:
    updated: int
    #: Keys no longer in the table (evicted since sampling).
    ignored: int


@dataclass(frozen=True)
class RateLimiterInfo:
    min_size_to_sample: int
    samples_per_insert: float
    error_tolerance: float
    can_sample: bool
    can_insert: bool
    sample_waits_total: int
    insert_waits_total: int


@dataclass(frozen=True)
class TableInfo:
    name: str
    size: int
    capacity: int
    inserts_total: int
    samples_total: int
    priority_updates_total: int
    ignored_updates_total: int
    #: Rejected inputs by reason, e.g. ``observation_length``.
    rejections_total: Dict[str, int]
    rate_limiter: RateLimiterInfo
    bytes_stored: int
    #: Last snapshot written, Unix milliseconds; ``None`` if none.
    last_snapshot_unix_ms: Optional[int]


@dataclass(frozen=True)
class SnapshotInfo:
    path: str
    items: int
    bytes: int
    duration_seconds: float


@dataclass(frozen=True)
class JoinedActor:
    index: int
    #: Actors that have joined so far, this one included.
    joined: int
