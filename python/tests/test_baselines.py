"""The baselines from Python: valid actions, the shield's vetoes, and the
action sets they refuse."""

from __future__ import annotations

import gymnasium as gym
import pytest

import crossroads
from crossroads.baselines import Shielded, ttc, ttc_creep


def episode(env: gym.Env, policy, seed: int) -> str:
    env.reset(seed=seed)
    while True:
        _, _, term, trunc, info = env.step(policy(env))
        if term or trunc:
            return info["outcome"]


def test_ttc_creep_behind_the_shield_drives_occluded() -> None:
    env = gym.make("crossroads/Occluded-Creep-v0")
    policy = Shielded(ttc_creep(1.5))
    outcomes = [episode(env, policy, s) for s in range(20)]
    assert set(outcomes) <= {"success", "collision", "timeout"}
    assert policy.go_decisions >= policy.vetoes


def test_unsupported_action_sets_are_refused() -> None:
    env = gym.make("crossroads/Left-TTG-v0")
    env.reset(seed=0)
    with pytest.raises(ValueError):
        ttc_creep(1.5)(env)
    seq = gym.make("crossroads/Left-Sequential-v0")
    seq.reset(seed=0)
    assert 0 <= ttc(1.5)(seq) < 12
    with pytest.raises(ValueError):
        Shielded(ttc(1.5))(seq)
    with pytest.raises(TypeError):
        ttc(1.5)(object())
