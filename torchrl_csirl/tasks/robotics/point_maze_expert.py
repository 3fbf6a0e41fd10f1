"""The expert of gymnasium-robotics' PointMaze (``PointMaze_UMaze-v3``, ``PointMaze_Medium-v3``, any map).

A waypoint controller over the maze's map: the shortest route of cells from the ball's cell to the goal's
(breadth-first, :func:`~torchrl_csirl.tasks.robotics.maze_cell_route`), then a PD controller pushing the
ball toward the centre of the route's next cell (the goal itself once the ball is in the goal's cell)::

    a = clip(kp (waypoint - position) - kd velocity, -1, 1)

It reads nothing but the ball's position, its velocity and the goal, so it acts on the flat observation of
the gymnasium task (:func:`~torchrl_csirl.tasks.make_gymnasium_task`: ``observation`` 0-4 is the ball's
(x, y, vx, vy), ``desired_goal`` 6-8) as a TorchRL policy, and on the gymnasium environment itself
(``reset(env)``, ``act(env)``, the interface of :func:`~torchrl_csirl.tasks.experts.make_expert`).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch
from tensordict import TensorDictBase

from torchrl_csirl.tasks.robotics.tasks import maze_cell_route

__all__ = ["PointMazeExpert", "make_point_maze_expert"]


class PointMazeExpert:
    """Drives PointMaze's ball along the shortest route of maze cells to the goal.

    Args:
        maze_map: rows of cells, ``1`` a wall (gymnasium-robotics' ``maze.maze_map``).
        cell_size: side of a cell [m] (``maze.maze_size_scaling``, 1 for PointMaze).
        kp: gain on the offset to the waypoint.
        kd: gain on the velocity (damping).
        position_slice: the ball's (x, y) in the flat observation (then its velocity, as PointMaze's
            ``observation`` entry: x, y, vx, vy).
        goal_slice: the goal's (x, y) in the flat observation (``desired_goal``).

    Examples:
        >>> from gymnasium_robotics.envs.maze.maps import U_MAZE
        >>> expert = PointMazeExpert(U_MAZE)
        >>> expert.cell_of(np.array([-1.0, 1.0])), expert.centre_of((3, 1)).tolist()
        ((1, 1), [-1.0, -1.0])
        >>> expert.action(np.array([-1.0, 1.0]), np.zeros(2), np.array([-1.0, -1.0])).tolist()  # first east
        [1.0, 0.0]
    """

    def __init__(self, maze_map: Sequence[Sequence[Any]], cell_size: float = 1.0, kp: float = 10.0, kd: float = 1.0,
                 position_slice: tuple[int, int] = (0, 2), goal_slice: tuple[int, int] = (6, 8)) -> None:
        self.maze_map = tuple(tuple(1 if cell == 1 else 0 for cell in row) for row in maze_map)
        self.cell_size = float(cell_size)
        self.kp, self.kd = float(kp), float(kd)
        self.position_slice, self.goal_slice = position_slice, goal_slice
        rows, cols = len(self.maze_map), len(self.maze_map[0])
        self._x_centre, self._y_centre = cols / 2 * self.cell_size, rows / 2 * self.cell_size

    @property
    def settings(self) -> dict[str, float]:
        """The controller's gains (recorded in the datasets' metadata)."""
        return {"kp": self.kp, "kd": self.kd, "cell_size": self.cell_size}

    def cell_of(self, xy: np.ndarray) -> tuple[int, int]:
        """The (row, col) cell holding ``(x, y)`` (gymnasium-robotics' ``cell_xy_to_rowcol``), clipped to the map."""
        row = math.floor((self._y_centre - float(xy[1])) / self.cell_size)
        col = math.floor((float(xy[0]) + self._x_centre) / self.cell_size)
        return min(max(row, 0), len(self.maze_map) - 1), min(max(col, 0), len(self.maze_map[0]) - 1)

    def centre_of(self, cell: tuple[int, int]) -> np.ndarray:
        """The (x, y) centre of a (row, col) cell (gymnasium-robotics' ``cell_rowcol_to_xy``)."""
        return np.array([(cell[1] + 0.5) * self.cell_size - self._x_centre,
                         self._y_centre - (cell[0] + 0.5) * self.cell_size])

    def waypoint(self, position: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """The centre of the route's next cell, or the goal once the ball is in the goal's cell."""
        start, end = self.cell_of(position), self.cell_of(goal)
        if self.maze_map[start[0]][start[1]] == 1 or start == end:  # pushed into a wall cell: head for the goal
            return np.asarray(goal, dtype=np.float64)
        return self.centre_of(maze_cell_route(self.maze_map, start, end)[1])

    def action(self, position: np.ndarray, velocity: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """The PD push toward :meth:`waypoint`, clipped to ``[-1, 1]`` (float32)."""
        push = self.kp * (self.waypoint(position, goal) - position) - self.kd * np.asarray(velocity, dtype=np.float64)
        return np.clip(push, -1.0, 1.0).astype(np.float32)

    def act_on(self, observation: np.ndarray) -> np.ndarray:
        """The action for one flat observation (the gymnasium task's)."""
        obs = np.asarray(observation, dtype=np.float64)
        p0, p1 = self.position_slice
        return self.action(obs[p0:p1], obs[p1:p1 + 2], obs[self.goal_slice[0]:self.goal_slice[1]])

    def __call__(self, td: TensorDictBase) -> TensorDictBase:
        """A TorchRL policy: ``"action"`` from ``"observation"`` (any batch shape)."""
        obs = td["observation"].detach().cpu().numpy()
        flat = obs.reshape(-1, obs.shape[-1])
        actions = np.stack([self.act_on(row) for row in flat]).reshape(*obs.shape[:-1], 2)
        td["action"] = torch.as_tensor(actions, device=td["observation"].device)
        return td

    def reset(self, env: Any) -> None:
        """Nothing to reset: the route is planned again at every step."""

    def act(self, env: Any) -> np.ndarray:
        """The action in a gymnasium PointMaze environment (wrapped or not), read from its simulation."""
        maze = env.unwrapped
        qpos, qvel = maze.point_env.data.qpos, maze.point_env.data.qvel
        return self.action(np.asarray(qpos[:2], dtype=np.float64), np.asarray(qvel[:2], dtype=np.float64), maze.goal)


def make_point_maze_expert(name: str, kp: float = 10.0, kd: float = 1.0) -> PointMazeExpert:
    """The expert of the PointMaze task ``name`` (a gymnasium id, its :attr:`~torchrl_csirl.tasks.TaskSpec.expert`):
    the maze map read from the environment, the ball and goal from the task's observation layout.

    Examples:
        >>> expert = make_point_maze_expert("PointMaze_UMaze-v3")
        >>> len(expert.maze_map), expert.goal_slice
        (5, (6, 8))
    """
    import gymnasium as gym

    from torchrl_csirl.tasks.catalog import TASKS
    from torchrl_csirl.tasks.gym_ids import import_gym_provider
    from torchrl_csirl.tasks.gymnasium_env import remove_maze_xml

    import_gym_provider(name)
    env = gym.make(name)
    remove_maze_xml(env)
    try:
        maze = env.unwrapped.maze
        maze_map, cell_size = maze.maze_map, maze.maze_size_scaling
    finally:
        env.close()
    spec = TASKS.get(name)
    layout = dict(spec.observation_layout) if spec is not None else {}
    ball = layout.get("observation", (0, 4))[0]  # PointMaze's observation: x, y, vx, vy
    return PointMazeExpert(maze_map, cell_size, kp, kd, position_slice=(ball, ball + 2),
                           goal_slice=layout.get("desired_goal", (6, 8)))

