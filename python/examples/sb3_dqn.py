"""Trains Stable-Baselines3's DQN on a crossroads environment, then plays
it, a random policy and go-at-once on held-out episodes.

    python python/examples/sb3_dqn.py [--env-id crossroads/Right-TTG-v0]
        [--timesteps 50000] [--seed 0] [--out runs/sb3-dqn] [--eval-episodes 1000]

Training steps ``N_ENVS`` environments of ``crossroads.sb3.CrossroadsVecEnv``
seeded ``seed`` to ``seed + N_ENVS - 1`` (more training per second than
one ``gym.make`` environment with an update per decision); the
evaluation plays episodes 0 to n - 1 after ``reset(seed=EVAL_SEED)``,
which no training seed reaches, so they are trials 0 to n - 1 of
``crossroads eval --seed 1000000000``. Prints one line per policy (success, collision and timeout
rates, mean time of the successful episodes) and saves the model to
``<out>/model.zip``; ``--json`` also writes the results to a file.
Needs the ``sb3`` extra.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import time
from dataclasses import asdict, dataclass
from typing import Any, Callable

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3 import DQN

import crossroads  # noqa: F401  (registers the ids)
from crossroads.sb3 import CrossroadsVecEnv

#: The held-out episodes' reset seed; training seeds stay below it.
EVAL_SEED = 1_000_000_000
#: Environments stepped together while training.
N_ENVS = 8
#: The simulator's step (time = steps x 0.2 s).
STEP_S = 0.2

#: DQN's settings, tuned on Right-TTG: the default budget takes about a
#: minute on one core (reports/performance/README.md#python has the runs).
#: train_freq counts vector steps, so one update per N_ENVS decisions;
#: gamma is per decision, however many simulator steps it lasts.
HYPERPARAMETERS: dict[str, Any] = {
    "learning_rate": 5e-4,
    "buffer_size": 50_000,
    "learning_starts": 2_000,
    "batch_size": 64,
    "gamma": 0.95,
    "train_freq": 1,
    "gradient_steps": 1,
    "target_update_interval": 1_000,
    "exploration_fraction": 0.3,
    "exploration_final_eps": 0.02,
    "policy_kwargs": {"net_arch": [128, 128]},
}


@dataclass
class Results:
    """One policy's outcomes over the held-out episodes."""

    policy: str
    episodes: int
    success: float
    collision: float
    timeout: float
    #: Mean time of the successful episodes, in seconds.
    mean_time_s: float | None

    def line(self) -> str:
        time_s = "-" if self.mean_time_s is None else f"{self.mean_time_s:.2f} s"
        return (
            f"{self.policy:<12} success {100 * self.success:6.2f} %  "
            f"collision {100 * self.collision:5.2f} %  timeout {100 * self.timeout:5.2f} %  "
            f"mean time {time_s}"
        )


def evaluate(
    env_id: str, name: str, policy: Callable[[np.ndarray], int], episodes: int
) -> Results:
    """Plays ``episodes`` episodes from ``reset(seed=EVAL_SEED)``."""
    env = gym.make(env_id)
    counts = {"success": 0, "collision": 0, "timeout": 0}
    times = []
    obs, _ = env.reset(seed=EVAL_SEED)
    for episode in range(episodes):
        if episode:
            obs, _ = env.reset()
        steps, done = 0, False
        while not done:
            obs, _, terminated, truncated, info = env.step(policy(obs))
            steps += info["steps"]
            done = terminated or truncated
        counts[info["outcome"]] += 1
        if info["outcome"] == "success":
            times.append(steps * STEP_S)
    env.close()
    return Results(
        name,
        episodes,
        counts["success"] / episodes,
        counts["collision"] / episodes,
        counts["timeout"] / episodes,
        float(np.mean(times)) if times else None,
    )


def train(env_id: str, timesteps: int, seed: int, **overrides: Any) -> DQN:
    """DQN trained for ``timesteps`` decisions (over all environments)."""
    settings = {**HYPERPARAMETERS, **overrides}
    n_envs = settings.pop("n_envs", N_ENVS)
    if seed + n_envs > EVAL_SEED:
        raise ValueError(f"training seeds {seed}..{seed + n_envs - 1} reach the held-out seed")
    envs = CrossroadsVecEnv(n_envs, env_id=env_id)
    envs.seed(seed)
    model = DQN("MlpPolicy", envs, seed=seed, device="cpu", verbose=0, **settings)
    model.learn(total_timesteps=timesteps)
    return model


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env-id", default="crossroads/Right-TTG-v0")
    parser.add_argument("--timesteps", type=int, default=50_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path("runs/sb3-dqn"))
    parser.add_argument("--eval-episodes", type=int, default=1000)
    parser.add_argument("--json", type=pathlib.Path, help="also write the results here")
    args = parser.parse_args()

    # One core: the figures in the report are for one.
    torch.set_num_threads(1)
    start = time.perf_counter()
    model = train(args.env_id, args.timesteps, args.seed)
    train_s = time.perf_counter() - start
    args.out.mkdir(parents=True, exist_ok=True)
    model.save(args.out / "model.zip")
    print(f"trained {args.timesteps} timesteps in {train_s:.0f} s; saved {args.out / 'model.zip'}")

    rng = np.random.default_rng(args.seed)
    n_actions = gym.make(args.env_id).action_space.n
    policies: dict[str, Callable[[np.ndarray], int]] = {
        "dqn": lambda obs: int(model.predict(obs, deterministic=True)[0]),
        "random": lambda obs: int(rng.integers(n_actions)),
        "go-at-once": lambda obs: 0,  # TTG's action 0 is go
    }
    print(f"{args.eval_episodes} episodes from reset(seed={EVAL_SEED}):")
    results = []
    for name, policy in policies.items():
        r = evaluate(args.env_id, name, policy, args.eval_episodes)
        print(r.line())
        results.append(r)
    if args.json is not None:
        args.json.write_text(
            json.dumps(
                {
                    "env_id": args.env_id,
                    "timesteps": args.timesteps,
                    "seed": args.seed,
                    "eval_seed": EVAL_SEED,
                    "train_s": train_s,
                    "results": [asdict(r) for r in results],
                },
                indent=2,
            )
        )


if __name__ == "__main__":
    main()
