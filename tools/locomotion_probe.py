"""Where does a locomotion policy go? The torso's x over deterministic test episodes, the return, and whether it flipped.

``python tools/locomotion_probe.py <run dir> [--episodes 1] [--seed S] [--stochastic]``

Reads a run on ``hopper`` or ``halfcheetah``: its ``policy.pt`` (a finished run) or, before the end, the actor of
its last checkpoint. For each episode (seeds ``S, S + 1, ...``; default the run's ``eval.seed``, its test
episodes) it prints the torso's x every 100 steps, the return, the length and the torso angle's range (beyond
pi / 2 the body is on its back). The actions are the policy's mean (the test's), or with ``--stochastic``
its samples (the behaviour that collected the training data). The last line is JSON. It tells a policy that runs from one that moves a few
metres and stops (docs/benchmark.md, MuJoCo locomotion).
"""
from __future__ import annotations

import argparse
import json
import math
import os

import torch
from omegaconf import OmegaConf
from torchrl.envs.utils import ExplorationType, set_exploration_type

from torchrl_csirl.envs import make_env, resolve_scenario
from torchrl_csirl.modules import load_policy, make_actor, make_input_features

ACTOR_PREFIXES = ("actor_network_params.", "actor_network.")


def load_actor(run_dir: str, task: str) -> torch.nn.Module:
    """The run's policy: ``policy.pt``, else the actor in its last checkpoint's ``loss`` state."""
    if os.path.isfile(os.path.join(run_dir, "policy.pt")):
        return load_policy(run_dir)
    path = os.path.join(run_dir, "checkpoints", "last", "state.pt")
    if not os.path.isfile(path):
        raise SystemExit(f"error: {run_dir}: neither policy.pt nor checkpoints/last/state.pt")
    state = torch.load(path, weights_only=False)["states"].get("loss", {})
    for prefix in ACTOR_PREFIXES:
        weights = {k[len(prefix):]: v for k, v in state.items() if k.startswith(prefix)}
        if weights:
            break
    else:
        raise SystemExit(f"error: {path}: no actor in its loss state; probe the finished run (policy.pt)")
    spec = resolve_scenario(task)
    actor = make_actor(spec.obs_dim, spec.action_dim, input_features=make_input_features(spec, ego_relative=False))
    actor.load_state_dict(weights)
    return actor


def probe(run_dir: str, episodes: int = 1, seed: int | None = None, stochastic: bool = False) -> dict:
    cfg = OmegaConf.load(os.path.join(run_dir, "config.yaml"))
    task = cfg.env.scenario
    spec = resolve_scenario(task)
    if "x" not in spec.observation_layout:
        raise SystemExit(f"error: {task} has no torso x (a locomotion task: hopper, halfcheetah)")
    actor = load_actor(run_dir, task)
    seed = int(cfg.eval.seed if seed is None else seed)
    x_at, angle_at = spec.observation_layout["x"][0], spec.observation_layout["angle"][0]
    out = []
    for i in range(episodes):
        env = make_env(task, seed=seed + i)
        mode = ExplorationType.RANDOM if stochastic else ExplorationType.DETERMINISTIC
        with torch.no_grad(), set_exploration_type(mode):
            rollout = env.rollout(spec.max_steps, actor, break_when_any_done=True)
        env.close()
        obs = rollout["next", "observation"]
        x = [round(float(v), 1) for v in obs[::100, x_at]] + [round(float(obs[-1, x_at]), 1)]
        angle = obs[:, angle_at]
        out.append({"seed": seed + i, "return": round(float(rollout["next", "reward"].sum()), 1),
                    "length": int(rollout.shape[-1]), "x_every_100": x,
                    "angle_range": [round(float(angle.min()), 2), round(float(angle.max()), 2)],
                    "on_its_back": bool(angle.abs().max() > math.pi / 2)})
        print(f"seed {seed + i}: return {out[-1]['return']}, {out[-1]['length']} steps, x {x}, "
              f"angle {out[-1]['angle_range']}")
    return {"run_dir": run_dir, "task": task, "actions": "sampled" if stochastic else "mean", "episodes": out}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dir")
    parser.add_argument("--episodes", type=int, default=1)
    parser.add_argument("--seed", type=int, default=None, help="first episode's seed (default: the run's eval.seed)")
    parser.add_argument("--stochastic", action="store_true", help="sample the actions (default: the policy's mean)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    print(json.dumps(probe(os.path.abspath(args.run_dir), args.episodes, args.seed, args.stochastic)))


if __name__ == "__main__":
    main()
