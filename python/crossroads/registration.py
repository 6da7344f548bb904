"""The environment ids registered on ``import crossroads``: every scenario
and action set of the paper's experiments (configs/experiments/), Table
II's occlusion lengths, and ``crossroads/Intersection-v0`` taking
``config=``."""

from __future__ import annotations

import gymnasium as gym

_SCENARIOS = {
    "Left": "left",
    "Right": "right",
    "Left2": "left2",
    "Forward": "forward",
    "Challenge": "challenge",
    "Occluded": "occluded",
}
_ACTIONS = {"TTG": "ttg", "Sequential": "sequential", "Creep": "creep"}


def _paper() -> dict[str, dict[str, str]]:
    ids: dict[str, dict[str, str]] = {}
    for name, scenario in _SCENARIOS.items():
        for label in ("TTG", "Sequential"):
            ids[f"crossroads/{name}-{label}-v0"] = {"scenario": scenario, "actions": _ACTIONS[label]}
    ids["crossroads/Occluded-Creep-v0"] = {"scenario": "occluded", "actions": "creep"}
    for length in (30, 60, 90):
        for label in ("Creep", "Sequential"):
            ids[f"crossroads/Occluded{length}-{label}-v0"] = {
                "scenario": f"occluded-{length}",
                "actions": _ACTIONS[label],
            }
    return ids


#: Each registered id and the settings it fixes.
ENV_IDS: dict[str, dict[str, str]] = {**_paper(), "crossroads/Intersection-v0": {}}


def register_envs() -> None:
    """Registers every id (once); the vectorised entry point where
    Gymnasium has one (1.x)."""
    vector = int(gym.__version__.split(".")[0]) >= 1
    for env_id, kwargs in ENV_IDS.items():
        if env_id in gym.registry:
            continue
        extra = {}
        if vector:
            extra["vector_entry_point"] = "crossroads.vector:CrossroadsVectorEnv"
        gym.register(
            id=env_id,
            entry_point="crossroads.env:CrossroadsEnv",
            kwargs=dict(kwargs),
            nondeterministic=False,
            **extra,
        )
