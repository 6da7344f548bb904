"""Seeding: episode e after reset(seed=s) is trial e of `crossroads eval
--seed s`, and the same seed gives the same episodes."""

from __future__ import annotations

import gymnasium as gym
import numpy as np

import crossroads


def run(env: gym.Env, seed: int | None, episodes: int, actions: np.ndarray) -> list:
    out = []
    obs, info = env.reset(seed=seed)
    k = 0
    for _ in range(episodes):
        trace = [obs.copy(), info["trial"]]
        done = False
        while not done:
            obs, r, term, trunc, info = env.step(int(actions[k % len(actions)]))
            k += 1
            trace.append((obs.copy(), r, term, trunc, info["steps"], info["outcome"]))
            done = term or trunc
        out.append(trace)
        obs, info = env.reset()
    return out


def same(a: list, b: list) -> bool:
    return repr(a) == repr(b) and all(
        np.array_equal(x[0], y[0]) for x, y in zip(a, b)
    )


def test_same_seed_same_episodes() -> None:
    actions = np.random.default_rng(5).integers(0, 5, 400)
    env = gym.make("crossroads/Right-TTG-v0")
    a = run(env, 11, 5, actions)
    b = run(env, 11, 5, actions)
    assert same(a, b)
    c = run(env, 12, 5, actions)
    assert not same(a, c)


def test_infos_name_the_trial() -> None:
    env = gym.make("crossroads/Left-Sequential-v0")
    _, info = env.reset(seed=42)
    assert (info["seed"], info["trial"]) == (42, 0)
    assert info["episode_seed"] == crossroads.episode_seed(42, 0)
    assert isinstance(info["episode_seed"], np.uint64)
    for trial in range(1, 4):
        _, info = env.reset()
        assert (info["seed"], info["trial"]) == (42, trial)
        assert info["episode_seed"] == crossroads.episode_seed(42, trial)


def test_semi_mdp_infos() -> None:
    env = gym.make("crossroads/Left-TTG-v0")
    env.reset(seed=0)
    _, _, _, _, info = env.step(4)  # wait 8 steps
    assert info["steps"] == 8 and np.isclose(info["discount"], 0.99**8)
    assert info["outcome"] is None and info["is_success"] is False
    _, _, term, trunc, info = env.step(0)  # go: to the end
    assert term or trunc
    assert info["outcome"] in ("success", "collision", "timeout")
    assert info["is_success"] == (info["outcome"] == "success")
    assert term == (info["outcome"] != "timeout")


def test_unseeded_resets_differ_between_environments() -> None:
    a, b = crossroads.CrossroadsEnv(), crossroads.CrossroadsEnv()
    assert a.reset()[1]["seed"] != b.reset()[1]["seed"]


def test_render_draws_the_scene() -> None:
    env = gym.make("crossroads/Occluded-Creep-v0", render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 4
    plain = crossroads.CrossroadsEnv(scenario="left", render_mode="rgb_array")
    plain.reset(seed=0)
    assert plain.render().shape == (400, 960, 3)
