"""DQN in one file, in CleanRL's manner (arguments in a dataclass, the whole
algorithm in one loop), on a crossroads environment.

    python python/examples/cleanrl_dqn.py [--env-id crossroads/Right-TTG-v0]
        [--total-timesteps 20000] [--seed 1] [--eval-episodes 1000]

Gymnasium 0.29.1 or 1.x and torch; nothing else. One environment, stepped
by hand, so that the two Gymnasium versions' vector autoresets never
differ. A decision may last several simulator steps (a semi-MDP), so the
target bootstraps with ``info["discount"]`` (``gamma ** steps``) in
place of a fixed gamma. After training it plays the held-out episodes
0 to n - 1 after ``reset(seed=1000000000)`` greedily and prints its
success, collision and timeout rates and mean time.
"""

from __future__ import annotations

import argparse
import dataclasses
import random
import time
from dataclasses import dataclass

import gymnasium as gym
import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F

import crossroads  # noqa: F401  (registers the ids)

#: The held-out episodes' reset seed (the SB3 example's too).
EVAL_SEED = 1_000_000_000


@dataclass
class Args:
    env_id: str = "crossroads/Right-TTG-v0"
    """a crossroads id with discrete actions"""
    seed: int = 1
    """seeds Python, numpy, torch and the training episodes"""
    total_timesteps: int = 20_000
    """decisions taken while training"""
    learning_rate: float = 5e-4
    """Adam's step size"""
    buffer_size: int = 50_000
    """transitions the replay buffer keeps"""
    gamma: float = 0.99
    """discount per 0.2 s simulator step"""
    target_network_frequency: int = 500
    """decisions between copies of the online network into the target"""
    batch_size: int = 64
    """transitions per update"""
    start_e: float = 1.0
    """epsilon at the start"""
    end_e: float = 0.02
    """epsilon at the end of the schedule"""
    exploration_fraction: float = 0.3
    """fraction of total_timesteps over which epsilon falls linearly"""
    learning_starts: int = 1_000
    """decisions before the first update"""
    train_frequency: int = 1
    """decisions between updates"""
    hidden: int = 128
    """units in each of the two hidden layers"""
    eval_episodes: int = 1_000
    """held-out episodes played after training"""


def parse_args() -> Args:
    """Args' fields as --kebab-case flags."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    for field in dataclasses.fields(Args):
        parser.add_argument(
            "--" + field.name.replace("_", "-"),
            type=type(field.default),
            default=field.default,
        )
    return Args(**vars(parser.parse_args()))


class QNetwork(nn.Module):
    """An MLP from the flat observation to one value per action."""

    def __init__(self, obs_size: int, n_actions: int, hidden: int) -> None:
        super().__init__()
        self.layers = nn.Sequential(
            nn.Linear(obs_size, hidden),
            nn.ReLU(),
            nn.Linear(hidden, hidden),
            nn.ReLU(),
            nn.Linear(hidden, n_actions),
        )

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.layers(obs)


class ReplayBuffer:
    """A ring of transitions in preallocated arrays, sampled uniformly."""

    def __init__(self, capacity: int, obs_size: int, rng: np.random.Generator) -> None:
        self.obs = np.zeros((capacity, obs_size), dtype=np.float32)
        self.next_obs = np.zeros((capacity, obs_size), dtype=np.float32)
        self.actions = np.zeros(capacity, dtype=np.int64)
        self.rewards = np.zeros(capacity, dtype=np.float32)
        # gamma ** steps, and 0 where the episode terminated: the factor
        # of the bootstrapped value in the target.
        self.discounts = np.zeros(capacity, dtype=np.float32)
        self.capacity, self.size, self.next = capacity, 0, 0
        self.rng = rng

    def add(self, obs, action, reward, next_obs, discount) -> None:
        i = self.next
        self.obs[i], self.actions[i], self.rewards[i] = obs, action, reward
        self.next_obs[i], self.discounts[i] = next_obs, discount
        self.next = (i + 1) % self.capacity
        self.size = min(self.size + 1, self.capacity)

    def sample(self, n: int) -> tuple[torch.Tensor, ...]:
        idx = self.rng.integers(0, self.size, n)
        return tuple(
            torch.from_numpy(a[idx])
            for a in (self.obs, self.actions, self.rewards, self.next_obs, self.discounts)
        )


def epsilon(args: Args, t: int) -> float:
    """Linear from start_e to end_e over exploration_fraction of the run."""
    span = args.exploration_fraction * args.total_timesteps
    return max(args.end_e, args.start_e + (args.end_e - args.start_e) * t / span)


def evaluate(args: Args, q_network: QNetwork) -> None:
    """Greedy play of the held-out episodes."""
    env = gym.make(args.env_id, gamma=args.gamma)
    outcomes = {"success": 0, "collision": 0, "timeout": 0}
    times = []
    obs, _ = env.reset(seed=EVAL_SEED)
    for episode in range(args.eval_episodes):
        if episode:
            obs, _ = env.reset()
        steps, done = 0, False
        while not done:
            with torch.no_grad():
                action = int(q_network(torch.from_numpy(obs)).argmax())
            obs, _, terminated, truncated, info = env.step(action)
            steps += info["steps"]
            done = terminated or truncated
        outcomes[info["outcome"]] += 1
        if info["outcome"] == "success":
            times.append(0.2 * steps)
    n = args.eval_episodes
    mean_time = f"{np.mean(times):.2f} s" if times else "-"
    print(
        f"eval: {n} episodes from reset(seed={EVAL_SEED}): "
        f"success {100 * outcomes['success'] / n:.2f} %, "
        f"collision {100 * outcomes['collision'] / n:.2f} %, "
        f"timeout {100 * outcomes['timeout'] / n:.2f} %, mean time {mean_time}"
    )


def main() -> None:
    args = parse_args()
    print(args)
    random.seed(args.seed)
    np.random.seed(args.seed)
    torch.manual_seed(args.seed)
    torch.set_num_threads(1)
    if args.seed >= EVAL_SEED:
        raise SystemExit(f"--seed {args.seed} would train on the held-out episodes")

    env = gym.make(args.env_id, gamma=args.gamma)
    assert isinstance(env.action_space, gym.spaces.Discrete), "DQN needs discrete actions"
    obs_size = int(np.prod(env.observation_space.shape))
    n_actions = int(env.action_space.n)
    env.action_space.seed(args.seed)

    q_network = QNetwork(obs_size, n_actions, args.hidden)
    target_network = QNetwork(obs_size, n_actions, args.hidden)
    target_network.load_state_dict(q_network.state_dict())
    optimizer = torch.optim.Adam(q_network.parameters(), lr=args.learning_rate)
    buffer = ReplayBuffer(args.buffer_size, obs_size, np.random.default_rng(args.seed))

    start = time.perf_counter()
    obs, _ = env.reset(seed=args.seed)
    episodes, successes, collisions = 0, 0, 0
    for t in range(args.total_timesteps):
        # Act: epsilon-greedy.
        if random.random() < epsilon(args, t):
            action = int(env.action_space.sample())
        else:
            with torch.no_grad():
                action = int(q_network(torch.from_numpy(obs)).argmax())
        next_obs, reward, terminated, truncated, info = env.step(action)

        # Store: a timeout still bootstraps, an ending does not.
        discount = 0.0 if terminated else info["discount"]
        buffer.add(obs, action, reward, next_obs, discount)
        obs = next_obs
        if terminated or truncated:
            episodes += 1
            successes += info["outcome"] == "success"
            collisions += info["outcome"] == "collision"
            if episodes % 500 == 0:
                print(
                    f"t={t + 1} episodes={episodes} epsilon={epsilon(args, t):.3f} "
                    f"last 500: success {successes / 5:.1f} %, collision {collisions / 5:.1f} % "
                    f"({time.perf_counter() - start:.0f} s)"
                )
                successes, collisions = 0, 0
            obs, _ = env.reset()

        if t < args.learning_starts or t % args.train_frequency:
            continue
        # Learn: the target under no_grad, then one step on the TD loss.
        s, a, r, s2, d = buffer.sample(args.batch_size)
        with torch.no_grad():
            target = r + d * target_network(s2).max(dim=1).values
        q = q_network(s).gather(1, a.unsqueeze(1)).squeeze(1)
        loss = F.smooth_l1_loss(q, target)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        if t % args.target_network_frequency == 0:
            target_network.load_state_dict(q_network.state_dict())

    print(f"trained {args.total_timesteps} decisions in {time.perf_counter() - start:.0f} s")
    env.close()
    evaluate(args, q_network)


if __name__ == "__main__":
    main()
