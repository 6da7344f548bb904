"""Stable-Baselines3's ``VecEnv`` over the native vectorised environment
(imports SB3, so only imported when asked for: ``crossroads.sb3``).

It behaves as SB3's ``DummyVecEnv`` of ``CrossroadsEnv``: ``seed(s)``
then ``reset()`` seeds environment ``i`` with ``s + i``, a finished
environment resets at once with its last observation in
``info["terminal_observation"]``, and ``info["TimeLimit.truncated"]``
marks timeouts.
"""

from __future__ import annotations

from typing import Any, Iterable, Sequence

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices, VecEnvStepReturn

from crossroads import _native
from crossroads._settings import OUTCOMES, Layout, native_kwargs, resolve


class CrossroadsVecEnv(VecEnv):
    """``num_envs`` crossroads environments stepped in one native call.
    ``env_id`` takes a registered id's settings; ``config`` and keyword
    arguments as :class:`crossroads.CrossroadsEnv` takes them."""

    def __init__(
        self,
        num_envs: int = 1,
        env_id: str | None = None,
        config: dict[str, Any] | None = None,
        render_mode: str | None = None,
        threads: int = 1,
        **kwargs: Any,
    ) -> None:
        if env_id is not None:
            kwargs = {**gym.spec(env_id).kwargs, **kwargs}
        self.config = resolve(config, **kwargs)
        native = native_kwargs(self.config)
        self._core = _native.VecEnv(num_envs, autoreset="same-step", threads=threads, **native)
        probe = _native.Env(**native)
        self._layout = Layout(probe, self.config["layout"])
        self.render_mode = render_mode
        self._seeded = np.zeros(num_envs, dtype=bool)
        self._rng = np.random.default_rng()
        self._actions = np.zeros(num_envs, dtype=np.int64)
        super().__init__(num_envs, self._layout.space, spaces.Discrete(probe.num_actions))

    @property
    def core(self) -> _native.VecEnv:
        """The native environments (what the baselines' ``batch`` reads)."""
        return self._core

    def reset(self) -> Any:
        seeds: list[int | None] = [None if s is None else int(s) for s in self._seeds]
        for i, s in enumerate(seeds):
            if s is None and not self._seeded[i]:
                seeds[i] = int(self._rng.integers(2**63))
        self._seeded[:] = True
        obs, base, trial, episode_seed = self._core.reset(seeds)
        self.reset_infos = [
            {"seed": int(base[i]), "trial": int(trial[i]), "episode_seed": episode_seed[i]}
            for i in range(self.num_envs)
        ]
        self._reset_seeds()
        self._reset_options()
        return self._layout.shape(obs)

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions, dtype=np.int64).reshape(self.num_envs)

    def step_wait(self) -> VecEnvStepReturn:
        (obs, rewards, terminated, truncated, _stepped, steps, discount, outcome, base, trial,
         episode_seed, final) = self._core.step(self._actions)
        dones = terminated | truncated
        infos: list[dict[str, Any]] = []
        for i in range(self.num_envs):
            info = {
                "seed": int(base[i]),
                "trial": int(trial[i]),
                "episode_seed": episode_seed[i],
                "steps": int(steps[i]),
                "discount": float(discount[i]),
                "outcome": OUTCOMES[outcome[i]],
                "is_success": bool(outcome[i] == 1),
                "TimeLimit.truncated": bool(truncated[i] and not terminated[i]),
            }
            infos.append(info)
        if final is not None:
            _ended, last, final_trial, final_seed = final
            shaped = self._layout.shape(last)
            for j, i in enumerate(np.flatnonzero(dones)):
                infos[i]["trial"] = int(final_trial[i])
                infos[i]["episode_seed"] = final_seed[i]
                infos[i]["terminal_observation"] = (
                    shaped[j] if self._layout.kind == "flat"
                    else {k: v[j] for k, v in shaped.items()}
                )
                self.reset_infos[i] = {
                    "seed": int(base[i]),
                    "trial": int(trial[i]),
                    "episode_seed": episode_seed[i],
                }
        return self._layout.shape(obs), rewards.astype(np.float32), dones, infos

    def close(self) -> None:
        pass

    def get_images(self) -> Sequence[np.ndarray | None]:
        grid, scale = self.config["render_grid"], self.config["render_scale"]
        return [self._core.render(i, grid, scale) for i in range(self.num_envs)]

    def _indices(self, indices: VecEnvIndices) -> Iterable[int]:
        if indices is None:
            return range(self.num_envs)
        if isinstance(indices, int):
            return [indices]
        return indices

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        # Every environment has the same settings.
        if attr_name not in ("render_mode", "config", "observation_space", "action_space"):
            raise AttributeError(f"crossroads environments have no attribute {attr_name!r}")
        value = getattr(self, attr_name)
        return [value for _ in self._indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        raise AttributeError(f"cannot set {attr_name!r} on crossroads environments")

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **method_kwargs: Any
    ) -> list[Any]:
        raise AttributeError(f"crossroads environments have no method {method_name!r} to call")

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> list[bool]:
        return [False for _ in self._indices(indices)]
