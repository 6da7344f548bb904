"""crossroads for Python: Gymnasium environments of the crossroads
intersection simulator, stepped in Rust.

``import crossroads`` registers ``crossroads/<Scenario>-<Actions>-v0`` for
the paper's experiments and ``crossroads/Intersection-v0`` (``config=``);
:class:`CrossroadsEnv` is one environment, :class:`CrossroadsVectorEnv`
(Gymnasium 1.x) steps many in one native call, :mod:`crossroads.baselines`
has the TTC rule and the shield, :mod:`crossroads.sb3` an adapter for
Stable-Baselines3. After ``reset(seed=s)``, episode ``e`` is trial ``e`` of
``crossroads eval --seed s``. Guide: docs/python.md.
"""

from __future__ import annotations

from importlib import metadata as _metadata
from typing import Any

from crossroads._native import builtin_scenarios, episode_seed
from crossroads._settings import DEFAULT_CONFIG
from crossroads.baselines import TTC, Shielded, ttc, ttc_creep
from crossroads.env import CrossroadsEnv
from crossroads.registration import ENV_IDS, register_envs

try:
    __version__ = _metadata.version("crossroads")
except _metadata.PackageNotFoundError:  # pragma: no cover - source tree
    __version__ = "0+unknown"

__all__ = [
    "DEFAULT_CONFIG",
    "ENV_IDS",
    "TTC",
    "CrossroadsEnv",
    "CrossroadsVectorEnv",
    "Shielded",
    "builtin_scenarios",
    "episode_seed",
    "ttc",
    "ttc_creep",
]

register_envs()


def __getattr__(name: str) -> Any:
    # The vector environment needs Gymnasium 1.x: imported when asked for.
    if name == "CrossroadsVectorEnv":
        from crossroads.vector import CrossroadsVectorEnv

        return CrossroadsVectorEnv
    raise AttributeError(f"module 'crossroads' has no attribute {name!r}")
