"""Where a merge policy fails: test episodes split by the traffic ahead, with their outcomes.

``python recipes/merge_outcomes.py <run dir or policy.pt> [--episodes 50] [--seed 1000000]``

Merge places two vehicles ahead of the ego (at about 70 m and 90 m, each in a random lane) that
slow down to 20 m/s. When they share a lane the other lane is **free**; when they are in
different lanes both lanes are **blocked**, and finishing means squeezing past them (the expert
nudges, docs/EXPERTS.md). This script rolls out the saved deterministic policy on the recipe's
test episodes (seeds ``seed .. seed + episodes - 1``, as the final evaluation), classifies each
episode by the lanes of those two vehicles at reset, and reports per class the accomplish rate
and the outcomes (success, crash, off-road, time-out). The last line is JSON.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from collections import Counter, defaultdict

import torch
from torchrl.envs import EnvBase, ExplorationType, set_exploration_type

from torchrl_csirl._compat import gym_env_of
from torchrl_csirl.envs import accomplish_rate_from_rollout, make_env, success_from_rollout
from torchrl_csirl.modules import load_policy

OUTCOMES = ("success", "crash", "offroad", "timeout")


def traffic_ahead(env: EnvBase) -> str:
    """``"free"`` or ``"blocked"``: the lanes of the two main-road vehicles ahead of the ego (after a reset)."""
    road = gym_env_of(env).unwrapped.road
    ego = road.vehicles[0]
    ahead = sorted((v for v in road.vehicles[1:] if v.lane_index[0] == "a" and v.position[0] > ego.position[0]),
                   key=lambda v: v.position[0])[:2]
    return "blocked" if len({v.lane_index[2] for v in ahead}) > 1 else "free"


def outcome(rollout) -> str:
    """How an episode ended: success (as the recipe's evaluation counts it), crash, off-road or time-out."""
    if bool(success_from_rollout(rollout)):
        return "success"
    for name, key in (("crash", "crashed"), ("offroad", "offroad")):
        if bool(rollout["next", key].any()):
            return name
    return "timeout"


def classify_episodes(policy, episodes: int, seed: int, max_steps: int = 60) -> list[dict]:
    """One record per test episode: ``traffic``, ``outcome``, ``accomplish_rate``, ``steps``."""
    env = make_env("merge")
    records = []
    try:
        with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
            for i in range(episodes):
                env.set_seed(seed + i)  # the reset below is the one of evaluate_policy's rollout
                start = env.reset()
                traffic = traffic_ahead(env)
                rollout = env.rollout(max_steps, policy, auto_reset=False, tensordict=start, break_when_any_done=True)
                records.append({"episode": i, "traffic": traffic, "outcome": outcome(rollout),
                                "accomplish_rate": float(accomplish_rate_from_rollout(rollout)),
                                "steps": rollout.shape[-1]})
    finally:
        env.close()
    return records


def summarize(records: list[dict]) -> dict[str, dict]:
    """Per traffic class (and ``all``): episodes, mean accomplish rate, outcome counts."""
    groups: dict[str, list[dict]] = defaultdict(list)
    for record in records:
        groups[record["traffic"]].append(record)
        groups["all"].append(record)
    out = {}
    for name in ("free", "blocked", "all"):
        group = groups.get(name, [])
        counts = Counter(r["outcome"] for r in group)
        out[name] = {
            "episodes": len(group),
            "accomplish_rate": sum(r["accomplish_rate"] for r in group) / len(group) if group else None,
            **{o: counts.get(o, 0) for o in OUTCOMES},
        }
    return out


def main(argv: list[str] | None = None) -> dict[str, dict]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("policy", help="a run directory or its policy.pt")
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--seed", type=int, default=1_000_000, help="seed of the first episode (the recipe's eval.seed)")
    args = parser.parse_args(argv)
    if args.episodes <= 0:
        parser.error(f"--episodes must be positive, got {args.episodes}")
    policy = load_policy(args.policy)
    scenario = policy.metadata.get("scenario")
    if scenario != "merge":
        parser.error(f"{args.policy}: a policy trained on {scenario!r}; this script analyses merge policies")
    torch.set_num_threads(1)
    stats = summarize(classify_episodes(policy, args.episodes, args.seed))
    print("| traffic ahead | episodes | accomplish (raw) | success | crash | off-road | time-out |", file=sys.stderr)
    print("|---|---|---|---|---|---|---|", file=sys.stderr)
    for name, s in stats.items():
        rate = "-" if s["accomplish_rate"] is None else f"{s['accomplish_rate']:.3f}"
        print(f"| {name} | {s['episodes']} | {rate} | {s['success']} | {s['crash']} | {s['offroad']} | {s['timeout']} |",
              file=sys.stderr)
    print(json.dumps({"policy": os.path.abspath(args.policy), **stats}))
    return stats


if __name__ == "__main__":
    main()
