"""The learner's weights files, read without torch.

A weights file is safetensors: f32 tensors under the network's variable
names (``trunk.<i>.*``, ``trunk.fc.*`` after a conv trunk's convolutions,
``value.*``, ``advantage.*``) in PyTorch's layout, and string metadata:

=================  ===========================================
``format``         ``crossroads.qnetwork``
``format_version`` ``1``
``weights_version`` the learner's monotonic version, decimal
``spec``           the :class:`NetworkSpec` as JSON
=================  ===========================================

:func:`read_weights` reads a file (or a run's ``best/`` folder, or the bytes
the learner's gRPC API sends) into a :class:`WeightsFile`: the spec, the
version and the tensors as numpy arrays. :mod:`crossroads.torch` builds the
network from it. Every problem is a ``ValueError`` naming it.
"""

from __future__ import annotations

import json
import os
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, Tuple, Union

import numpy as np

FORMAT = "crossroads.qnetwork"
FORMAT_VERSION = "1"
WEIGHTS_FILE = "weights.safetensors"

Source = Union[str, "os.PathLike[str]", bytes, bytearray, memoryview]


@dataclass(frozen=True)
class ObservationLayout:
    """A flat observation: a channel-major ``channels x rows x cols`` grid,
    then ``extra`` dense values (the field names are the weights file's)."""

    kind: str
    channels: int
    rows: int
    cols: int
    extra: int

    @property
    def grid_len(self) -> int:
        return self.channels * self.rows * self.cols

    @property
    def size(self) -> int:
        """Values in one flat observation."""
        return self.grid_len + self.extra


@dataclass(frozen=True)
class NetworkSpec:
    """What fixes a network's tensors, as the ``spec`` metadata says.

    ``hidden``: for ``mlp``, the widths of the hidden layers; for ``conv``,
    the channels of each 3x3 convolution (stride 1, then 2), then the width
    of the fully connected layer.
    """

    observation: ObservationLayout
    action_set: str
    num_actions: int
    trunk: str
    hidden: Tuple[int, ...]

    @classmethod
    def from_json(cls, text: str) -> "NetworkSpec":
        """The spec from the metadata's JSON; ``ValueError`` naming what is
        wrong."""
        try:
            raw = json.loads(text)
            o = raw["observation"]
            layout = ObservationLayout(
                kind=str(o["kind"]),
                channels=_int(o["channels"], "observation.channels"),
                rows=_int(o["rows"], "observation.rows"),
                cols=_int(o["cols"], "observation.cols"),
                extra=_int(o["extra"], "observation.extra"),
            )
            spec = cls(
                observation=layout,
                action_set=str(raw["action_set"]),
                num_actions=_int(raw["num_actions"], "num_actions"),
                trunk=str(raw["trunk"]),
                hidden=tuple(_int(h, "hidden") for h in raw["hidden"]),
            )
        except (json.JSONDecodeError, TypeError) as e:
            raise ValueError(f"spec metadata is not a network spec: {e}") from None
        except KeyError as e:
            raise ValueError(f"spec metadata lacks {e.args[0]!r}") from None
        spec.validate()
        return spec

    def to_json(self) -> str:
        """The spec as the weights file's metadata holds it."""
        o = self.observation
        return json.dumps(
            {
                "observation": {
                    "kind": o.kind,
                    "channels": o.channels,
                    "rows": o.rows,
                    "cols": o.cols,
                    "extra": o.extra,
                },
                "action_set": self.action_set,
                "num_actions": self.num_actions,
                "trunk": self.trunk,
                "hidden": list(self.hidden),
            },
            separators=(",", ":"),
        )

    def validate(self) -> None:
        """Checks what the Rust model checks (``NetworkSpec::validate``)."""
        o = self.observation
        if not o.kind:
            raise ValueError("spec: the observation kind is empty")
        if min(o.channels, o.rows, o.cols) <= 0 or o.extra < 0:
            raise ValueError(f"spec: observation dimensions must be positive: {o}")
        if self.num_actions <= 0:
            raise ValueError(f"spec: num_actions must be positive, got {self.num_actions}")
        if any(h <= 0 or h > 1 << 16 for h in self.hidden):
            raise ValueError(
                f"spec: hidden sizes must be between 1 and 65536, got {list(self.hidden)}"
            )
        if self.trunk not in ("mlp", "conv"):
            raise ValueError(f"spec: unknown trunk {self.trunk!r}; expected 'mlp' or 'conv'")
        if self.trunk == "conv" and len(self.hidden) < 2:
            raise ValueError(
                "spec: a conv trunk needs at least one convolution's channels and the "
                f"fully connected width, got {list(self.hidden)}"
            )

    @property
    def input_len(self) -> int:
        """Values per observation the network reads."""
        return self.observation.size

    def tensor_shapes(self) -> Dict[str, Tuple[int, ...]]:
        """Every tensor of a network of this spec, name to shape."""
        shapes: Dict[str, Tuple[int, ...]] = {}
        o = self.observation
        if self.trunk == "mlp":
            width = o.size
            for i, h in enumerate(self.hidden):
                shapes[f"trunk.{i}.weight"] = (h, width)
                shapes[f"trunk.{i}.bias"] = (h,)
                width = h
        else:
            c, rows, cols = o.channels, o.rows, o.cols
            for i, out in enumerate(self.hidden[:-1]):
                stride = 1 if i == 0 else 2
                shapes[f"trunk.{i}.weight"] = (out, c, 3, 3)
                shapes[f"trunk.{i}.bias"] = (out,)
                c = out
                rows = (rows - 1) // stride + 1
                cols = (cols - 1) // stride + 1
            width = self.hidden[-1]
            shapes["trunk.fc.weight"] = (width, c * rows * cols + o.extra)
            shapes["trunk.fc.bias"] = (width,)
        shapes["value.weight"] = (1, width)
        shapes["value.bias"] = (1,)
        shapes["advantage.weight"] = (self.num_actions, width)
        shapes["advantage.bias"] = (self.num_actions,)
        return shapes


@dataclass(frozen=True)
class WeightsFile:
    """A weights file's contents: its spec, the learner's version of the
    weights, and every tensor (float32 numpy arrays, read-only views of
    the bytes)."""

    spec: NetworkSpec
    version: int
    tensors: Dict[str, np.ndarray]
    metadata: Dict[str, str]


def _int(value: object, field: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(f"spec metadata: {field} is {value!r}, not an integer")
    return value


def read_bytes(source: Source) -> bytes:
    """The bytes of ``source``: bytes as they are; a folder's
    ``weights.safetensors`` (a checkpoint or a run's ``best/``); a file."""
    if isinstance(source, (bytes, bytearray, memoryview)):
        return bytes(source)
    path = Path(source)
    if path.is_dir():
        path = path / WEIGHTS_FILE
    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise ValueError(f"{path}: no such weights file") from None


def read_safetensors(data: bytes) -> Tuple[Dict[str, str], Dict[str, np.ndarray]]:
    """The metadata and the f32 tensors of safetensors bytes; anything else
    (another dtype, offsets outside the data) is a ``ValueError``."""
    if len(data) < 8:
        raise ValueError("not a safetensors file: shorter than its 8-byte header length")
    (n,) = struct.unpack("<Q", data[:8])
    if n > len(data) - 8:
        raise ValueError(f"not a safetensors file: a header of {n} bytes in {len(data)}")
    try:
        header = json.loads(data[8 : 8 + n])
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise ValueError(f"not a safetensors file: its header is not JSON ({e})") from None
    if not isinstance(header, dict):
        raise ValueError("not a safetensors file: its header is not a JSON object")
    metadata = header.pop("__metadata__", None) or {}
    body = memoryview(data)[8 + n :]
    tensors: Dict[str, np.ndarray] = {}
    for name, info in header.items():
        try:
            dtype, shape, (start, end) = info["dtype"], info["shape"], info["data_offsets"]
        except (KeyError, TypeError, ValueError):
            raise ValueError(f"tensor {name!r}: malformed safetensors entry {info!r}") from None
        if dtype != "F32":
            raise ValueError(f"tensor {name!r} is {dtype}; crossroads weights are F32")
        count = int(np.prod(shape, dtype=np.int64))
        if not 0 <= start <= end <= len(body) or end - start != 4 * count:
            raise ValueError(
                f"tensor {name!r}: bytes {start}..{end} do not hold shape {shape} "
                f"in {len(body)} bytes of data"
            )
        tensors[name] = np.frombuffer(body[start:end], dtype="<f4").reshape(shape)
    return metadata, tensors


def read_weights(source: Source) -> WeightsFile:
    """Reads and checks a weights file (path, folder or bytes): the format
    metadata, the spec, and that the tensors are exactly the spec's, with
    its shapes and finite values."""
    metadata, tensors = read_safetensors(read_bytes(source))
    if "spec" not in metadata:
        raise ValueError(
            "the file has no spec metadata: it is not a crossroads weights file "
            f"(metadata keys: {sorted(metadata)})"
        )
    if metadata.get("format") != FORMAT:
        raise ValueError(f"format is {metadata.get('format')!r}, expected {FORMAT!r}")
    if metadata.get("format_version") != FORMAT_VERSION:
        raise ValueError(
            f"format_version is {metadata.get('format_version')!r}; "
            f"this package reads {FORMAT_VERSION}"
        )
    try:
        version = int(metadata.get("weights_version", ""))
    except ValueError:
        raise ValueError(
            f"weights_version is {metadata.get('weights_version')!r}, not an integer"
        ) from None
    spec = NetworkSpec.from_json(metadata["spec"])
    expected = spec.tensor_shapes()
    missing = sorted(set(expected) - set(tensors))
    unknown = sorted(set(tensors) - set(expected))
    if missing or unknown:
        raise ValueError(
            f"tensor names do not match the {spec.trunk} network of the spec: "
            f"missing {missing}, unknown {unknown}"
        )
    for name, shape in expected.items():
        got = tuple(tensors[name].shape)
        if got != shape:
            raise ValueError(
                f"tensor {name!r} has shape {list(got)}, the spec's network has {list(shape)}"
            )
        if not np.isfinite(tensors[name]).all():
            raise ValueError(f"tensor {name!r} holds a NaN or infinite value")
    return WeightsFile(spec=spec, version=version, tensors=tensors, metadata=dict(metadata))
