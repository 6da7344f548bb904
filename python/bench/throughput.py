"""Decisions per second of random actions on Right with TTG actions: one
environment, and 64 in the native vector environment on one thread (and
highway-env's intersection-v1 when it is installed).

    python python/bench/throughput.py [--seconds 3]

A decision is one action applied (several simulator steps for a wait or a
go); resets are inside the timing. Prints one line per measurement.
"""

from __future__ import annotations

import argparse
import platform
import time

import gymnasium as gym
import numpy as np

import crossroads


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def single(env: gym.Env, seconds: float) -> float:
    """Decisions per second; highway-env's continuous actions are sampled
    in the loop (its time dwarfs the sampling)."""
    if isinstance(env.action_space, gym.spaces.Discrete):
        actions = np.random.default_rng(0).integers(0, env.action_space.n, 1 << 16).tolist()
    else:
        actions = [env.action_space.sample() for _ in range(1 << 16)]
    mask = len(actions) - 1
    env.reset(seed=0)
    n, start = 0, time.perf_counter()
    while True:
        for _ in range(1024):
            _, _, term, trunc, _ = env.step(actions[n & mask])
            n += 1
            if term or trunc:
                env.reset()
        elapsed = time.perf_counter() - start
        if elapsed >= seconds:
            return n / elapsed


def vector(envs, seconds: float) -> float:
    """Decisions per second: environments that stepped (not those that
    only reset, in next-step mode)."""
    rng = np.random.default_rng(0)
    actions = rng.integers(0, envs.single_action_space.n, (256, envs.num_envs))
    envs.reset(seed=0)
    n, k, start = 0, 0, time.perf_counter()
    while True:
        for _ in range(64):
            _, _, _, _, info = envs.step(actions[k % len(actions)])
            k += 1
            # Those that stepped: their step infos, or in same-step mode
            # for an episode that ended, its final info.
            for mask in ("_steps", "_final_info"):
                if mask in info:
                    n += int(np.count_nonzero(info[mask]))
        elapsed = time.perf_counter() - start
        if elapsed >= seconds:
            return n / elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--envs", type=int, default=64)
    args = parser.parse_args()
    print(f"cpu: {cpu_model()}; python {platform.python_version()}; gymnasium {gym.__version__}")

    sim = crossroads._native.bench_simulator("right", args.seconds / 2)
    print(f"simulator alone (Rust, crossroads bench sim) {sim:12,.0f} decisions/s")
    raw = crossroads.CrossroadsEnv(scenario="right", actions="ttg")
    print(f"single env (CrossroadsEnv)           {single(raw, args.seconds):12,.0f} decisions/s")
    made = gym.make("crossroads/Right-TTG-v0")
    print(f"single env (gym.make, its wrappers)  {single(made, args.seconds):12,.0f} decisions/s")
    for mode in ("next-step", "same-step"):
        envs = crossroads.CrossroadsVectorEnv(
            args.envs, scenario="right", actions="ttg", threads=1, autoreset_mode=mode
        )
        rate = vector(envs, args.seconds)
        print(f"vector env, {args.envs} envs, 1 thread, {mode}  {rate:12,.0f} decisions/s")
    try:
        import highway_env  # noqa: F401
    except ImportError:
        print("highway-env: not installed")
        return
    hw = gym.make("intersection-v1")
    print(f"highway-env intersection-v1          {single(hw, args.seconds):12,.0f} decisions/s")


if __name__ == "__main__":
    main()
