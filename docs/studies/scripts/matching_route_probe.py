"""How CSIRL's matching reward pays the expert's own route: per target rule and subgoal, along the demonstrations.

``python docs/studies/scripts/matching_route_probe.py [--task antmaze-umaze] [--subgoals 0.1 0.25 0.5 1.0] [--rules final path]
[key=value ...]``

Builds the matching reward as a run does (the CSIRL recipe's configuration for the task with the overrides; the
first demonstration is the curriculum trajectory, as in a run) and evaluates it, with the subgoal held at each given
share of the curriculum, on every step of the other demonstrations (each walks the expert's route from its own
start). For each rule and subgoal it prints the reward summed over each quarter of a demonstration (the mean over
the demonstrations), its *opening*: the lowest point of the running sum along a demonstration (how much the route
costs before it pays; 0 when every stretch pays; the health report's ``route_opening`` at the run's subgoal), and
the discounted return from the start (``csirl.gamma``), which standing still (0) would beat when it is negative. A
route that turns away from its goal (a U-maze) shows where the straight line to the target (``final``, ``next``)
and the distance along the expert's path (``path``) part (docs/studies/outside-driving.md, AntMaze U-maze).

The last line is JSON; a Markdown table goes to stderr.
"""
from __future__ import annotations

import argparse
import json
import sys

import torch

from torchrl_csirl.analysis.diagnostics import discounted_returns, route_opening
from torchrl_csirl.methods.csirl import make_matching
from torchrl_csirl.run.builders import load_experts
from torchrl_csirl.run.recipes import load_config_for
from torchrl_csirl.tasks import resolve_scenario

RULES = ("final", "next", "path")


def route_figures(rewards: torch.Tensor, gamma: float) -> dict[str, object]:
    """One demonstration's matching rewards ``[T]``: the sum over each quarter, the opening (the running sum's
    lowest point, at most 0) and the discounted return from the first step.

    Examples:
        >>> f = route_figures(torch.tensor([-1.0, -1.0, 2.0, 2.0]), 1.0)
        >>> f["quarters"], f["opening"], f["return"]
        ([-1.0, -1.0, 2.0, 2.0], -2.0, 2.0)
    """
    rewards = rewards.double()
    quarters = [float(part.sum()) for part in torch.tensor_split(rewards, 4)]
    opening = route_opening([rewards]).figures["opening_mean"]  # the health report's figure
    return {"quarters": quarters, "opening": opening, "return": float(discounted_returns(rewards, gamma)[0])}


def probe(task: str, shares: list[float], rules: list[str], overrides: list[str]) -> list[dict[str, object]]:
    """One row per (rule, subgoal share): the mean over the demonstrations (the curriculum's own left out) of
    :func:`route_figures`, and the share of the demonstrations whose return from the start is negative."""
    rows = []
    for rule in rules:
        cfg = load_config_for("csirl")([f"env.task={task}", f"csirl.matching_target={rule}", *overrides])
        spec = resolve_scenario(cfg.env.task)
        demos = load_experts(cfg.expert, spec)
        if demos.num_trajectories < 2:
            raise SystemExit(f"error: {task}: {demos.num_trajectories} demonstration; the probe walks the others")
        curriculum = demos.trajectory_observations(0, include_final=True)
        for share in shares:
            subgoal = max(1, round(share * (len(curriculum) - 1)))
            matching = make_matching(cfg, spec, curriculum, subgoal)
            figures = [route_figures(matching(demos.trajectory(k).clone())["next", matching.out_key].reshape(-1),
                                     cfg.csirl.gamma) for k in range(1, demos.num_trajectories)]
            rows.append({
                "rule": rule, "subgoal": subgoal, "curriculum_length": len(curriculum),
                "quarters": [sum(f["quarters"][q] for f in figures) / len(figures) for q in range(4)],
                "opening": sum(f["opening"] for f in figures) / len(figures),
                "return": sum(f["return"] for f in figures) / len(figures),
                "negative_return_share": sum(f["return"] < 0 for f in figures) / len(figures),
                "demonstrations": len(figures)})
    return rows


def print_table(task: str, rows: list[dict[str, object]]) -> None:
    print(f"{task}: the matching reward along the demonstrations (mean over {rows[0]['demonstrations']})\n",
          file=sys.stderr)
    print("| rule | subgoal | 1st quarter | 2nd | 3rd | 4th | opening | return from the start | negative returns |",
          file=sys.stderr)
    print("|---|---|---|---|---|---|---|---|---|", file=sys.stderr)
    for r in rows:
        quarters = " | ".join(f"{q:.2f}" for q in r["quarters"])
        print(f"| {r['rule']} | {r['subgoal']} of {r['curriculum_length']} | {quarters} | {r['opening']:.2f} | "
              f"{r['return']:.2f} | {r['negative_return_share']:.0%} |", file=sys.stderr)


def main(argv: list[str] | None = None) -> list[dict[str, object]]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="antmaze-umaze", help="a scenario or task id (env.scenario)")
    parser.add_argument("--subgoals", type=float, nargs="+", default=[0.1, 0.25, 0.5, 1.0],
                        help="subgoals as shares of the curriculum trajectory (0-1]")
    parser.add_argument("--rules", nargs="+", default=["final", "path"], choices=RULES, help="csirl.matching_target")
    parser.add_argument("overrides", nargs="*", help="key=value overrides of the CSIRL recipe")
    args = parser.parse_args(argv)
    if not all(0.0 < s <= 1.0 for s in args.subgoals):
        parser.error(f"--subgoals must lie in (0, 1], got {args.subgoals}")
    rows = probe(args.task, args.subgoals, args.rules, args.overrides)
    print_table(args.task, rows)
    print(json.dumps({"task": args.task, "rows": rows}))
    return rows


if __name__ == "__main__":
    main()
