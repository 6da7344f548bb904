"""The native vectorised environment equals single environments step for
step: Gymnasium's SyncVectorEnv over CrossroadsEnv (observations, rewards,
ends and infos, both autoreset modes), and SB3's DummyVecEnv."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from conftest import equal, needs_gymnasium_1
from crossroads.baselines import ttc_creep

def pairs(env_id: str, n: int, mode: str, **kwargs):
    from gymnasium.vector import AutoresetMode, SyncVectorEnv

    from crossroads.vector import CrossroadsVectorEnv

    gym_mode = AutoresetMode.NEXT_STEP if mode == "next-step" else AutoresetMode.SAME_STEP
    spec_kwargs = gym.spec(env_id).kwargs
    native = CrossroadsVectorEnv(n, autoreset_mode=gym_mode, **spec_kwargs, **kwargs)
    sync = SyncVectorEnv(
        [lambda: gym.make(env_id, **kwargs) for _ in range(n)], autoreset_mode=gym_mode
    )
    return native, sync


@needs_gymnasium_1
@pytest.mark.parametrize("mode", ["next-step", "same-step"])
@pytest.mark.parametrize(
    "env_id,layout",
    [("crossroads/Right-TTG-v0", "flat"), ("crossroads/Occluded-Sequential-v0", "grid")],
)
def test_native_equals_sync(env_id: str, layout: str, mode: str) -> None:
    native, sync = pairs(env_id, 6, mode, layout=layout)
    assert native.observation_space == sync.observation_space
    assert native.action_space == sync.action_space
    equal(native.reset(seed=9), sync.reset(seed=9))
    rng = np.random.default_rng(0)
    ends = 0
    for t in range(400):
        actions = rng.integers(0, native.single_action_space.n, native.num_envs)
        a, b = native.step(actions), sync.step(actions)
        equal(a, b, f"step {t}")
        ends += int(np.sum(a[2] | a[3]))
    assert ends > 20
    # A reset mid-way with a list of seeds, one left to run on.
    equal(native.reset(seed=[3, None, 5, 6, 7, 8]), sync.reset(seed=[3, None, 5, 6, 7, 8]))


@needs_gymnasium_1
def test_make_vec_is_native_and_threads_change_nothing() -> None:
    from crossroads.vector import CrossroadsVectorEnv

    envs = gym.make_vec("crossroads/Occluded-Creep-v0", 4)
    assert isinstance(envs.unwrapped, CrossroadsVectorEnv)
    threaded = CrossroadsVectorEnv(4, scenario="occluded", actions="creep", threads=2)
    equal(envs.reset(seed=1), threaded.reset(seed=1))
    policy = ttc_creep(1.5)
    for t in range(200):
        actions = policy.batch(envs)
        equal(envs.step(actions), threaded.step(actions), f"step {t}")


def test_sb3_adapter_equals_dummy_vec_env() -> None:
    pytest.importorskip("stable_baselines3")
    from stable_baselines3.common.vec_env import DummyVecEnv

    from crossroads.sb3 import CrossroadsVecEnv

    env_id = "crossroads/Left-TTG-v0"
    native = CrossroadsVecEnv(5, env_id=env_id)
    dummy = DummyVecEnv([lambda: gym.make(env_id) for _ in range(5)])
    native.seed(4)
    dummy.seed(4)
    equal(native.reset(), dummy.reset())
    equal(native.reset_infos, dummy.reset_infos)
    rng = np.random.default_rng(1)
    for t in range(300):
        actions = rng.integers(0, 5, 5)
        obs_a, rew_a, done_a, info_a = native.step(actions)
        obs_b, rew_b, done_b, info_b = dummy.step(actions)
        equal((obs_a, rew_a, done_a), (obs_b, rew_b, done_b), f"step {t}")
        equal(dict(enumerate(info_a)), dict(enumerate(info_b)), f"step {t} infos")
