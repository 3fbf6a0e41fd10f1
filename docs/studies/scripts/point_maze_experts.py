"""PointMaze's expert (the waypoint controller): its success rate, and the shipped demonstrations.

``python docs/studies/scripts/point_maze_experts.py [--episodes 50] [--seed 1000] [--ids PointMaze_UMaze-v3 PointMaze_Medium-v3]``
rolls the expert (:mod:`torchrl_csirl.tasks.robotics.point_maze_expert`) for ``--episodes`` seeded episodes
(seeds ``--seed, --seed + 1, ...``) of each gymnasium task and prints one JSON line: per id, the success rate
(the ball within 0.45 m of the goal, ``info["success"]``) and the mean and longest episode length.

``--module <name>`` imports a module first for the ids it registers (``examples/fixed_goal_mazes.py``'s fixed-goal
mazes). ``--ship`` instead writes the shipped files, ``torchrl_csirl/data/experts/<id>/expert_25.npz`` (or under
``--out-dir``): the first 25 successful episodes from seed 0.
"""
from __future__ import annotations

import argparse
import json
import os

import numpy as np

from torchrl_csirl._paths import EXPERTS_DIR
from torchrl_csirl.data import ExpertDemonstrations, record_demonstrations
from torchrl_csirl.tasks import import_task_module, make_gymnasium_task
from torchrl_csirl.tasks.experts import make_expert

POINT_MAZE_IDS = ("PointMaze_UMaze-v3", "PointMaze_Medium-v3")
SHIPPED_TRAJECTORIES = 25


def record(gym_id: str, episodes: int, seed: int, only_successful: bool = True) -> ExpertDemonstrations:
    """The expert's episodes on the gymnasium task ``gym_id`` (:func:`~torchrl_csirl.data.record_demonstrations`
    with the expert as the policy: episode ``i`` seeded ``seed + i``, ending where the ball reaches the goal)."""
    make_gymnasium_task(gym_id)
    expert = make_expert(gym_id)
    demos = record_demonstrations(gym_id, expert, episodes, seed=seed, only_successful=only_successful)
    return demos.with_metadata(generator=f"{type(expert).__module__}.{type(expert).__qualname__}",
                               expert_settings=expert.settings, base_seed=seed, only_successful=only_successful)


def measure(gym_id: str, episodes: int, seed: int) -> dict[str, float]:
    """Success rate and episode lengths of the expert over ``episodes`` seeded episodes (all kept)."""
    rolled = record(gym_id, episodes, seed, only_successful=False).metadata["episodes"]
    lengths = [e["length"] for e in rolled]
    return {"episodes": episodes, "first_seed": seed, "success_rate": float(np.mean([e["success"] for e in rolled])),
            "mean_length": float(np.mean(lengths)), "max_length": int(max(lengths))}


def ship(gym_id: str, out_dir: str, module: str | None = None) -> str:
    """Writes ``<out_dir>/<gym_id>/expert_25.npz``: the first 25 successful episodes from seed 0."""
    demos = record(gym_id, SHIPPED_TRAJECTORIES, seed=0)
    demos = demos.with_metadata(curriculum="expert", num_trajectories=SHIPPED_TRAJECTORIES,
                                command=f"python docs/studies/scripts/point_maze_experts.py --ship --ids {gym_id}"
                                        + (f" --module {module}" if module else ""))
    os.makedirs(os.path.join(out_dir, gym_id), exist_ok=True)
    return demos.save(os.path.join(out_dir, gym_id, f"expert_{SHIPPED_TRAJECTORIES}.npz"))


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--ids", nargs="+", default=list(POINT_MAZE_IDS), help="PointMaze gymnasium ids")
    parser.add_argument("--episodes", type=int, default=50, help="episodes measured per id")
    parser.add_argument("--seed", type=int, default=1000, help="seed of the first measured episode")
    parser.add_argument("--ship", action="store_true", help="write the shipped demonstrations instead")
    parser.add_argument("--out-dir", default=EXPERTS_DIR, help="folder of --ship's files")
    parser.add_argument("--module", default=None,
                        help="a module to import first, for the ids it registers (e.g. fixed_goal_mazes, with examples/ on PYTHONPATH)")
    args = parser.parse_args(argv)
    if args.module:
        import_task_module(args.module)
    if args.ship:
        result = {gym_id: ship(gym_id, args.out_dir, args.module) for gym_id in args.ids}
    else:
        result = {gym_id: measure(gym_id, args.episodes, args.seed) for gym_id in args.ids}
    print(json.dumps(result, sort_keys=True))
    return result


if __name__ == "__main__":
    main()
