"""crossroads.torch: the learner's network rebuilt in PyTorch from a
weights file. That the committed ttg-left network gives the Rust model's
own Q-values is checked from the Rust side
(learner/tests/it/python.rs, committed_network_gives_the_same_q_values_in_pytorch,
which runs this package); here, the module against the file and a numpy
reading of the architecture, and every refusal."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="needs the torch extra: pip install './python[torch]'")

from crossroads.torch import QNetwork, greedy, load_weights  # noqa: E402
from crossroads.weights import NetworkSpec, ObservationLayout, read_weights  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
TTG_LEFT = ROOT / "reports" / "paper" / "runs" / "ttg-left" / "best"


def safetensors_bytes(tensors: dict, metadata: dict | None) -> bytes:
    """A safetensors file of f32 arrays (the format, written by hand)."""
    header: dict = {"__metadata__": metadata} if metadata is not None else {}
    data = b""
    for name, array in sorted(tensors.items()):
        raw = np.ascontiguousarray(array, dtype="<f4").tobytes()
        header[name] = {
            "dtype": "F32",
            "shape": list(array.shape),
            "data_offsets": [len(data), len(data) + len(raw)],
        }
        data += raw
    text = json.dumps(header).encode()
    return struct.pack("<Q", len(text)) + text + data


def metadata(spec: NetworkSpec, version: int = 7) -> dict:
    return {
        "format": "crossroads.qnetwork",
        "format_version": "1",
        "weights_version": str(version),
        "spec": spec.to_json(),
    }


def random_tensors(spec: NetworkSpec, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    return {n: rng.normal(0, 0.3, s).astype(np.float32) for n, s in spec.tensor_shapes().items()}


def observations(layout: ObservationLayout, n: int, seed: int = 1) -> np.ndarray:
    """Mostly empty observations in [0, 1), and a dense last row."""
    rng = np.random.default_rng(seed)
    x = rng.random((n, layout.size), dtype=np.float32)
    x[:-1] *= rng.random((n - 1, layout.size)) < 0.05
    return x


SMALL_MLP = NetworkSpec(ObservationLayout("toy", 2, 3, 4, 2), "ttg", 5, "mlp", (8, 6))
SMALL_CONV = NetworkSpec(ObservationLayout("toy", 2, 5, 7, 3), "creep", 3, "conv", (4, 6, 10))


# --- numpy reading of the architecture ------------------------------------


def conv3x3(x: np.ndarray, w: np.ndarray, b: np.ndarray, stride: int) -> np.ndarray:
    """3x3 cross-correlation, padding 1: x [n, c, h, w], w [o, c, 3, 3]."""
    n, c, h, wd = x.shape
    padded = np.pad(x, ((0, 0), (0, 0), (1, 1), (1, 1)))
    oh, ow = (h - 1) // stride + 1, (wd - 1) // stride + 1
    out = np.zeros((n, w.shape[0], oh, ow))
    for i in range(3):
        for j in range(3):
            patch = padded[:, :, i : i + stride * oh : stride, j : j + stride * ow : stride]
            out += np.einsum("nchw,oc->nohw", patch, w[:, :, i, j])
    return out + b[None, :, None, None]


def reference_q(spec: NetworkSpec, t: dict, x: np.ndarray) -> np.ndarray:
    """Q = V + A - mean A over the trunk, in float64, as ARCHITECTURE reads."""
    relu = lambda v: np.maximum(v, 0)  # noqa: E731
    t = {k: v.astype(np.float64) for k, v in t.items()}
    x = x.astype(np.float64)
    if spec.trunk == "mlp":
        h = x
        for i in range(len(spec.hidden)):
            h = relu(h @ t[f"trunk.{i}.weight"].T + t[f"trunk.{i}.bias"])
    else:
        o = spec.observation
        g = x[:, : o.grid_len].reshape(-1, o.channels, o.rows, o.cols)
        for i in range(len(spec.hidden) - 1):
            g = relu(conv3x3(g, t[f"trunk.{i}.weight"], t[f"trunk.{i}.bias"], 1 if i == 0 else 2))
        joined = np.concatenate([g.reshape(len(x), -1), x[:, o.grid_len :]], axis=1)
        h = relu(joined @ t["trunk.fc.weight"].T + t["trunk.fc.bias"])
    v = h @ t["value.weight"].T + t["value.bias"]
    a = h @ t["advantage.weight"].T + t["advantage.bias"]
    return v + a - a.mean(axis=1, keepdims=True)


# --- the committed network ------------------------------------------------


def test_committed_ttg_left_network_loads_under_the_files_names():
    net = load_weights(TTG_LEFT)
    file = read_weights(TTG_LEFT / "weights.safetensors")
    assert net.spec == file.spec
    assert net.spec.trunk == "conv" and net.spec.hidden == (16, 32, 256)
    assert net.spec.observation == ObservationLayout("ttg", 5, 18, 26, 4)
    assert net.version == 1009 and not net.training
    state = net.state_dict()
    assert sorted(state) == sorted(file.tensors)
    for name, t in file.tensors.items():
        assert torch.equal(state[name], torch.from_numpy(t.copy())), name


def test_committed_network_computes_the_architecture():
    net = load_weights(TTG_LEFT)
    x = observations(net.spec.observation, 6)
    with torch.no_grad():
        q = net(torch.from_numpy(x)).numpy()
    want = reference_q(net.spec, read_weights(TTG_LEFT).tensors, x)
    np.testing.assert_allclose(q, want, atol=1e-4, rtol=0)
    with torch.no_grad():
        one = net(torch.from_numpy(x[0]))
    assert one.shape == (5,)
    np.testing.assert_allclose(one.numpy(), q[0], atol=1e-6)


@pytest.mark.parametrize(
    "spec", [SMALL_MLP, SMALL_CONV, NetworkSpec(SMALL_MLP.observation, "ttg", 5, "mlp", ())]
)
def test_a_written_file_loads_from_bytes_and_computes_the_architecture(spec):
    tensors = random_tensors(spec)
    data = safetensors_bytes(tensors, metadata(spec, version=42))
    net = load_weights(data)
    assert net.version == 42 and net.spec == spec
    assert sorted(net.state_dict()) == sorted(tensors)
    x = observations(spec.observation, 5)
    with torch.no_grad():
        q = net(torch.from_numpy(x)).numpy()
    np.testing.assert_allclose(q, reference_q(spec, tensors, x), atol=1e-5, rtol=0)
    v, a = net.streams(torch.from_numpy(x))
    assert v.shape == (5, 1) and a.shape == (5, spec.num_actions)


def test_greedy_takes_the_first_of_equal_maxima():
    q = torch.tensor([[0.0, 2.0, 2.0], [5.0, -1.0, 5.0], [-3.0, -2.0, -4.0]])
    assert greedy(q).tolist() == [1, 0, 1]
    assert int(greedy(q[0])) == 1


# --- refusals ---------------------------------------------------------------


def refused(data: bytes, says: str) -> None:
    with pytest.raises(ValueError, match=says):
        load_weights(data)


def test_a_file_without_spec_metadata_is_refused():
    tensors = random_tensors(SMALL_MLP)
    refused(safetensors_bytes(tensors, None), "no spec metadata")
    refused(safetensors_bytes(tensors, {"format": "pt"}), "no spec metadata")


def test_other_formats_and_bad_specs_are_refused():
    tensors = random_tensors(SMALL_MLP)
    meta = metadata(SMALL_MLP)
    refused(safetensors_bytes(tensors, {**meta, "format_version": "2"}), "format_version")
    refused(safetensors_bytes(tensors, {**meta, "format": "other"}), "format is 'other'")
    refused(safetensors_bytes(tensors, {**meta, "weights_version": "x"}), "weights_version")
    spec = json.loads(meta["spec"])
    refused(
        safetensors_bytes(tensors, {**meta, "spec": json.dumps({**spec, "trunk": "lstm"})}),
        "unknown trunk 'lstm'",
    )
    refused(
        safetensors_bytes(tensors, {**meta, "spec": json.dumps({**spec, "hidden": [0]})}),
        "hidden sizes",
    )
    del spec["action_set"]
    refused(safetensors_bytes(tensors, {**meta, "spec": json.dumps(spec)}), "lacks 'action_set'")
    refused(safetensors_bytes(tensors, {**meta, "spec": "{"}), "not a network spec")
    refused(b"\x01\x02", "not a safetensors file")


def test_tensors_that_do_not_fit_the_spec_are_refused():
    tensors = random_tensors(SMALL_CONV)
    meta = metadata(SMALL_CONV)
    wrong = dict(tensors, **{"trunk.fc.weight": np.zeros((10, 5), np.float32)})
    refused(safetensors_bytes(wrong, meta), r"'trunk.fc.weight' has shape \[10, 5\].*\[10, 75\]")
    missing = {k: v for k, v in tensors.items() if k != "value.bias"}
    refused(safetensors_bytes(missing, meta), r"missing \['value.bias'\]")
    extra = dict(tensors, **{"trunk.9.weight": np.zeros(1, np.float32)})
    refused(safetensors_bytes(extra, meta), r"unknown \['trunk.9.weight'\]")
    nan = dict(tensors, **{"value.bias": np.array([np.nan], np.float32)})
    refused(safetensors_bytes(nan, meta), "NaN or infinite")


def test_observations_of_another_shape_or_type_are_refused():
    net = QNetwork(SMALL_MLP)
    with pytest.raises(ValueError, match=r"\[batch, 26\]"):
        net(torch.zeros(2, 25))
    with pytest.raises(ValueError, match="float32"):
        net(torch.zeros(2, 26, dtype=torch.float64))


def test_a_missing_file_is_named(tmp_path):
    with pytest.raises(ValueError, match="no such weights file"):
        load_weights(tmp_path)
