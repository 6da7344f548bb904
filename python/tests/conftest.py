"""What the tests share: the ids, and where the crossroads binary is."""

from __future__ import annotations

import os
import pathlib
import shutil

import gymnasium as gym
import numpy as np
import pytest

import crossroads

ROOT = pathlib.Path(__file__).resolve().parents[2]
GYMNASIUM_1 = int(gym.__version__.split(".")[0]) >= 1


def crossroads_bin() -> str | None:
    """CROSSROADS_BIN, else the newer of the workspace's release and debug
    builds (`make test` builds the debug one; a release one may be older
    than the simulator it is compared with)."""
    if os.environ.get("CROSSROADS_BIN"):
        return os.environ["CROSSROADS_BIN"]
    builds = [ROOT / "target" / p / "crossroads" for p in ("release", "debug")]
    builds = [b for b in builds if b.exists()]
    if builds:
        return str(max(builds, key=lambda b: b.stat().st_mtime))
    return shutil.which("crossroads")


def equal(a, b, path: str = "") -> None:
    """Asserts deep equality of observations and infos (arrays, dicts,
    object arrays of arrays), naming where they differ."""
    if isinstance(a, (tuple, list)):
        assert type(a) is type(b) and len(a) == len(b), f"{path}: {type(b)} of {len(b)}"
        for i, (x, y) in enumerate(zip(a, b)):
            equal(x, y, f"{path}[{i}]")
    elif isinstance(a, dict):
        assert isinstance(b, dict) and set(a) == set(b), f"{path}: keys {sorted(a)} != {sorted(b)}"
        for k in a:
            equal(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, np.ndarray) and a.dtype == object:
        assert isinstance(b, np.ndarray) and b.dtype == object and a.shape == b.shape, path
        for i, (x, y) in enumerate(zip(a, b)):
            equal(x, y, f"{path}[{i}]")
    elif isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray), f"{path}: {type(b)}"
        assert a.dtype == b.dtype, f"{path}: dtype {a.dtype} != {b.dtype}"
        np.testing.assert_array_equal(a, b, err_msg=path)
    else:
        assert type(a) is type(b) and a == b, f"{path}: {a!r} != {b!r}"


needs_gymnasium_1 = pytest.mark.skipif(not GYMNASIUM_1, reason="vector environments need Gymnasium 1.x")
ALL_IDS = list(crossroads.ENV_IDS)
