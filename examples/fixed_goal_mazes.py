"""PointMaze with one goal and one start cell: the single change of the goal-conditioned study
(docs/studies/outside-driving.md), registered as gymnasium ids when imported (``env.module=fixed_goal_mazes``).

gymnasium-robotics' ``PointMaze_UMaze-v3`` and ``PointMaze_Medium-v3`` draw the goal and the start cell anew each
episode; CSIRL's published matching (``csirl.goal_conditioned=false``) follows one curriculum trajectory (the
demonstrations' first), toward that trajectory's goal.
These ids are the same mazes, the same environment class and episode limits, with the goal cell (``g``) and the
start cell (``r``) fixed as in D4RL's AntMaze U-maze, the paper's robotics maze: start bottom-left, goal top-left
around the U (U-maze); start top-left, goal bottom-right (Medium). The ball still starts and the goal still sits
within +-0.25 m of noise of their cells' centres.

Run with this folder on ``PYTHONPATH`` (``env.module`` also looks in the working directory)::

    PYTHONPATH=examples python recipes/csirl_highway.py env.module=fixed_goal_mazes \\
        env.gym_id=PointMaze_UMazeFixedGoal-v3 expert.path=<demonstrations of that id>
"""
from __future__ import annotations

import gymnasium as gym

__all__ = ["FIXED_GOAL_IDS", "MEDIUM_FIXED", "U_MAZE_FIXED"]

G, R = "g", "r"
#: gymnasium-robotics' U_MAZE with the start bottom-left and the goal top-left (around the U)
U_MAZE_FIXED = [
    [1, 1, 1, 1, 1],
    [1, G, 0, 0, 1],
    [1, 1, 1, 0, 1],
    [1, R, 0, 0, 1],
    [1, 1, 1, 1, 1],
]
#: gymnasium-robotics' MEDIUM_MAZE with the start top-left and the goal bottom-right
MEDIUM_FIXED = [
    [1, 1, 1, 1, 1, 1, 1, 1],
    [1, R, 0, 1, 1, 0, 0, 1],
    [1, 0, 0, 1, 0, 0, 0, 1],
    [1, 1, 0, 0, 0, 1, 1, 1],
    [1, 0, 0, 1, 0, 0, 0, 1],
    [1, 0, 1, 0, 0, 1, 0, 1],
    [1, 0, 0, 0, 1, 0, G, 1],
    [1, 1, 1, 1, 1, 1, 1, 1],
]
#: id -> (maze map, episode limit of the random-goal id it copies)
FIXED_GOAL_IDS = {"PointMaze_UMazeFixedGoal-v3": (U_MAZE_FIXED, 300), "PointMaze_MediumFixedGoal-v3": (MEDIUM_FIXED, 600)}

for _id, (_map, _steps) in FIXED_GOAL_IDS.items():
    if _id not in gym.registry:
        gym.register(_id, entry_point="gymnasium_robotics.envs.maze.point_maze:PointMazeEnv",
                     kwargs={"maze_map": _map, "reward_type": "sparse"}, max_episode_steps=_steps)
