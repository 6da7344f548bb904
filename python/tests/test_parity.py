"""A Python loop of the TTC rule gives the counts and the failing trials of
`crossroads eval` with the same seed (needs the binary: CROSSROADS_BIN,
else the newer of target/release and target/debug)."""

from __future__ import annotations

import json
import os
import subprocess

import gymnasium as gym
import pytest

from conftest import crossroads_bin
from crossroads.baselines import Shielded, ttc, ttc_creep

CASES = [
    # (id, policy flags, policy, trials, seed); the first is the issue's.
    ("crossroads/Left-TTG-v0", ["--policy", "ttc:1.5"], lambda: ttc(1.5), 10_000, 0),
    (
        "crossroads/Occluded-Creep-v0",
        ["--policy", "ttc-creep:1.5", "--actions", "creep", "--shield"],
        lambda: Shielded(ttc_creep(1.5)),
        300,
        0,
    ),
    # Collisions and timeouts both, with sequential actions.
    (
        "crossroads/Challenge-Sequential-v0",
        ["--policy", "ttc:1", "--actions", "sequential"],
        lambda: ttc(1.0),
        500,
        3,
    ),
]


def python_trials(env_id: str, policy, trials: int, seed: int) -> dict:
    env = gym.make(env_id)
    counts = {"success": 0, "collision": 0, "timeout": 0}
    collisions, timeouts = [], []
    env.reset(seed=seed)
    for trial in range(trials):
        if trial:
            env.reset()
        while True:
            _, _, term, trunc, info = env.step(policy(env))
            if term or trunc:
                break
        assert info["trial"] == trial
        counts[info["outcome"]] += 1
        if info["outcome"] == "collision":
            collisions.append(trial)
        elif info["outcome"] == "timeout":
            timeouts.append(trial)
    return {"counts": counts, "collisions": collisions, "timeouts": timeouts}


def cli_trials(binary: str, env_id: str, flags: list, trials: int, seed: int) -> dict:
    scenario = gym.spec(env_id).kwargs["scenario"]
    out = subprocess.run(
        [binary, "eval", *flags, "--scenario", scenario, "--trials", str(trials),
         "--seed", str(seed), "--json", "--failures", str(trials)],
        check=True, capture_output=True, text=True, env={**os.environ, "RUST_LOG": "warn"},
    )
    report = json.loads(out.stdout.strip().splitlines()[-1])
    rate = {k: report[f"{k}_rate"] for k in ("success", "collision", "timeout")}
    return {
        "counts": {k: round(v * report["trials"]) for k, v in rate.items()},
        "collisions": [t for t, _ in report["failures"]["collisions"]],
        "timeouts": report["failures"]["timeouts"],
    }


@pytest.mark.parametrize("env_id,flags,make_policy,trials,seed", CASES, ids=[c[0] for c in CASES])
def test_python_equals_crossroads_eval(env_id, flags, make_policy, trials, seed) -> None:
    binary = crossroads_bin()
    if binary is None:
        pytest.skip("no crossroads binary: set CROSSROADS_BIN")
    cli = cli_trials(binary, env_id, flags, trials, seed)
    py = python_trials(env_id, make_policy(), trials, seed)
    assert sum(py["counts"].values()) == trials
    assert py == cli
