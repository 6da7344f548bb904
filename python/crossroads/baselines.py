"""The rule baselines as callables on an environment's present state, so a
learned policy can be compared with them trial by trial: the TTC rule, TTC
with creeping, and the safety shield in front of any policy. They are the
policies of ``crossroads eval --policy ttc:T|ttc-creep:T [--shield]``."""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from crossroads import _native


def _single(env: Any) -> _native.Env:
    """The native environment of a CrossroadsEnv (wrapped or not)."""
    if isinstance(env, _native.Env):
        return env
    core = getattr(getattr(env, "unwrapped", env), "core", None)
    if not isinstance(core, _native.Env):
        raise TypeError(f"{env!r} is not a crossroads environment")
    return core


def _vector(envs: Any) -> _native.VecEnv:
    """The native environments of a vectorised crossroads environment."""
    if isinstance(envs, _native.VecEnv):
        return envs
    core = getattr(getattr(envs, "unwrapped", envs), "core", None)
    if not isinstance(core, _native.VecEnv):
        raise TypeError(f"{envs!r} is not a vectorised crossroads environment")
    return core


class TTC:
    """Go when every car the ego sees is more than ``threshold`` seconds
    from its path; with ``creep``, first creep until the conflicting lanes
    are in view (creep and sequential actions only)."""

    def __init__(self, threshold: float = 1.5, creep: bool = False) -> None:
        self._rule = _native.Ttc(threshold, creep)
        self.name = self._rule.name

    def __call__(self, env: Any) -> int:
        """The action for ``env``'s present state."""
        return self._rule(_single(env))

    def batch(self, envs: Any) -> np.ndarray:
        """One action per environment of a vectorised environment."""
        return self._rule.batch(_vector(envs))

    def __repr__(self) -> str:
        return f"TTC({self.name})"


def ttc(threshold: float = 1.5) -> TTC:
    """``crossroads eval --policy ttc:<threshold>``."""
    return TTC(threshold, creep=False)


def ttc_creep(threshold: float = 1.5) -> TTC:
    """``crossroads eval --policy ttc-creep:<threshold>``."""
    return TTC(threshold, creep=True)


class Shielded:
    """``policy`` behind the safety shield: a *go* the shield cannot prove
    safe becomes a one-step creep (before the creep limit) or wait. TTG and
    Creep actions; ``assumptions`` as ``--shield`` takes them (``default``
    or ``key=value,...``, e.g. ``assume=human``)."""

    def __init__(self, policy: Callable[[Any], int], assumptions: str = "default") -> None:
        self.policy = policy
        self._shield = _native.Shield(assumptions)

    def __call__(self, env: Any) -> int:
        return self._shield(_single(env), int(self.policy(env)))

    def batch(self, envs: Any) -> np.ndarray:
        """Vets the inner policy's ``batch`` actions."""
        actions = np.asarray(self.policy.batch(envs), dtype=np.int64)  # type: ignore[attr-defined]
        return self._shield.batch(_vector(envs), actions)

    @property
    def vetoes(self) -> int:
        """*Go* decisions vetoed so far."""
        return self._shield.vetoes

    @property
    def go_decisions(self) -> int:
        """*Go* decisions checked so far."""
        return self._shield.go_decisions
