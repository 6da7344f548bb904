"""Gymnasium's and Stable-Baselines3's environment checkers on every
registered id, with warnings turned into errors."""

from __future__ import annotations

import warnings

import gymnasium as gym
import pytest
from gymnasium.utils.env_checker import check_env

import crossroads
from conftest import ALL_IDS, ROOT


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_gymnasium_check_env(env_id: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = gym.make(env_id, render_mode="rgb_array")
        check_env(env.unwrapped)
        # gym.make's own checker on the first reset and step, too.
        env.reset(seed=1)
        env.step(env.action_space.sample())
        env.close()


@pytest.mark.parametrize("env_id", ["crossroads/Left-TTG-v0", "crossroads/Occluded-Creep-v0"])
def test_gymnasium_check_env_grid_layout(env_id: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = gym.make(env_id, layout="grid")
        check_env(env.unwrapped)
        obs, _ = env.reset(seed=3)
        assert obs["grid"].shape == env.unwrapped.core.grid_shape


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_sb3_check_env(env_id: str) -> None:
    sb3_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sb3_checker.check_env(gym.make(env_id).unwrapped, warn=True)


def test_ids_cover_the_paper() -> None:
    for scenario in ("Left", "Right", "Left2", "Forward", "Challenge", "Occluded"):
        for actions in ("TTG", "Sequential"):
            assert f"crossroads/{scenario}-{actions}-v0" in crossroads.ENV_IDS
    assert "crossroads/Occluded-Creep-v0" in crossroads.ENV_IDS
    env = gym.make("crossroads/Intersection-v0", config={"scenario": "right", "actions": "creep"})
    assert env.unwrapped.core.scenario == "right" and env.action_space.n == 3


def test_config_overrides_and_errors() -> None:
    env = crossroads.CrossroadsEnv(
        config={"scenario": "left", "drivers": "human", "overrides": {"step_limit": 30}}
    )
    env.reset(seed=0)
    done, steps = False, 0
    while not done:
        _, _, term, trunc, info = env.step(1)
        done, steps = term or trunc, steps + info["steps"]
    assert steps <= 30
    from_file = crossroads.CrossroadsEnv(scenario=str(ROOT / "configs/scenarios/right.toml"))
    assert from_file.core.scenario == "right"
    with pytest.raises(ValueError, match="unknown config keys"):
        crossroads.CrossroadsEnv(config={"scenaro": "left"})
    with pytest.raises(ValueError, match="scenario"):
        crossroads.CrossroadsEnv(scenario="nowhere")
    with pytest.raises(ValueError, match="out of range"):
        env.step(7)
