"""The Gymnasium environment: one intersection, stepped in Rust."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from crossroads import _native
from crossroads._settings import Layout, native_kwargs, resolve


class CrossroadsEnv(gym.Env):
    """One intersection of the crossroads simulator.

    Actions are ``Discrete``: the action set's indices (TTG: 0 go, 1-4 wait
    1, 2, 4, 8 steps; Creep: 0 wait, 1 creep, 2 go; Sequential: 12
    accelerations). A decision may take several simulator steps of 0.2 s
    (a semi-MDP): ``info["steps"]`` says how many, the reward is their
    discounted sum and ``info["discount"]`` is ``gamma ** steps``. Success
    and collision end an episode as ``terminated``, the time limit as
    ``truncated``. ``info`` also has ``outcome``, ``is_success``, and the
    episode's ``seed``, ``trial`` and ``episode_seed``: after
    ``reset(seed=s)``, episode ``e`` is trial ``e`` of ``crossroads eval
    --seed s``. Settings: the keyword arguments or ``config=``
    (:data:`crossroads.DEFAULT_CONFIG`).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 5}

    def __init__(
        self,
        config: dict[str, Any] | None = None,
        render_mode: str | None = None,
        **kwargs: Any,
    ) -> None:
        self.config = resolve(config, **kwargs)
        self._core = _native.Env(**native_kwargs(self.config))
        self._layout = Layout(self._core, self.config["layout"])
        self.observation_space = self._layout.space
        self.action_space = spaces.Discrete(self._core.num_actions)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode {render_mode!r}: expected 'rgb_array' or None")
        self.render_mode = render_mode
        self._seeded = False

    @property
    def core(self) -> _native.Env:
        """The native environment (what the baselines read)."""
        return self._core

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        super().reset(seed=seed)
        if seed is not None:
            base = int(seed)
        elif not self._seeded:
            base = int(self.np_random.integers(2**63))
        else:
            base = None
        self._seeded = True
        obs, info = self._core.reset(base)
        return self._layout.shape(obs), info

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self._core.step(int(action))
        return self._layout.shape(obs), reward, terminated, truncated, info

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        return self._core.render(self.config["render_grid"], self.config["render_scale"])

    def __repr__(self) -> str:
        return f"CrossroadsEnv({self._core!r}, layout={self.config['layout']!r})"
