"""How a driving policy's test episodes end, and how fast it drives: any scenario (``torchrl-csirl outcomes``).

``torchrl-csirl outcomes <run dir or policy.pt> [--episodes 50] [--seed 1000000]``

Rolls out the saved deterministic policy on the recipe's test episodes (seeds
``seed .. seed + episodes - 1``, as the final evaluation does) and reports, per group of
episodes, the accomplish rate, the outcomes (success, crash, off-road, time-out), the ego's mean
and largest speed, the speed and the step at which crashed episodes ended, and the mean
accomplish rate of the crashed and of the off-road episodes (an accomplish rate earned by driving
far and then crashing is not expert-like), and where the off-road episodes left the road: the lane
they were last on, the ego's position and its lateral offset from that lane's centre line (the
summary: the mean absolute offset; a lane is half its width on either side of that line). On merge
the episodes are also split by the traffic ahead at reset:
two main-road vehicles ahead of the ego slow to 20 m/s; when they share a lane the other one is
**free**, when they do not both lanes are **blocked** and finishing means squeezing past them (the
expert nudges, docs/experts.md). The last line is JSON.

Examples:
    >>> summarize_group([{"outcome": "crash", "accomplish_rate": 0.5, "mean_speed": 25.0, "max_speed": 30.0,
    ...                   "final_speed": 28.0, "steps": 40}])["crash_step"]
    40.0
"""
from __future__ import annotations

import json
import os
import sys
from collections import Counter, defaultdict

import torch
from torchrl.envs import EnvBase

from torchrl_csirl.scripts._policy_rollouts import format_cell, load_test_policy, mean_or_none, roll_test_episodes
from torchrl_csirl.tasks import SCENARIOS, ScenarioSpec, accomplish_rate_from_rollout, gym_env_of, success_from_rollout

__all__ = ["OUTCOMES", "classify_episodes", "main", "report", "summarize"]

OUTCOMES = ("success", "crash", "offroad", "timeout")


def traffic_ahead(env: EnvBase) -> str:
    """Merge: ``"free"`` or ``"blocked"``, the lanes of the two main-road vehicles ahead of the ego (after a reset)."""
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


def ego_speeds(observations: torch.Tensor, spec: ScenarioSpec) -> torch.Tensor:
    """The ego's speed [m/s] at each step, from the normalised ``vx``, ``vy`` of its observation row."""
    speeds = []
    for name in ("vx", "vy"):
        lo, hi = spec.features_range[name]
        value = observations[..., spec.features.index(name)]  # the ego row comes first
        speeds.append(lo + (value + 1.0) * (hi - lo) / 2.0)
    return torch.stack(speeds, -1).norm(dim=-1)


def road_position(env: EnvBase) -> dict[str, object]:
    """Where the ego is on the road: ``lane`` (highway-env's lane index, as text), ``position`` [m] and
    ``lateral`` [m], its offset from that lane's centre line (off the road beyond half the lane width)."""
    vehicle = gym_env_of(env).unwrapped.vehicle
    lane = vehicle.road.network.get_lane(vehicle.lane_index)
    _, lateral = lane.local_coordinates(vehicle.position)
    return {"lane": "/".join(str(part) for part in vehicle.lane_index), "position": [round(float(v), 2) for v in vehicle.position],
            "lateral": float(lateral), "half_width": float(lane.width_at(0)) / 2}


def classify_episodes(policy, scenario: str, episodes: int, seed: int) -> list[dict]:
    """One record per test episode: ``group``, ``outcome``, ``accomplish_rate``, ``steps``, speeds; an off-road
    one also its :func:`road_position` at the end (``offroad_at``)."""
    spec = SCENARIOS[scenario]
    grouping = traffic_ahead if scenario == "merge" else None
    records = []
    for i, (env, rollout, group) in enumerate(roll_test_episodes(policy, scenario, episodes, seed, spec.max_steps,
                                                                 at_reset=grouping)):
        speeds = ego_speeds(rollout["next", "observation"], spec)
        records.append({"episode": i, "group": group or "all", "outcome": outcome(rollout),
                        "accomplish_rate": float(accomplish_rate_from_rollout(rollout)),
                        "steps": rollout.shape[-1], "mean_speed": float(speeds.mean()),
                        "max_speed": float(speeds.max()), "final_speed": float(speeds[-1])})
        if records[-1]["outcome"] == "offroad":
            records[-1]["offroad_at"] = road_position(env)
    return records


def summarize_group(group: list[dict]) -> dict[str, object]:
    """Episodes, mean accomplish rate, outcome counts, speeds, and what the crashed episodes had reached."""
    counts = Counter(r["outcome"] for r in group)
    crashed = [r for r in group if r["outcome"] == "crash"]
    offroad = [r for r in group if r["outcome"] == "offroad"]
    return {
        "episodes": len(group),
        "accomplish_rate": mean_or_none([r["accomplish_rate"] for r in group]),
        **{o: counts.get(o, 0) for o in OUTCOMES},
        "mean_speed": mean_or_none([r["mean_speed"] for r in group]),
        "max_speed": max((r["max_speed"] for r in group), default=None),
        "crash_speed": mean_or_none([r["final_speed"] for r in crashed]),
        "crash_step": mean_or_none([float(r["steps"]) for r in crashed]),
        "crash_accomplish_rate": mean_or_none([r["accomplish_rate"] for r in crashed]),
        "offroad_accomplish_rate": mean_or_none([r["accomplish_rate"] for r in offroad]),
        "offroad_lanes": dict(Counter(r["offroad_at"]["lane"] for r in offroad).most_common()),
        "offroad_lateral": mean_or_none([abs(r["offroad_at"]["lateral"]) for r in offroad]),
    }


def summarize(records: list[dict]) -> dict[str, dict]:
    """:func:`summarize_group` per group (merge: ``free``, ``blocked``) and over ``all`` episodes."""
    groups: dict[str, list[dict]] = defaultdict(list)
    for record in records:
        if record["group"] != "all":
            groups[record["group"]].append(record)
    groups["all"] = list(records)
    return {name: summarize_group(group) for name, group in groups.items()}


def _lanes(counts: dict[str, int]) -> str:
    return " ".join(f"{lane} ({n})" for lane, n in counts.items()) or "-"


def print_table(stats: dict[str, dict]) -> None:
    """The groups as a Markdown table on stderr."""
    print("| episodes | n | accomplish (raw) | success | crash | off-road | time-out | mean / max speed [m/s] "
          "| at a crash: speed, step, accomplish | off-road: accomplish, abs. lateral offset [m], lanes |", file=sys.stderr)
    print("|---|---|---|---|---|---|---|---|---|---|", file=sys.stderr)
    for name, s in stats.items():
        crash = ", ".join(format_cell(s[key], fmt) for key, fmt in
                          (("crash_speed", ".1f"), ("crash_step", ".0f"), ("crash_accomplish_rate", ".2f")))
        print(f"| {name} | {s['episodes']} | {format_cell(s['accomplish_rate'], '.3f')} | {s['success']} | {s['crash']} "
              f"| {s['offroad']} | {s['timeout']} | {format_cell(s['mean_speed'], '.1f')} / {format_cell(s['max_speed'], '.1f')} "
              f"| {crash} | {format_cell(s['offroad_accomplish_rate'], '.2f')}, {format_cell(s['offroad_lateral'], '.1f')}, "
              f"{_lanes(s['offroad_lanes'])} |", file=sys.stderr)


def report(args, policy, scenario: str) -> dict[str, dict]:
    """Rolls ``policy`` on ``scenario``'s test episodes (``args.episodes`` from ``args.seed``), prints the table
    (stderr) and the JSON line; returns the groups' statistics."""
    stats = summarize(classify_episodes(policy, scenario, args.episodes, args.seed))
    print_table(stats)
    print(json.dumps({"policy": os.path.abspath(args.policy), "scenario": scenario, **stats}))
    return stats


def main(argv: list[str] | None = None) -> dict[str, dict]:
    """``torchrl-csirl outcomes`` for a driving policy alone (``argv``: the command line); returns :func:`report`'s."""
    return report(*load_test_policy(__doc__.splitlines()[0], argv, SCENARIOS, "driving scenarios",
                                    prog="torchrl-csirl outcomes"))


if __name__ == "__main__":
    main()
