"""A client of the learner's gRPC API (``crossroads.v1.Learner``): its
weights (latest, and a subscription that survives disconnects) and its
checkpoints (list, pull, save, restore, delete)."""

from __future__ import annotations

import os
import shutil
import time
from pathlib import Path
from typing import Dict, Iterator, List, Optional, Tuple

import grpc

from ..weights import NetworkSpec, ObservationLayout
from ._channel import Connection, translate
from ._proto import learner_pb2, learner_pb2_grpc, schema_pb2
from .errors import CrossroadsError, InvalidArgument, ServerError, Unavailable, from_rpc_error
from .types import CheckpointInfo, LearnerStatus, RestoredCheckpoint, Weights

__all__ = ["LearnerClient"]

#: Statuses after which a subscription reconnects: the learner went away
#: (restart, network), or the stream was cut.
_RECONNECT = (grpc.StatusCode.UNAVAILABLE,)


class LearnerClient(Connection):
    """The learner at ``endpoint``; see :class:`Connection` for TLS and the
    token. Listing, pulling and the weights need no token; saving,
    restoring and deleting checkpoints do when the learner has one
    (otherwise :class:`~crossroads.service.errors.Unauthenticated`).

    Use as a context manager, or call :meth:`close`.
    """

    def __init__(self, endpoint: str, **kwargs) -> None:
        super().__init__(endpoint, **kwargs)
        self._stub = learner_pb2_grpc.LearnerStub(self.channel)

    def status(self) -> LearnerStatus:
        """Where training stands."""
        s = self.call("Status", self._stub.Status, learner_pb2.StatusRequest())
        return LearnerStatus(
            update_step=s.update_step,
            weights_version=s.weights_version,
            loss=s.loss,
            mean_q=s.mean_q,
            updates_per_second=s.updates_per_second,
            uptime_seconds=s.uptime_seconds,
            scenario=s.scenario,
            latest_checkpoint=s.latest_checkpoint or None,
            config_toml=s.config_toml,
        )

    def latest_weights(self) -> Weights:
        """The latest published weights; ``NotFound`` before the first."""
        w = self.call(
            "GetLatestWeights", self._stub.GetLatestWeights, learner_pb2.GetLatestWeightsRequest()
        )
        return _weights(w)

    def subscribe_weights(
        self,
        have_version: int = 0,
        *,
        reconnect: bool = True,
        give_up_after: Optional[float] = None,
        max_backoff: float = 5.0,
    ) -> Iterator[Weights]:
        """Yields the latest weights newer than ``have_version`` at once,
        then every newer version as the learner publishes it (a slow
        reader gets the newest, skipping those it fell behind on).

        When the stream breaks (the learner restarts, the connection is
        cut) it reconnects, backing off up to ``max_backoff`` seconds, and
        asks for versions newer than the last one it yielded, so no
        version is yielded twice. ``give_up_after``: seconds without a
        connection before raising ``Unavailable`` (``None``: never);
        ``reconnect=False`` raises at the first break instead. Errors that
        retrying cannot mend (``Unauthenticated``, ...) are raised at once.
        Closing the generator cancels the call.
        """
        have = have_version
        backoff = 0.05
        lost_since: Optional[float] = None
        while True:
            call = self.stream(
                self._stub.SubscribeWeights, learner_pb2.SubscribeWeightsRequest(have_version=have)
            )
            try:
                for w in call:
                    lost_since, backoff = None, 0.05
                    if w.version <= have:
                        continue
                    have = w.version
                    yield _weights(w)
                broken: Optional[CrossroadsError] = Unavailable(
                    "the learner ended the weights stream", "UNAVAILABLE", "SubscribeWeights"
                )
            except grpc.RpcError as e:
                if e.code() not in _RECONNECT:
                    raise from_rpc_error(e, "SubscribeWeights") from None
                broken = from_rpc_error(e, "SubscribeWeights")
            finally:
                call.cancel()
            if not reconnect:
                raise broken
            now = time.monotonic()
            lost_since = now if lost_since is None else lost_since
            if give_up_after is not None and now - lost_since > give_up_after:
                raise broken
            time.sleep(backoff)
            backoff = min(backoff * 2, max_backoff)

    def list_checkpoints(self) -> List[CheckpointInfo]:
        """Every stored checkpoint, newest first."""
        r = self.call(
            "ListCheckpoints", self._stub.ListCheckpoints, learner_pb2.ListCheckpointsRequest()
        )
        return [_checkpoint(c) for c in r.checkpoints]

    def save_checkpoint(self) -> CheckpointInfo:
        """Writes a checkpoint now and returns it (needs the token)."""
        return _checkpoint(
            self.call(
                "SaveCheckpoint", self._stub.SaveCheckpoint, learner_pb2.SaveCheckpointRequest()
            )
        )

    def restore_checkpoint(self, id: str) -> RestoredCheckpoint:
        """Makes the learner resume from checkpoint ``id`` (weights,
        optimizer, target network, step); it publishes the weights under a
        new, higher version. Needs the token; ``NotFound`` for an unknown
        id."""
        r = self.call(
            "RestoreCheckpoint",
            self._stub.RestoreCheckpoint,
            learner_pb2.RestoreCheckpointRequest(id=id),
        )
        return RestoredCheckpoint(
            checkpoint=_checkpoint(r.checkpoint), weights_version=r.weights_version
        )

    def delete_checkpoint(self, id: str) -> None:
        """Removes checkpoint ``id`` (needs the token)."""
        self.call(
            "DeleteCheckpoint",
            self._stub.DeleteCheckpoint,
            learner_pb2.DeleteCheckpointRequest(id=id),
        )

    def report_evaluation(self, weights_version: int, metrics: Dict[str, float]) -> None:
        """Reports the greedy evaluation of a weights version (metric name
        to finite value, e.g. ``success_rate``); needs the token."""
        self.call(
            "ReportEvaluation",
            self._stub.ReportEvaluation,
            learner_pb2.ReportEvaluationRequest(weights_version=weights_version, metrics=metrics),
        )

    def pull_checkpoint(
        self, id: str, out: "os.PathLike[str] | str", timeout: float = 600.0
    ) -> Tuple[CheckpointInfo, Path]:
        """Downloads checkpoint ``id`` into ``out/<id>/`` (written under a
        temporary name, then renamed into place); returns its description
        and folder. File names from the learner are checked, so nothing is
        written outside that folder. ``timeout``: seconds the whole
        download may take."""
        out = Path(out)
        call = self.stream(
            self._stub.GetCheckpoint, learner_pb2.GetCheckpointRequest(id=id), timeout=timeout
        )
        tmp: Optional[Path] = None
        try:
            with translate("GetCheckpoint"):
                chunks = iter(call)
                first = next(chunks, None)
                if first is None or not first.HasField("info"):
                    raise ServerError(
                        "the checkpoint stream did not start with its info",
                        "INTERNAL",
                        "GetCheckpoint",
                    )
                info = _checkpoint(first.info)
                _check_name(info.id, "checkpoint id")
                out.mkdir(parents=True, exist_ok=True)
                tmp = out / f".pull-{info.id}-{os.getpid()}"
                shutil.rmtree(tmp, ignore_errors=True)
                tmp.mkdir()
                written: Dict[str, int] = {}
                done: Dict[str, bool] = {}
                for chunk in chunks:
                    name = chunk.file
                    _check_name(name, "file name")
                    if name not in info.files:
                        raise ServerError(
                            f"unexpected file {name!r} in checkpoint {info.id}",
                            "INTERNAL",
                            "GetCheckpoint",
                        )
                    if done.get(name) or chunk.offset != written.get(name, 0):
                        raise ServerError(
                            f"chunk of {name} at offset {chunk.offset} out of order",
                            "INTERNAL",
                            "GetCheckpoint",
                        )
                    with open(tmp / name, "ab") as f:
                        f.write(chunk.data)
                    written[name] = chunk.offset + len(chunk.data)
                    done[name] = chunk.end_of_file
                incomplete = [n for n in info.files if not done.get(n)]
                if incomplete:
                    raise ServerError(
                        f"the stream ended before {incomplete} were complete",
                        "INTERNAL",
                        "GetCheckpoint",
                    )
            dest = out / info.id
            if dest.exists():
                shutil.rmtree(dest)
            tmp.rename(dest)
            tmp = None
            return info, dest
        finally:
            call.cancel()
            if tmp is not None:
                shutil.rmtree(tmp, ignore_errors=True)


def _check_name(name: str, what: str) -> None:
    """A plain name: no folder, not hidden, nothing that leaves the
    folder."""
    if not name or name.startswith(".") or "/" in name or "\\" in name or "\0" in name:
        raise InvalidArgument(
            f"invalid {what} {name!r} from the learner", "INVALID_ARGUMENT", "GetCheckpoint"
        )


def _spec(s: schema_pb2.NetworkSpec) -> NetworkSpec:
    o = s.observation
    if len(o.shape) != 3:
        raise ServerError(
            f"network spec: observation shape {list(o.shape)} is not [channels, rows, cols]",
            "INTERNAL",
        )
    extra = o.extra_features or s.extra_features
    return NetworkSpec(
        observation=ObservationLayout(o.kind, o.shape[0], o.shape[1], o.shape[2], extra),
        action_set=s.action_set,
        num_actions=s.num_actions,
        trunk=s.trunk,
        hidden=tuple(s.hidden),
    )


def _weights(w: schema_pb2.Weights) -> Weights:
    return Weights(
        version=w.version,
        update_step=w.update_step,
        spec=_spec(w.spec),
        safetensors=w.safetensors,
        published_unix_ms=w.published_unix_ms,
    )


def _checkpoint(c: schema_pb2.CheckpointInfo) -> CheckpointInfo:
    return CheckpointInfo(
        id=c.id,
        update_step=c.update_step,
        weights_version=c.weights_version,
        created_unix_ms=c.created_unix_ms,
        size_bytes=c.size_bytes,
        scenario=c.scenario,
        eval_metrics=dict(c.eval_metrics),
        best=c.best,
        files=tuple(c.files),
    )
