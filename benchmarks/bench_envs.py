"""Steps per second of the CSIRL tasks: stock highway-env / raw gymnasium-robotics vs ours.

For every scenario both variants run the same scene config, the same seeds and the same
random actions (uniform in [-1, 1]^2; episodes reset when done, resets included in the time):

* ``stock``: ``fast=False`` -- highway-env's pandas Kinematics observation and its
  deep-copying trajectory prediction (intersection traffic rules);
* ``ours``: the default -- :class:`~torchrl_csirl.tasks.driving._observation.FastKinematicObservation`,
  copy-free ego prediction and once-per-pass predictions in the intersection.

The two produce identical observations and trajectories (see tests/test_envs.py), so the
ratio is a pure speed-up. Variants are interleaved in short rounds to share machine noise.

For the robotics tasks (``antmaze-umaze``, ``relocate``) the comparison is

* ``raw``: ``gym.make`` of the gymnasium-robotics id with the same options (``AntMaze_UMaze-v5``
  with the U-maze map, ``continuing_task=False``, no contact forces, our +-0.1 m start/goal noise;
  ``AdroitHandRelocate-v1``),
  with gymnasium's default wrappers (checker, order enforcing, time limit);
* ``ours``: :func:`~torchrl_csirl.tasks.make_gym_env` (flat observation, step limit and the
  CSIRL info entries: route length, progress, success).

Usage::

    python benchmarks/bench_envs.py [--steps 600] [--rounds 3] [--scenarios merge relocate]

The last line printed is a JSON object mapping each driving scenario to
``{"stock_steps_per_s": ..., "ours_steps_per_s": ..., "speedup": ...}`` and each robotics task to
``{"raw_steps_per_s": ..., "ours_steps_per_s": ..., "ratio": ...}`` (ours / raw).
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np
import torch

from torchrl_csirl.tasks import SCENARIOS, make_gym_env
from torchrl_csirl.tasks.robotics import ANTMAZE_UMAZE_MAP, ROBOTICS_TASKS
from torchrl_csirl.tasks.robotics.tasks import ANTMAZE_POSITION_NOISE, _remove_maze_xml


def run_steps(env, n_steps: int, seed: int) -> float:
    """Run ``n_steps`` random-action steps (resetting on done); return elapsed seconds."""
    rng = np.random.default_rng(seed)
    actions = rng.uniform(-1.0, 1.0, size=(n_steps, *env.action_space.shape)).astype(np.float32)
    episode = 0
    start = time.perf_counter()
    env.reset(seed=seed)
    for t in range(n_steps):
        _, _, terminated, truncated, _ = env.step(actions[t])
        if terminated or truncated:
            episode += 1
            env.reset(seed=seed + episode)
    return time.perf_counter() - start


def interleaved_steps_per_s(envs: dict, n_steps: int, rounds: int, seed: int = 0) -> dict[str, float]:
    """Steps per second of each env, run in interleaved rounds (after a short warm-up)."""
    elapsed = {k: 0.0 for k in envs}
    for env in envs.values():
        run_steps(env, 20, seed)  # warm-up (imports, caches)
    names = list(envs)
    for r in range(rounds):
        for k in names if r % 2 == 0 else names[::-1]:
            elapsed[k] += run_steps(envs[k], n_steps, seed + 1000 * r)
    return {k: n_steps * rounds / elapsed[k] for k in envs}


def raw_robotics_env(name: str):
    """The gymnasium-robotics environment our robotics task wraps, made the plain gymnasium way."""
    import gymnasium as gym
    import gymnasium_robotics

    gym.register_envs(gymnasium_robotics)
    spec = ROBOTICS_TASKS[name]
    if name == "antmaze-umaze":
        maze_map = [list(row) for row in ANTMAZE_UMAZE_MAP]
        env = gym.make(spec.base_env, maze_map=maze_map, continuing_task=False, include_cfrc_ext_in_observation=False)
        env.unwrapped.position_noise_range = ANTMAZE_POSITION_NOISE  # ours: D4RL's small start/goal noise
        _remove_maze_xml(env.unwrapped)
        return env
    return gym.make(spec.base_env)


def bench(name: str, n_steps: int, rounds: int, seed: int = 0) -> dict:
    if name in ROBOTICS_TASKS:
        sps = interleaved_steps_per_s({"raw": raw_robotics_env(name), "ours": make_gym_env(name)}, n_steps, rounds, seed)
        return {
            "raw_steps_per_s": round(sps["raw"], 1),
            "ours_steps_per_s": round(sps["ours"], 1),
            "ratio": round(sps["ours"] / sps["raw"], 2),
        }
    sps = interleaved_steps_per_s({"stock": make_gym_env(name, fast=False), "ours": make_gym_env(name)}, n_steps, rounds, seed)
    return {
        "stock_steps_per_s": round(sps["stock"], 1),
        "ours_steps_per_s": round(sps["ours"], 1),
        "speedup": round(sps["ours"] / sps["stock"], 2),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=600, help="steps per round and variant")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--scenarios", nargs="*", default=[*SCENARIOS, *ROBOTICS_TASKS])
    args = parser.parse_args()
    torch.set_num_threads(2)
    results = {}
    for name in args.scenarios:
        results[name] = bench(name, args.steps, args.rounds)
        print(name, results[name], flush=True)
    print(json.dumps(results))


if __name__ == "__main__":
    main()
