"""Steps per second of the CSIRL scenarios: stock highway-env code paths vs ours.

For every scenario both variants run the same scene config, the same seeds and the same
random actions (uniform in [-1, 1]^2; episodes reset when done, resets included in the time):

* ``stock``: ``fast=False`` -- highway-env's pandas Kinematics observation and its
  deep-copying trajectory prediction (intersection traffic rules);
* ``ours``: the default -- :class:`~torchrl_csirl.envs._observation.FastKinematicObservation`,
  copy-free ego prediction and once-per-pass predictions in the intersection.

The two produce identical observations and trajectories (see tests/test_envs.py), so the
ratio is a pure speed-up. Variants are interleaved in short rounds to share machine noise.

Usage::

    python benchmarks/bench_envs.py [--steps 600] [--rounds 3] [--scenarios merge intersection]

The last line printed is a JSON object mapping each scenario to
``{"stock_steps_per_s": ..., "ours_steps_per_s": ..., "speedup": ...}``.
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np
import torch

from torchrl_csirl.envs import SCENARIOS, make_gym_env


def run_steps(env, n_steps: int, seed: int) -> float:
    """Run ``n_steps`` random-action steps (resetting on done); return elapsed seconds."""
    rng = np.random.default_rng(seed)
    actions = rng.uniform(-1.0, 1.0, size=(n_steps, 2)).astype(np.float32)
    episode = 0
    start = time.perf_counter()
    env.reset(seed=seed)
    for t in range(n_steps):
        _, _, terminated, truncated, _ = env.step(actions[t])
        if terminated or truncated:
            episode += 1
            env.reset(seed=seed + episode)
    return time.perf_counter() - start


def bench(name: str, n_steps: int, rounds: int, seed: int = 0) -> dict:
    envs = {"stock": make_gym_env(name, fast=False), "ours": make_gym_env(name)}
    elapsed = {k: 0.0 for k in envs}
    run_steps(envs["stock"], 20, seed)  # warm-up (imports, caches)
    run_steps(envs["ours"], 20, seed)
    for r in range(rounds):
        order = ("stock", "ours") if r % 2 == 0 else ("ours", "stock")
        for k in order:
            elapsed[k] += run_steps(envs[k], n_steps, seed + 1000 * r)
    total = n_steps * rounds
    stock, ours = total / elapsed["stock"], total / elapsed["ours"]
    return {
        "stock_steps_per_s": round(stock, 1),
        "ours_steps_per_s": round(ours, 1),
        "speedup": round(ours / stock, 2),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=600, help="steps per round and variant")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--scenarios", nargs="*", default=list(SCENARIOS))
    args = parser.parse_args()
    torch.set_num_threads(2)
    results = {}
    for name in args.scenarios:
        results[name] = bench(name, args.steps, args.rounds)
        print(name, results[name], flush=True)
    print(json.dumps(results))


if __name__ == "__main__":
    main()
