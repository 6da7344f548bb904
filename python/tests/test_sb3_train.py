"""Issue 44's acceptance: SB3's DQN trained on Right-TTG by
python/examples/sb3_dqn.py with its default budget reaches 95 % success
with at most 2 % collisions on 1,000 held-out episodes, and beats a random
policy and go-at-once. A training of about a minute: it runs only with
CROSSROADS_SLOW_TESTS=1."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from conftest import GYMNASIUM_1, ROOT

pytestmark = [
    pytest.mark.skipif(
        os.environ.get("CROSSROADS_SLOW_TESTS") != "1",
        reason="a training of about a minute: set CROSSROADS_SLOW_TESTS=1",
    ),
    pytest.mark.skipif(not GYMNASIUM_1, reason="the example's budget is tuned on Gymnasium 1.x"),
]


def test_sb3_dqn_on_right_ttg(tmp_path):
    pytest.importorskip(
        "stable_baselines3", reason="needs the sb3 extra: pip install './python[sb3]'"
    )
    out = tmp_path / "results.json"
    subprocess.run(
        [
            sys.executable,
            str(ROOT / "python" / "examples" / "sb3_dqn.py"),
            "--env-id", "crossroads/Right-TTG-v0",
            "--eval-episodes", "1000",
            "--out", str(tmp_path / "model"),
            "--json", str(out),
        ],
        check=True,
        timeout=900,
    )
    results = {r["policy"]: r for r in json.loads(out.read_text())["results"]}
    dqn, rand, go = results["dqn"], results["random"], results["go-at-once"]
    assert dqn["episodes"] == 1000
    assert dqn["success"] >= 0.95, dqn
    assert dqn["collision"] <= 0.02, dqn
    for baseline in (rand, go):
        assert dqn["success"] > baseline["success"], (dqn, baseline)
        assert dqn["collision"] < baseline["collision"], (dqn, baseline)
