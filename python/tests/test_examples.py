"""The examples still run: python/examples/cleanrl_dqn.py for a few
hundred decisions, under either Gymnasium version (its learning is
measured in reports/performance; the SB3 example's in
test_sb3_train.py)."""

from __future__ import annotations

import subprocess
import sys

import pytest

from conftest import ROOT


def test_cleanrl_dqn_runs():
    pytest.importorskip("torch", reason="needs torch: pip install './python[torch]'")
    done = subprocess.run(
        [
            sys.executable,
            str(ROOT / "python" / "examples" / "cleanrl_dqn.py"),
            "--total-timesteps", "300",
            "--learning-starts", "100",
            "--eval-episodes", "5",
        ],
        check=True,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert "eval: 5 episodes from reset(seed=1000000000)" in done.stdout, done.stdout
