"""How the Python classes turn ``config=`` and keyword arguments into the
native environment's settings, spaces and observations."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
from gymnasium import spaces

from crossroads import _native

#: Every key of ``config=`` and its default (highway-env's convention:
#: ``config`` overrides the keyword arguments, key by key).
DEFAULT_CONFIG: dict[str, Any] = {
    # A built-in scenario (left, right, left2, forward, challenge,
    # occluded, occluded-<30|60|90>[-<left|right|both>]) or a TOML file.
    "scenario": "left",
    # ttg, sequential or creep.
    "actions": "ttg",
    # sumo, human, mixed or a drivers TOML file; None keeps the scenario's.
    "drivers": None,
    # "flat": one float32 vector; "grid": {"grid": (C, H, W), "ego": (4,)}.
    "layout": "flat",
    # The grid: ttg or sequential; None pairs it with the action set.
    "observation": None,
    # Discount inside a k-step action (info["discount"] is gamma**steps).
    "gamma": 0.99,
    # Reward of a collision in place of the scenario's (-10).
    "collision_reward": None,
    # Merged into the scenario's spec, e.g. {"traffic": {"headway": 1.2}}.
    "overrides": None,
    # render() overlays the observation grid.
    "render_grid": False,
    # render() pixels per metre; None: crossroads render's.
    "render_scale": None,
}

#: Outcome names by the native step's codes (0 while running).
OUTCOMES = np.array([None, "success", "collision", "timeout"], dtype=object)

NATIVE_KEYS = ("scenario", "actions", "drivers", "observation", "gamma", "collision_reward")


def resolve(config: dict[str, Any] | None, **kwargs: Any) -> dict[str, Any]:
    """The defaults, then the keyword arguments, then ``config``."""
    out = dict(DEFAULT_CONFIG)
    for source in (kwargs, config or {}):
        unknown = set(source) - set(DEFAULT_CONFIG)
        if unknown:
            raise ValueError(
                f"unknown config keys {sorted(unknown)}; known: {sorted(DEFAULT_CONFIG)}"
            )
        out.update(source)
    if out["layout"] not in ("flat", "grid"):
        raise ValueError(f"layout {out['layout']!r}: expected 'flat' or 'grid'")
    return out


def native_kwargs(settings: dict[str, Any]) -> dict[str, Any]:
    """The native constructor's keyword arguments."""
    kwargs = {key: settings[key] for key in NATIVE_KEYS}
    kwargs["scenario"] = str(kwargs["scenario"])
    if settings["overrides"] is not None:
        kwargs["overrides"] = json.dumps(settings["overrides"])
    return kwargs


class Layout:
    """The observation space of one environment, and how a flat
    observation (or a batch of them) becomes one of its observations."""

    def __init__(self, core: _native.Env, layout: str) -> None:
        self.kind = layout
        self.grid_shape = tuple(core.grid_shape)
        self.grid_len = int(np.prod(self.grid_shape))
        low, high = core.obs_low, core.obs_high
        if layout == "flat":
            self.space: spaces.Space = spaces.Box(low, high, dtype=np.float32)
        else:
            g = self.grid_len
            self.space = spaces.Dict(
                {
                    "grid": spaces.Box(
                        low[:g].reshape(self.grid_shape),
                        high[:g].reshape(self.grid_shape),
                        dtype=np.float32,
                    ),
                    "ego": spaces.Box(low[g:], high[g:], dtype=np.float32),
                }
            )

    def shape(self, flat: np.ndarray) -> Any:
        """One observation (``flat`` of shape ``(L,)``) or a batch
        (``(N, L)``) in this layout: the array itself, or views of it."""
        if self.kind == "flat":
            return flat
        lead = flat.shape[:-1]
        return {
            "grid": flat[..., : self.grid_len].reshape(*lead, *self.grid_shape),
            "ego": flat[..., self.grid_len :],
        }
