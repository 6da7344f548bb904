"""Gymnasium 1.x vectorised environment: N intersections stepped in Rust
in one call, with Python's lock released."""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
from gymnasium import spaces
from gymnasium.vector import VectorEnv
from gymnasium.vector.utils import batch_space

from crossroads import _native
from crossroads._settings import OUTCOMES, Layout, native_kwargs, resolve

try:  # Gymnasium >= 1.1
    from gymnasium.vector import AutoresetMode
except ImportError:  # pragma: no cover - Gymnasium 1.0: next-step only
    AutoresetMode = None


def _mode_name(mode: Any) -> str:
    value = getattr(mode, "value", mode)
    if value in ("next-step", "NextStep", "next_step"):
        return "next-step"
    if value in ("same-step", "SameStep", "same_step"):
        return "same-step"
    raise ValueError(f"autoreset_mode {mode!r}: expected next-step or same-step")


def seeds_for(seed: int | Sequence[int | None] | None, num_envs: int) -> list[int | None]:
    """Gymnasium's rule: an int ``s`` seeds environment ``i`` with ``s + i``."""
    if seed is None:
        return [None] * num_envs
    if isinstance(seed, (int, np.integer)):
        return [int(seed) + i for i in range(num_envs)]
    seeds = [None if s is None else int(s) for s in seed]
    if len(seeds) != num_envs:
        raise ValueError(f"{len(seeds)} seeds for {num_envs} environments")
    return seeds


class CrossroadsVectorEnv(VectorEnv):
    """``num_envs`` environments of one scenario and action set.

    Environment ``i`` after ``reset(seed=s)`` is ``CrossroadsEnv`` after
    ``reset(seed=s + i)``, step for step, and the infos are those
    ``SyncVectorEnv`` builds from single environments. ``autoreset_mode``:
    Gymnasium's next-step (default) or same-step (the last observation in
    ``info["final_obs"]``). ``threads`` > 1 steps on a pool of its own.
    """

    def __init__(
        self,
        num_envs: int = 1,
        config: dict[str, Any] | None = None,
        render_mode: str | None = None,
        autoreset_mode: Any = "next-step",
        threads: int = 1,
        **kwargs: Any,
    ) -> None:
        self.config = resolve(config, **kwargs)
        native = native_kwargs(self.config)
        self._mode = _mode_name(autoreset_mode)
        if AutoresetMode is None and self._mode != "next-step":
            raise ValueError("same-step autoreset needs Gymnasium >= 1.1")
        self._core = _native.VecEnv(num_envs, autoreset=self._mode, threads=threads, **native)
        probe = _native.Env(**native)
        self._layout = Layout(probe, self.config["layout"])
        self.num_envs = num_envs
        self.single_observation_space = self._layout.space
        self.single_action_space = spaces.Discrete(probe.num_actions)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        mode = self._mode
        if AutoresetMode is not None:
            mode = AutoresetMode.NEXT_STEP if mode == "next-step" else AutoresetMode.SAME_STEP
        self.metadata = {"autoreset_mode": mode, "render_modes": ["rgb_array"], "render_fps": 5}
        self.render_mode = render_mode
        self._seeded = np.zeros(num_envs, dtype=bool)

    @property
    def core(self) -> _native.VecEnv:
        """The native environments (what the baselines' ``batch`` reads)."""
        return self._core

    def reset(
        self,
        *,
        seed: int | Sequence[int | None] | None = None,
        options: dict[str, Any] | None = None,
    ) -> tuple[Any, dict[str, Any]]:
        if isinstance(seed, (int, np.integer)):
            super().reset(seed=int(seed))
        seeds = seeds_for(seed, self.num_envs)
        for i, s in enumerate(seeds):
            if s is None and not self._seeded[i]:
                seeds[i] = int(self.np_random.integers(2**63))
        self._seeded[:] = True
        obs, base, trial, episode_seed = self._core.reset(seeds)
        every = np.ones(self.num_envs, dtype=bool)
        infos = {
            "seed": base.astype(np.int64),
            "_seed": every,
            "trial": trial.astype(np.int64),
            "_trial": every.copy(),
            "episode_seed": episode_seed,
            "_episode_seed": every.copy(),
        }
        return self._layout.shape(obs), infos

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        actions = np.asarray(actions, dtype=np.int64).reshape(self.num_envs)
        (obs, rewards, terminated, truncated, stepped, steps, discount, outcome, base, trial,
         episode_seed, final) = self._core.step(actions)
        every = np.ones(self.num_envs, dtype=bool)
        infos: dict[str, Any] = {
            "seed": base.astype(np.int64),
            "_seed": every,
            "trial": trial.astype(np.int64),
            "_trial": every.copy(),
            "episode_seed": episode_seed,
            "_episode_seed": every.copy(),
        }
        if final is None:
            # Where an environment only reset (next-step mode), the native
            # step left steps, discount and outcome at 0, as SyncVectorEnv.
            if stepped.any():
                infos.update(
                    steps=steps,
                    _steps=stepped,
                    discount=discount,
                    _discount=stepped.copy(),
                    outcome=OUTCOMES[outcome],
                    _outcome=stepped.copy(),
                    is_success=outcome == 1,
                    _is_success=stepped.copy(),
                )
            return self._layout.shape(obs), rewards, terminated, truncated, infos
        # Same-step mode with endings: their step infos go to final_info.
        has_step = ~final[0]
        if has_step.any():
            names = OUTCOMES[outcome]
            names[~has_step] = None
            infos.update(
                steps=np.where(has_step, steps, 0),
                _steps=has_step,
                discount=np.where(has_step, discount, 0.0),
                _discount=has_step.copy(),
                outcome=names,
                _outcome=has_step.copy(),
                is_success=(outcome == 1) & has_step,
                _is_success=has_step.copy(),
            )
        ended, last, final_trial, final_seed = final
        final_obs = np.full(self.num_envs, None, dtype=object)
        shaped = self._layout.shape(last)
        for j, i in enumerate(np.flatnonzero(ended)):
            final_obs[i] = (
                shaped[j] if self._layout.kind == "flat"
                else {k: v[j] for k, v in shaped.items()}
            )
        names = OUTCOMES[outcome]
        names[~ended] = None
        infos["final_obs"] = final_obs
        infos["_final_obs"] = ended
        infos["final_info"] = {
            "seed": np.where(ended, base, 0).astype(np.int64),
            "_seed": ended.copy(),
            "trial": np.where(ended, final_trial, 0).astype(np.int64),
            "_trial": ended.copy(),
            "episode_seed": np.where(ended, final_seed, 0).astype(np.uint64),
            "_episode_seed": ended.copy(),
            "steps": np.where(ended, steps, 0),
            "_steps": ended.copy(),
            "discount": np.where(ended, discount, 0.0),
            "_discount": ended.copy(),
            "outcome": names,
            "_outcome": ended.copy(),
            "is_success": (outcome == 1) & ended,
            "_is_success": ended.copy(),
        }
        infos["_final_info"] = ended.copy()
        return self._layout.shape(obs), rewards, terminated, truncated, infos

    def render(self) -> tuple[np.ndarray, ...] | None:
        if self.render_mode != "rgb_array":
            return None
        grid, scale = self.config["render_grid"], self.config["render_scale"]
        return tuple(self._core.render(i, grid, scale) for i in range(self.num_envs))
