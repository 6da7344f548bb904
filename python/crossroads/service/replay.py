"""A client of the replay server's gRPC API (``crossroads.v1.Replay``):
table info, inserts, prioritized samples and priority updates."""

from __future__ import annotations

from typing import Iterable, List, Optional, Sequence

import numpy as np

from ..weights import ObservationLayout
from ._channel import Connection, translate
from ._proto import replay_pb2, replay_pb2_grpc, schema_pb2
from .errors import ServerError
from .types import (
    InsertAck,
    JoinedActor,
    PriorityUpdate,
    RateLimiterInfo,
    Sample,
    SnapshotInfo,
    TableInfo,
    TransitionBatch,
)

__all__ = ["ReplayClient"]

_DENSE = schema_pb2.OBSERVATION_ENCODING_DENSE_F32
_SPARSE = schema_pb2.OBSERVATION_ENCODING_SPARSE_F32


class ReplayClient(Connection):
    """The replay server at ``endpoint``, table ``table``; see
    :class:`Connection` for TLS and the token. ``info`` needs no token;
    inserting, sampling, priority updates, snapshots and joining do when
    the server has one.

    Use as a context manager, or call :meth:`close`.
    """

    def __init__(self, endpoint: str, table: str = "transitions", **kwargs) -> None:
        super().__init__(endpoint, **kwargs)
        self.table = table
        self._stub = replay_pb2_grpc.ReplayStub(self.channel)

    def info(self) -> TableInfo:
        """Size, capacity, counters and rate-limiter state of the table."""
        t = self.call("Info", self._stub.Info, replay_pb2.InfoRequest(table=self.table))
        r = t.rate_limiter
        return TableInfo(
            name=t.name,
            size=t.size,
            capacity=t.capacity,
            inserts_total=t.inserts_total,
            samples_total=t.samples_total,
            priority_updates_total=t.priority_updates_total,
            ignored_updates_total=t.ignored_updates_total,
            rejections_total=dict(t.rejections_total),
            rate_limiter=RateLimiterInfo(
                min_size_to_sample=r.min_size_to_sample,
                samples_per_insert=r.samples_per_insert,
                error_tolerance=r.error_tolerance,
                can_sample=r.can_sample,
                can_insert=r.can_insert,
                sample_waits_total=r.sample_waits_total,
                insert_waits_total=r.insert_waits_total,
            ),
            bytes_stored=t.bytes_stored,
            last_snapshot_unix_ms=t.last_snapshot_unix_ms or None,
        )

    def insert(self, batch: TransitionBatch, *, encoding: str = "sparse") -> InsertAck:
        """Stores one batch; returns once it is in the table."""
        return self.insert_many([batch], encoding=encoding)[0]

    def insert_many(
        self, batches: Iterable[TransitionBatch], *, encoding: str = "sparse"
    ) -> List[InsertAck]:
        """Streams batches on one call; returns each one's acknowledgement,
        in order. Observations travel ``sparse`` (only non-zero cells; a
        grid is mostly empty) or ``dense``. A batch the server rejects
        ends the call with ``InvalidArgument`` (``ResourceExhausted`` when
        oversized), naming the field; batches acknowledged before it are
        stored."""
        requests = [
            replay_pb2.InsertRequest(
                table=self.table, batch_id=i, batch=_batch_to_wire(b, encoding)
            )
            for i, b in enumerate(batches)
        ]
        if not requests:
            return []
        acks: List[InsertAck] = []
        call = self.stream(self._stub.Insert, iter(requests), timeout=self.timeout)
        try:
            with translate("Insert"):
                for ack in call:
                    if ack.batch_id != len(acks):
                        raise ServerError(
                            f"acknowledgement of batch {ack.batch_id}, expected {len(acks)}",
                            "INTERNAL",
                            "Insert",
                        )
                    acks.append(InsertAck(inserted=ack.inserted, table_size=ack.table_size))
        finally:
            call.cancel()
        if len(acks) != len(requests):
            raise ServerError(
                f"{len(acks)} of {len(requests)} batches acknowledged", "INTERNAL", "Insert"
            )
        return acks

    def sample(self, batch_size: int, beta: float = 0.4, timeout: Optional[float] = None) -> Sample:
        """Draws ``batch_size`` items with replacement, with probability
        priority^alpha / sum, and their importance weights (exponent
        ``beta``). ``timeout``: the longest wait for the rate limiter, in
        seconds (the server's default when ``None``); ``DeadlineExceeded``
        when sampling is not allowed within it."""
        timeout_ms = 0 if timeout is None else max(1, int(timeout * 1000))
        deadline = self.timeout + (timeout if timeout is not None else 600.0)
        r = self.call(
            "Sample",
            self._stub.Sample,
            replay_pb2.SampleRequest(
                table=self.table, batch_size=batch_size, beta=beta, timeout_ms=timeout_ms
            ),
            timeout=deadline,
        )
        batch = _batch_from_wire(r.batch)
        n = len(batch)
        if not (len(r.keys) == len(r.weights) == len(r.priorities) == n):
            raise ServerError(
                f"{len(r.keys)} keys, {len(r.weights)} weights for {n} transitions",
                "INTERNAL",
                "Sample",
            )
        return Sample(
            keys=np.asarray(r.keys, dtype=np.uint64),
            weights=np.asarray(r.weights, dtype=np.float32),
            priorities=np.asarray(r.priorities, dtype=np.float32),
            batch=batch,
        )

    def update_priorities(self, keys: Sequence[int], priorities: Sequence[float]) -> PriorityUpdate:
        """Sets the priorities (>= 0, finite) of sampled items; keys of items
        evicted since are counted as ignored."""
        keys = [int(k) for k in keys]
        priorities = [float(p) for p in priorities]
        if len(keys) != len(priorities):
            raise ValueError(f"{len(keys)} keys but {len(priorities)} priorities")
        r = self.call(
            "UpdatePriorities",
            self._stub.UpdatePriorities,
            replay_pb2.UpdatePrioritiesRequest(table=self.table, keys=keys, priorities=priorities),
        )
        return PriorityUpdate(updated=r.updated, ignored=r.ignored)

    def snapshot(self) -> SnapshotInfo:
        """Writes a snapshot now; ``FailedPrecondition`` when the server
        has no snapshot directory."""
        r = self.call("Snapshot", self._stub.Snapshot, replay_pb2.SnapshotRequest())
        return SnapshotInfo(
            path=r.path, items=r.items, bytes=r.bytes, duration_seconds=r.duration_seconds
        )

    def join_actor(self, name: str) -> JoinedActor:
        """An actor index for ``name`` (the same name gets the same one)."""
        r = self.call("JoinActor", self._stub.JoinActor, replay_pb2.JoinActorRequest(name=name))
        return JoinedActor(index=r.index, joined=r.joined)


def _layout_to_wire(layout: ObservationLayout) -> schema_pb2.ObservationSpec:
    return schema_pb2.ObservationSpec(
        kind=layout.kind,
        shape=[layout.channels, layout.rows, layout.cols],
        extra_features=layout.extra,
    )


def _batch_to_wire(b: TransitionBatch, encoding: str) -> schema_pb2.TransitionBatch:
    obs = np.ascontiguousarray(b.observations, dtype=np.float32)
    if obs.ndim != 2 or obs.shape[1] != b.layout.size:
        raise ValueError(
            f"observations must be [n, {b.layout.size}] for layout {b.layout}, "
            f"got {list(obs.shape)}"
        )
    offsets: List[int] = []
    parts: List[bytes] = []
    size = 0
    if encoding == "dense":
        for row in obs:
            offsets.append(size)
            data = row.astype("<f4").tobytes()
            parts.append(data)
            size += len(data)
        wire_encoding = _DENSE
    elif encoding == "sparse":
        for row in obs:
            offsets.append(size)
            (idx,) = np.nonzero(row)
            pairs = np.empty(len(idx), dtype=[("i", "<u4"), ("v", "<f4")])
            pairs["i"], pairs["v"] = idx, row[idx]
            data = pairs.tobytes()
            parts.append(data)
            size += len(data)
        wire_encoding = _SPARSE
    else:
        raise ValueError(f"encoding must be 'sparse' or 'dense', got {encoding!r}")
    return schema_pb2.TransitionBatch(
        spec=_layout_to_wire(b.layout),
        num_actions=b.num_actions,
        actions=np.asarray(b.actions, dtype=np.uint32).tolist(),
        rewards=np.asarray(b.rewards, dtype=np.float32).tolist(),
        discounts=np.asarray(b.discounts, dtype=np.float32).tolist(),
        priorities=np.asarray(b.priorities, dtype=np.float32).tolist(),
        observations=schema_pb2.ObservationPool(
            encoding=wire_encoding, offsets=offsets, data=b"".join(parts)
        ),
        observation_index=np.asarray(b.observation_index, dtype=np.uint32).tolist(),
        next_observation_index=np.asarray(b.next_observation_index, dtype=np.uint32).tolist(),
    )


def _batch_from_wire(b: schema_pb2.TransitionBatch) -> TransitionBatch:
    shape = list(b.spec.shape)
    if len(shape) != 3:
        raise ServerError(
            f"sampled batch: observation shape {shape} is not [channels, rows, cols]",
            "INTERNAL",
            "Sample",
        )
    layout = ObservationLayout(b.spec.kind, shape[0], shape[1], shape[2], b.spec.extra_features)
    pool = b.observations
    offsets = list(pool.offsets) + [len(pool.data)]
    obs = np.zeros((len(pool.offsets), layout.size), dtype=np.float32)
    data = pool.data
    for i in range(len(pool.offsets)):
        chunk = data[offsets[i] : offsets[i + 1]]
        if pool.encoding == _DENSE:
            obs[i] = np.frombuffer(chunk, dtype="<f4")
        elif pool.encoding == _SPARSE:
            pairs = np.frombuffer(chunk, dtype=[("i", "<u4"), ("v", "<f4")])
            obs[i, pairs["i"]] = pairs["v"]
        else:
            raise ServerError(
                f"sampled batch: unknown observation encoding {pool.encoding}", "INTERNAL", "Sample"
            )
    return TransitionBatch(
        layout=layout,
        num_actions=b.num_actions,
        observations=obs,
        actions=np.asarray(b.actions, dtype=np.uint32),
        rewards=np.asarray(b.rewards, dtype=np.float32),
        discounts=np.asarray(b.discounts, dtype=np.float32),
        priorities=np.asarray(b.priorities, dtype=np.float32),
        observation_index=np.asarray(b.observation_index, dtype=np.uint32),
        next_observation_index=np.asarray(b.next_observation_index, dtype=np.uint32),
    )
