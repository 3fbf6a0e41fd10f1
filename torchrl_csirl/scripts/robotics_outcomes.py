"""How a robotics policy's test episodes end: AntMaze U-maze or Adroit Relocate (``torchrl-csirl outcomes``).

``torchrl-csirl outcomes <run dir or policy.pt> [--episodes 50] [--seed 1000000]``

Rolls out the saved deterministic policy on the recipe's test episodes (seeds
``seed .. seed + episodes - 1``, as the final evaluation does) and reports how they end:

* **AntMaze**: ``goal`` (reached), ``flipped`` (the ant lies on its back: it never rights itself)
  or ``short`` (neither, at the 700-step limit); the progress along the route, the step of the
  flips, and **where the ant ended**: the maze cell, counted along the cell route from the start
  (``0`` is the start cell, the goal cell the last; ``off`` a cell off the route), with the mean
  end position in each. A policy pulled in a straight line toward a target round the corner stops
  in the start arm (cells 0-1), facing the central wall (docs/studies/index.md, "AntMaze: CSIRL with
  cloning at 3 seeds").
* **Relocate**: ``at_target`` (the ball within 0.1 m of the target at the last step), ``lost`` (it
  was there at some step, not at the end) or ``never``; the progress, the return, and the
  ball-target distance at the end.

The last line is JSON; a Markdown table goes to stderr.

Examples:
    >>> summarize("relocate", [{"outcome": "lost", "accomplish_rate": 0.5, "return": 3.0, "final_distance": 0.2}])
    {'episodes': 1, 'accomplish_rate': 0.5, 'at_target': 0, 'lost': 1, 'never': 0, 'return': 3.0, 'final_distance': 0.2}
"""
from __future__ import annotations

import json
import os
import sys
from collections import Counter, defaultdict

import numpy as np

from torchrl_csirl.scripts._policy_rollouts import first_crash_step, format_cell, load_test_policy, mean_or_none, roll_test_episodes
from torchrl_csirl.tasks import accomplish_rate_from_rollout, gym_env_of
from torchrl_csirl.tasks.robotics import ROBOTICS_TASKS

__all__ = ["OUTCOMES", "classify_episodes", "main", "print_table", "report", "summarize"]

OUTCOMES = {"antmaze-umaze": ("goal", "flipped", "short"), "relocate": ("at_target", "lost", "never")}


def route_cell(task_env, position: np.ndarray) -> str:
    """AntMaze: the maze cell at ``position``, as its index along the start-to-goal cell route (``"off"`` if not on it)."""
    cell = tuple(int(v) for v in task_env.maze.cell_xy_to_rowcol(np.asarray(position)))
    return str(task_env.route_cells.index(cell)) if cell in task_env.route_cells else "off"


def antmaze_record(rollout, task_env) -> dict:
    """One AntMaze episode: outcome, the first flipped step, the end position and its route cell."""
    flip_step = first_crash_step(rollout)
    if bool(rollout["next", "success"].any()):
        outcome = "goal"
    else:
        outcome = "short" if flip_step is None else "flipped"
    position = task_env.position()
    return {"outcome": outcome, "flip_step": flip_step,
            "end": [round(float(v), 2) for v in position], "end_cell": route_cell(task_env, position)}


def relocate_record(rollout, task_env) -> dict:
    """One Relocate episode: outcome, the return and the ball-target distance at the end."""
    success = rollout["next", "success"].reshape(-1)
    if bool(success[-1]):
        outcome = "at_target"
    else:
        outcome = "lost" if bool(success.any()) else "never"
    return {"outcome": outcome, "return": float(rollout["next", "reward"].sum()),
            "final_distance": float(rollout["next", "distance_to_finish"].reshape(-1)[-1])}


def classify_episodes(policy, task: str, episodes: int, seed: int) -> list[dict]:
    """One record per test episode: ``outcome``, ``accomplish_rate`` (progress), ``steps`` and the task's own fields."""
    describe = antmaze_record if task == "antmaze-umaze" else relocate_record
    rollouts = roll_test_episodes(policy, task, episodes, seed, ROBOTICS_TASKS[task].max_steps)
    return [{"episode": i, "accomplish_rate": float(accomplish_rate_from_rollout(rollout)),
             "steps": rollout.shape[-1], **describe(rollout, gym_env_of(env).unwrapped)}
            for i, (env, rollout, _) in enumerate(rollouts)]


def summarize(task: str, records: list[dict]) -> dict[str, object]:
    """Outcome counts and mean progress; AntMaze: flip step and end cells; Relocate: return and final distance."""
    counts = Counter(r["outcome"] for r in records)
    stats: dict[str, object] = {"episodes": len(records), "accomplish_rate": mean_or_none([r["accomplish_rate"] for r in records]),
                                **{o: counts.get(o, 0) for o in OUTCOMES[task]}}
    if task == "antmaze-umaze":
        ends: dict[str, list] = defaultdict(list)
        for r in records:
            if r["outcome"] != "goal":
                ends[r["end_cell"]].append(r["end"])
        stats["flip_step"] = mean_or_none([float(r["flip_step"]) for r in records if r["flip_step"] is not None])
        stats["end_cells"] = {cell: {"episodes": len(points), "mean_end": [round(float(v), 2) for v in np.mean(points, axis=0)]}
                              for cell, points in sorted(ends.items())}
    else:
        stats["return"] = mean_or_none([r["return"] for r in records])
        stats["final_distance"] = mean_or_none([r["final_distance"] for r in records])
    return stats


def print_table(task: str, stats: dict[str, object]) -> None:
    """The summary as a one-row Markdown table on stderr."""
    outcomes = OUTCOMES[task]
    if task == "antmaze-umaze":
        ends = " ".join(f"{cell}: {e['episodes']} at {tuple(e['mean_end'])}" for cell, e in stats["end_cells"].items())
        extra = ("flipped at step", "not at the goal, by end cell (route index: n at mean (x, y))"), \
            (format_cell(stats["flip_step"], ".0f"), ends or "-")
    else:
        extra = ("return", "ball-target distance at the end [m]"), \
            (format_cell(stats["return"], ".1f"), format_cell(stats["final_distance"], ".3f"))
    header = ["episodes", "progress", *outcomes, *extra[0]]
    row = [str(stats["episodes"]), format_cell(stats["accomplish_rate"], ".3f"), *(str(stats[o]) for o in outcomes), *extra[1]]
    print("| " + " | ".join(header) + " |", file=sys.stderr)
    print("|" + "---|" * len(header), file=sys.stderr)
    print("| " + " | ".join(row) + " |", file=sys.stderr)


def report(args, policy, task: str) -> dict[str, object]:
    """Rolls ``policy`` on ``task``'s test episodes (``args.episodes`` from ``args.seed``), prints the table
    (stderr) and the JSON line; returns the summary."""
    stats = summarize(task, classify_episodes(policy, task, args.episodes, args.seed))
    print_table(task, stats)
    print(json.dumps({"policy": os.path.abspath(args.policy), "task": task, **stats}))
    return stats


def main(argv: list[str] | None = None) -> dict[str, object]:
    """``torchrl-csirl outcomes`` for a robotics policy alone (``argv``: the command line); returns :func:`report`'s."""
    return report(*load_test_policy(__doc__.splitlines()[0], argv, OUTCOMES, "robotics tasks",
                                    prog="torchrl-csirl outcomes"))


if __name__ == "__main__":
    main()
