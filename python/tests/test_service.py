"""crossroads.service against real servers: a replay server and a learner
started from the binary CROSSROADS_BIN names, with TLS (a throwaway CA)
and a token, on loopback ports. Python inserts transitions, the learner
trains on them and publishes weights, and every client call is made, with
and without the token; the weights subscription is cut and the learner
restarted under it. Skips without CROSSROADS_BIN unless
CROSSROADS_REQUIRE_PYTHON=1."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from _servers import TOKEN, Pki, Relay, Role, binary, free_port, skip_or_fail

grpc = pytest.importorskip("grpc", reason="needs the grpc extra: pip install './python[grpc]'")

from crossroads.service import (  # noqa: E402
    InvalidArgument,
    LearnerClient,
    NotFound,
    ObservationLayout,
    ReplayClient,
    TransitionBatch,
    Unauthenticated,
    Unavailable,
)
from crossroads.weights import read_weights  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
PROTO_DIR = ROOT / "python" / "crossroads" / "service" / "_proto"

#: The simulator's TTG view, which the learner's default network reads.
TTG = ObservationLayout("ttg", 5, 18, 26, 4)
FILLED = 48


def transitions(n: int, seed: int) -> TransitionBatch:
    """``n`` transitions of mostly empty TTG observations."""
    rng = np.random.default_rng(seed)

    def observations():
        x = rng.random((n, TTG.size), dtype=np.float32)
        return np.where(rng.random((n, TTG.size)) < 0.03, x, 0.0).astype(np.float32)

    return TransitionBatch.from_transitions(
        TTG,
        5,
        states=observations(),
        actions=rng.integers(0, 5, n),
        rewards=rng.uniform(-1, 1, n),
        next_states=observations(),
        discounts=np.full(n, 0.99),
        priorities=rng.uniform(0.5, 2.0, n),
    )


# --- servers ------------------------------------------------------------


@pytest.fixture(scope="module")
def pki(tmp_path_factory):
    binary()
    pytest.importorskip(
        "cryptography", reason="the tests make their certificates with cryptography"
    )
    return Pki(tmp_path_factory.mktemp("pki"))


@pytest.fixture(scope="module")
def replay(pki, tmp_path_factory):
    dir = tmp_path_factory.mktemp("replay")
    role = Role(
        pki.server_args()
        + [
            "--set",
            "telemetry.metrics_addr=127.0.0.1:0",
            "--set",
            "replay.min_size_to_sample=1",
            "--set",
            "replay.samples_per_insert=0",
            "replay",
            "--listen",
            "127.0.0.1:0",
            "--no-shm",
            "--snapshot-dir",
            str(dir / "snapshots"),
        ],
        "replay server listening",
        dir / "replay.log",
    )
    yield role
    role.stop()


class Learner:
    """The learner on a fixed port, so that it can be restarted there."""

    def __init__(self, pki: Pki, replay: Role, dir: Path) -> None:
        self.port = free_port()
        self.args = pki.server_args() + [
            "--set",
            "telemetry.metrics_addr=127.0.0.1:0",
            "--set",
            "learner.hidden=[16]",
            "--set",
            "learner.batch_size=8",
            "--set",
            "learner.publish_every=20",
            "--set",
            "learner.checkpoint_every=1000000000",
            "--set",
            "learner.checkpoint_keep=50",
            "learner",
            "--listen",
            f"127.0.0.1:{self.port}",
            "--replay",
            f"https://{replay.addr}",
            "--no-shm",
            "--checkpoint-dir",
            str(dir / "checkpoints"),
        ]
        self.dir = dir
        self.starts = 0
        self.role = self._start()
        self.addr = self.role.addr

    def _start(self) -> Role:
        self.starts += 1
        return Role(self.args, "learner listening", self.dir / f"learner-{self.starts}.log")

    def restart(self) -> None:
        """SIGTERM (the learner writes its last checkpoint), then a new
        process on the same port that resumes from it."""
        self.role.stop()
        self.role = self._start()
        assert self.role.addr == self.addr

    def stop(self) -> None:
        self.role.stop()


@pytest.fixture(scope="module")
def learner(pki, replay, tmp_path_factory):
    process = Learner(pki, replay, tmp_path_factory.mktemp("learner"))
    yield process
    process.stop()


@pytest.fixture(scope="module")
def replay_client(pki, replay):
    with ReplayClient(f"https://{replay.addr}", ca_file=pki.ca, token_file=pki.token) as c:
        yield c


@pytest.fixture(scope="module")
def learner_client(pki, learner):
    with LearnerClient(f"https://{learner.addr}", ca_file=pki.ca, token_file=pki.token) as c:
        yield c


@pytest.fixture(scope="module")
def filled(replay_client):
    """The replay holding FILLED transitions (one batch sparse, two dense
    on one call), so the learner trains and publishes new versions."""
    first = transitions(FILLED // 2, seed=1)
    rest = [transitions(FILLED // 4, seed=2), transitions(FILLED // 4, seed=3)]
    acks = [replay_client.insert(first)] + replay_client.insert_many(rest, encoding="dense")
    assert [a.inserted for a in acks] == [FILLED // 2, FILLED // 4, FILLED // 4]
    assert acks[-1].table_size == FILLED
    return [first, *rest]


def take(stream, enough, timeout: float = 120.0):
    """Reads ``stream`` on a thread until ``enough(got)``; what it got.
    The stream stays open for the next call."""
    got, errors, done = [], [], threading.Event()

    def run():
        try:
            for w in stream:
                got.append(w)
                if enough(got):
                    return
            errors.append(AssertionError("the subscription ended"))
        except BaseException as e:  # noqa: BLE001 - handed to the test
            errors.append(e)
        finally:
            done.set()

    threading.Thread(target=run, daemon=True).start()
    assert done.wait(timeout), f"no weights in {timeout}s (got {[w.version for w in got]})"
    if errors:
        raise errors[0]
    return got


# --- replay -------------------------------------------------------------


def test_replay_info_insert_sample_and_priorities(replay_client, filled):
    info = replay_client.info()
    assert info.name == "transitions"
    assert info.size == FILLED and info.inserts_total == FILLED
    assert info.capacity >= FILLED
    assert info.rate_limiter.min_size_to_sample == 1 and info.rate_limiter.can_sample

    sample = replay_client.sample(6, beta=0.5, timeout=10)
    assert (
        len(sample.keys) == len(sample.weights) == len(sample.priorities) == len(sample.batch) == 6
    )
    assert sample.keys.dtype == np.uint64
    assert np.all((sample.weights > 0) & (sample.weights <= 1))
    assert sample.batch.layout == TTG and sample.batch.num_actions == 5
    # Every sampled item is one that was inserted, sparse or dense, exactly.
    inserted = {
        (s.tobytes(), n.tobytes(), int(a), float(r))
        for b in filled
        for s, n, a, r in zip(b.states(), b.next_states(), b.actions, b.rewards, strict=True)
    }
    for s, n, a, r in zip(
        sample.batch.states(),
        sample.batch.next_states(),
        sample.batch.actions,
        sample.batch.rewards,
        strict=True,
    ):
        assert (s.tobytes(), n.tobytes(), int(a), float(r)) in inserted

    update = replay_client.update_priorities(sample.keys, [3.0] * 6)
    assert (update.updated, update.ignored) == (6, 0)
    assert replay_client.info().priority_updates_total >= 6


def test_replay_snapshot_and_join(replay_client, filled):
    snapshot = replay_client.snapshot()
    assert snapshot.items == FILLED and Path(snapshot.path).exists()
    assert replay_client.info().last_snapshot_unix_ms
    joined = replay_client.join_actor("python-test")
    assert replay_client.join_actor("python-test").index == joined.index


def test_replay_rejects_an_invalid_batch_naming_the_field(replay_client, filled):
    bad = transitions(2, seed=4)
    bad.discounts[1] = 2.0
    with pytest.raises(InvalidArgument, match=r"discounts\[1\]"):
        replay_client.insert(bad)
    with pytest.raises(InvalidArgument, match="beta"):
        replay_client.sample(2, beta=1.5)
    assert replay_client.info().size == FILLED


# --- learner ------------------------------------------------------------


def test_latest_weights_and_status(learner_client):
    w = learner_client.latest_weights()
    assert w.version >= 1
    assert w.spec.observation == TTG and w.spec.trunk == "mlp" and w.spec.hidden == (16,)
    assert w.spec.num_actions == 5 and w.spec.action_set == "ttg"
    file = w.read()
    assert file.version == w.version and file.spec == w.spec
    assert set(file.tensors) == set(w.spec.tensor_shapes())
    status = learner_client.status()
    assert status.weights_version >= w.version and "[learner]" in status.config_toml
    try:
        import torch
    except ImportError:
        return
    q = w.to_torch()(torch.zeros(3, TTG.size))
    assert q.shape == (3, 5)


def test_checkpoints_save_list_pull_restore_delete(learner_client, tmp_path):
    learner_client.report_evaluation(learner_client.latest_weights().version, {"success_rate": 0.5})
    with pytest.raises(InvalidArgument, match="empty"):
        learner_client.report_evaluation(1, {})
    saved = learner_client.save_checkpoint()
    assert "weights.safetensors" in saved.files
    assert saved.eval_metrics == {"success_rate": 0.5}
    assert saved.id in [c.id for c in learner_client.list_checkpoints()]

    info, folder = learner_client.pull_checkpoint(saved.id, tmp_path)
    assert info == saved and folder == tmp_path / saved.id
    assert sorted(p.name for p in folder.iterdir()) == sorted(saved.files)
    assert sum(p.stat().st_size for p in folder.iterdir()) == saved.size_bytes
    pulled = read_weights(folder)
    assert pulled.version == saved.weights_version
    assert pulled.spec == learner_client.latest_weights().spec

    latest = learner_client.latest_weights().version
    restored = learner_client.restore_checkpoint(saved.id)
    assert restored.checkpoint.id == saved.id
    assert restored.weights_version > latest
    assert learner_client.latest_weights().version >= restored.weights_version

    learner_client.delete_checkpoint(saved.id)
    assert saved.id not in [c.id for c in learner_client.list_checkpoints()]
    with pytest.raises(NotFound):
        learner_client.delete_checkpoint(saved.id)
    with pytest.raises(NotFound):
        learner_client.restore_checkpoint(saved.id)
    with pytest.raises(NotFound):
        learner_client.pull_checkpoint(saved.id, tmp_path)
    with pytest.raises(InvalidArgument):
        learner_client.pull_checkpoint("../escape", tmp_path)
    assert not (tmp_path / saved.id).exists() or (tmp_path / saved.id) == folder
    assert [p.name for p in tmp_path.iterdir()] == [saved.id], "no temporary folder is left"


def test_subscription_yields_new_versions_and_resumes_after_the_stream_is_cut(pki, learner, filled):
    relay = Relay(learner.addr)
    try:
        with LearnerClient(
            f"https://{relay.addr}", ca_file=pki.ca, server_name="localhost"
        ) as client:
            stream = client.subscribe_weights(give_up_after=60)
            before = take(stream, lambda got: len(got) >= 2)
            assert relay.accepted == 1
            relay.cut()
            after = take(stream, lambda got: relay.accepted >= 2 and len(got) >= 2)
            stream.close()
    finally:
        relay.close()
    versions = [w.version for w in before + after]
    assert versions == sorted(set(versions)), f"a version came twice or went back: {versions}"


def test_subscription_resumes_after_the_learner_restarts(pki, learner, learner_client, filled):
    stream = learner_client.subscribe_weights(give_up_after=180)
    before = take(stream, lambda got: len(got) >= 1)
    learner.restart()
    restarted = learner_client.status()
    assert restarted.uptime_seconds < 60
    after = take(stream, lambda got: got[-1].version >= restarted.weights_version, timeout=180)
    stream.close()
    versions = [w.version for w in before + after]
    assert versions == sorted(set(versions)), f"a version came twice or went back: {versions}"
    assert after[-1].version > before[-1].version


def test_subscription_without_reconnect_raises_unavailable(pki):
    with LearnerClient(f"https://127.0.0.1:{free_port()}", ca_file=pki.ca) as client:
        with pytest.raises(Unavailable):
            next(client.subscribe_weights(reconnect=False))
        with pytest.raises(Unavailable):
            next(client.subscribe_weights(give_up_after=0.5))


# --- security -------------------------------------------------------------


def test_guarded_calls_need_the_token(pki, replay, learner, filled, tmp_path, monkeypatch):
    monkeypatch.delenv("CROSSROADS_TOKEN", raising=False)
    wrong = tmp_path / "wrong-token"
    wrong.write_text("not-the-token")
    for token_file, says in [(None, "missing authorization"), (wrong, "does not match")]:
        with ReplayClient(f"https://{replay.addr}", ca_file=pki.ca, token_file=token_file) as r:
            with pytest.raises(Unauthenticated, match=says):
                r.insert(transitions(2, seed=5))
            with pytest.raises(Unauthenticated, match=says):
                r.sample(2)
            with pytest.raises(Unauthenticated, match=says):
                r.update_priorities([0], [1.0])
            assert r.info().size == FILLED, "Info is open, and nothing got in"
        with LearnerClient(f"https://{learner.addr}", ca_file=pki.ca, token_file=token_file) as c:
            with pytest.raises(Unauthenticated, match=says):
                c.save_checkpoint()
            with pytest.raises(Unauthenticated, match=says):
                c.delete_checkpoint("ckpt-000000000")
            with pytest.raises(Unauthenticated, match=says):
                c.restore_checkpoint("ckpt-000000000")
            c.list_checkpoints()
            c.latest_weights()
    # The token from the environment, as the roles read it.
    monkeypatch.setenv("CROSSROADS_TOKEN", TOKEN)
    with ReplayClient(f"https://{replay.addr}", ca_file=pki.ca) as r:
        assert r.has_token
        assert len(r.sample(1).keys) == 1


def test_tls_refuses_a_server_the_ca_did_not_sign(pki, replay):
    with ReplayClient(f"https://{replay.addr}", ca_file=pki.stranger_ca, timeout=5) as r:
        with pytest.raises(Unavailable):
            r.info()


# --- generated stubs ------------------------------------------------------


def test_generated_stubs_are_up_to_date(tmp_path):
    """scripts/gen-python-grpc.sh writes exactly the committed stubs."""
    try:
        import grpc_tools
        from importlib.metadata import version
    except ImportError:
        skip_or_fail("grpcio-tools is not installed: pip install grpcio-tools==1.85.4")
    committed = (PROTO_DIR / "learner_pb2_grpc.py").read_text()
    wanted = committed.split("GRPC_GENERATED_VERSION = '", 1)[1].split("'", 1)[0]
    have = version("grpcio-tools")
    if have != wanted:
        skip_or_fail(f"the stubs were generated by grpcio-tools {wanted}; this is {have}")
    del grpc_tools
    subprocess.run(
        ["bash", str(ROOT / "scripts" / "gen-python-grpc.sh"), str(tmp_path)],
        check=True,
        env=dict(os.environ, PYTHON=sys.executable),
    )
    ours = sorted(p.name for p in PROTO_DIR.iterdir() if p.is_file())
    theirs = sorted(p.name for p in tmp_path.iterdir())
    assert ours == theirs
    for name in ours:
        assert (PROTO_DIR / name).read_bytes() == (tmp_path / name).read_bytes(), (
            f"{name} differs from what scripts/gen-python-grpc.sh makes: rerun it"
        )
