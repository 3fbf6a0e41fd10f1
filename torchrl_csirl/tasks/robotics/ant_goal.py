"""The AntMaze expert's pieces: a short-hop goal-reaching ant and the waypoint controller driving it.

D4RL and Minari built their AntMaze data from a goal-reaching ant policy driven through the maze
by waypoints from a path planner (SPEC section 5, docs/studies/robotics.md). No such policy is reachable
offline, so we train our own:

* :class:`AntGoalEnv` (task ``"ant-goal"``, :func:`~torchrl_csirl.tasks.make_env`): the U-maze ant
  (gymnasium-robotics' ``AntMazeEnv`` model, 0.05 s steps) starting anywhere in a random free cell
  with a random heading, walking a chain of ``CHAIN_HOPS`` (4) goals: each goal is the centre of
  the ant's cell or of a neighbouring free cell, with +-1 m of noise (0.9-6.3 m hops, shorter ones
  redrawn: what the waypoint controller asks), and the next one is drawn the moment the ant
  arrives (within 0.45 m), so the ant learns to walk on, as it must through the maze, where the
  waypoint moves ahead without stopping. Reward: the speed toward the current goal
  (``(d_{t-1} - d_t) / dt``), minus a control cost (``0.1 |a|^2``; gymnasium's ant: 0.5), +10 on
  each arrival; the last arrival ends the episode (success); a flipped ant (its torso's up axis
  pointing below the horizon: it never recovers) ends it too. 300 steps.
* :func:`ant_goal_observation`: the policy's input (29 values): the ant's 27 values (torso height,
  orientation, joint angles, velocities; no position) then the goal vector in the torso's heading
  frame, clipped to 5 m. Where the hop is in the maze does not matter to the policy.
* :class:`WaypointAntExpert`: the expert of ``"antmaze-umaze"``. At each step the breadth-first
  cell route (:func:`~torchrl_csirl.tasks.robotics.maze_cell_route`) from the ant's cell to the goal
  cell gives the waypoint (the centre of the next cell on it; the goal itself in the goal cell),
  and the trained goal-reaching policy acts on it with its mean action.

``recipes/train_ant_expert.py`` trains the policy with TorchRL's SAC (resumable).
"""
from __future__ import annotations

import dataclasses
import math
import os
from types import MappingProxyType
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from torchrl_csirl._paths import EXPERTS_DIR
from torchrl_csirl.tasks.robotics.tasks import (
    ANT_LAYOUT,
    ANTMAZE_SUCCESS_RADIUS,
    ANTMAZE_UMAZE_MAP,
    ROBOTICS_TASKS,
    AntMazeUMazeEnv,
    RoboticsTaskSpec,
    Route,
    is_flipped,
    maze_cell_route,
)

__all__ = [
    "ANT_GOAL_SPEC",
    "ANT_POLICY_PATH",
    "AntGoalEnv",
    "WaypointAntExpert",
    "ant_goal_observation",
    "free_cells",
    "heading_of",
    "is_flipped",
    "make_waypoint_ant_expert",
    "next_waypoint",
    "pursuit_waypoint",
]

GOAL_VECTOR_CLIP = 5.0  # [m] the policy never sees a goal further away than this
ARRIVAL_BONUS = 10.0
CHAIN_HOPS = 4  # goals per ant-goal episode (a single hop never showed the ant how to keep walking)
CONTROL_COST = 0.1  # x |a|^2 (gymnasium's ant: 0.5; lower, so that ending an episode early never pays)
ANT_POLICY_PATH = os.path.join(EXPERTS_DIR, "antmaze-umaze", "ant_goal_policy.pt")
"""The shipped goal-reaching ant (a :func:`~torchrl_csirl.modules.save_policy` file trained by
``recipes/train_ant_expert.py``; docs/experts.md gives the run and its figures)."""


def free_cells(maze_map: Any = ANTMAZE_UMAZE_MAP) -> list[tuple[int, int]]:
    """The (row, col) cells of a maze that are not walls (``1``).

    Examples:
        >>> free_cells()[:3]
        [(1, 1), (1, 2), (1, 3)]
    """
    return [(r, c) for r, row in enumerate(maze_map) for c, cell in enumerate(row) if cell != 1]


def heading_of(quaternion: np.ndarray) -> float:
    """The yaw [rad] of a MuJoCo ``(w, x, y, z)`` quaternion.

    Examples:
        >>> round(heading_of(np.array([math.cos(0.4), 0.0, 0.0, math.sin(0.4)])), 6)
        0.8
    """
    w, x, y, z = (float(v) for v in quaternion[:4])
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def ant_goal_observation(ant_values: np.ndarray, position: np.ndarray, goal: np.ndarray) -> np.ndarray:
    """The goal-reaching policy's input: the ant's 27 values, then the goal vector in its heading frame.

    Args:
        ant_values: the 27 values of the ant (``qpos[2:]`` then ``qvel``: torso height, the
            ``(w, x, y, z)`` orientation, 8 joint angles, 14 velocities).
        position: the torso's ``(x, y)`` [m].
        goal: the goal's ``(x, y)`` [m].

    Returns:
        29 float64 values; the goal vector ``R(-yaw) (goal - position)`` is clipped to 5 m.

    Examples:
        >>> ant = np.zeros(27); ant[1] = 1.0  # upright, heading +x
        >>> ant_goal_observation(ant, np.array([1.0, 1.0]), np.array([1.0, 9.0]))[27:].tolist()
        [0.0, 5.0]
    """
    ant_values = np.asarray(ant_values, dtype=np.float64).reshape(-1)
    if ant_values.shape[0] != 27:
        raise ValueError(f"ant_values must hold the ant's 27 values, got {ant_values.shape[0]}.")
    dx, dy = (np.asarray(goal, dtype=np.float64) - np.asarray(position, dtype=np.float64))[:2]
    yaw = heading_of(ant_values[1:5])
    cos, sin = math.cos(yaw), math.sin(yaw)
    local = np.array([cos * dx + sin * dy, -sin * dx + cos * dy])
    norm = float(np.hypot(*local))
    if norm > GOAL_VECTOR_CLIP:
        local *= GOAL_VECTOR_CLIP / norm
    return np.concatenate([ant_values, local])


class AntGoalEnv(AntMazeUMazeEnv):
    """Chained-hop goal reaching for the U-maze ant (the training task of the AntMaze expert).

    The U-maze ant of :class:`~torchrl_csirl.tasks.robotics.AntMazeUMazeEnv` (same model, position,
    rendering and info keys) with its own episodes: each starts in a uniformly drawn free cell
    (+-1 m around its centre, a uniform heading) and chains :data:`CHAIN_HOPS` goals, each the
    centre (+-1 m) of the ant's current cell or of a free neighbour, the next drawn on arrival at
    the last. ``distance_to_finish`` is the straight-line distance to the current goal;
    ``progress`` is ``(hops done + the current hop's progress) / CHAIN_HOPS``; ``hops`` counts the
    goals reached; ``success`` is the last goal reached.

    Why chained: with one hop per episode (the first version) the trained ant reached 85-95 % of
    its hops yet flipped in 9 of 10 AntMaze episodes, where the waypoint keeps moving ahead and the
    ant walks for ~250 steps without a stop (docs/studies/robotics.md).

    Examples:
        >>> env = AntGoalEnv()
        >>> obs, info = env.reset(seed=0)
        >>> obs.shape, info["success"], info["hops"]
        ((29,), False, 0)
        >>> obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        >>> terminated, truncated
        (False, False)
    """

    max_steps = 300

    def __init__(self, render_mode: str | None = None) -> None:
        super().__init__(render_mode, position_noise=0.25)  # +-1 m in 4 m cells (gymnasium-robotics' default)
        self.dt = float(self._inner.ant_env.dt)
        self._cells = free_cells()
        self._distance = 0.0
        self._hops = 0

    def _ant_values(self) -> np.ndarray:
        data = self._inner.ant_env.data
        return np.concatenate([data.qpos[2:], data.qvel]).astype(np.float64)

    def _goal_cell_from(self, cell: tuple[int, int]) -> tuple[int, int]:
        r, c = cell
        options = [cell] + [n for n in ((r - 1, c), (r + 1, c), (r, c - 1), (r, c + 1)) if n in self._cells]
        return options[int(self.np_random.integers(len(options)))]

    def _turn(self, yaw: float) -> None:
        ant = self._inner.ant_env
        qpos, qvel = ant.data.qpos.copy(), ant.data.qvel.copy()
        qpos[3:7] = (math.cos(yaw / 2.0), 0.0, 0.0, math.sin(yaw / 2.0))
        ant.set_state(qpos, qvel)

    def _goal_observation(self) -> np.ndarray:
        return ant_goal_observation(self._ant_values(), self.position(), self.goal)

    def _set_goal(self, goal: np.ndarray) -> None:
        self._inner.goal = np.asarray(goal, dtype=np.float64)
        self._inner.update_target_site_pos()
        self._distance = self._initial_distance = float(np.hypot(*(self.goal - self.position())))

    def _next_goal(self) -> None:
        """The next hop from the ant's cell (a goal already within reach is drawn again)."""
        cell = tuple(int(v) for v in self.maze.cell_xy_to_rowcol(self.position()))
        if cell not in self._cells:  # the torso over a wall's edge: the nearest free cell
            cell = min(self._cells, key=lambda c: float(np.hypot(*(self.maze.cell_rowcol_to_xy(np.array(c))
                                                                    - self.position()))))
        noise = self._inner.position_noise_range * self.maze.maze_size_scaling
        for _ in range(100):
            centre = self.maze.cell_rowcol_to_xy(np.array(self._goal_cell_from(cell)))
            self._set_goal(centre + self.np_random.uniform(-noise, noise, 2))
            if self._distance > 2.0 * ANTMAZE_SUCCESS_RADIUS:
                break

    def _distance_and_success(self) -> tuple[float, bool]:
        return self._distance, self._hops >= CHAIN_HOPS

    def _info(self) -> dict[str, Any]:
        info = super()._info()  # its progress is the current hop's (distance against the hop's start)
        hop = 0.0 if info["success"] else info["progress"]
        info.update(progress=(self._hops + hop) / CHAIN_HOPS, hops=self._hops)
        return info

    def _flatten(self, raw: np.ndarray) -> np.ndarray:
        return raw  # _inner_step's, already the policy's input

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        gym.Env.reset(self, seed=seed)
        start = self._cells[int(self.np_random.integers(len(self._cells)))]
        # the inner env draws its noise from its own generator: seed it from ours
        inner_seed = int(self.np_random.integers(2**31 - 1))
        self._inner.reset(seed=inner_seed, options={"reset_cell": np.array(start), "goal_cell": np.array(start)})
        self._turn(float(self.np_random.uniform(-math.pi, math.pi)))
        self._hops = 0
        self._next_goal()
        self._steps = 0
        self._observation = self._goal_observation()
        return self._observation.astype(np.float32), self._info()

    def _inner_step(self, action) -> tuple[np.ndarray, float, bool]:
        """One ant step: speed toward the goal minus the control cost, +10 and the next goal on arrival;
        ends at the last arrival or a flip."""
        action = np.asarray(action, dtype=np.float64)
        self._inner.ant_env.step(action)
        before, self._distance = self._distance, float(np.hypot(*(self.goal - self.position())))
        reward = (before - self._distance) / self.dt - CONTROL_COST * float(np.sum(action * action))
        if self._distance <= ANTMAZE_SUCCESS_RADIUS:
            reward += ARRIVAL_BONUS
            self._hops += 1
            if self._hops < CHAIN_HOPS:
                self._next_goal()
        done = self._hops >= CHAIN_HOPS or is_flipped(self._inner.ant_env.data.qpos[3:7])
        return self._goal_observation(), reward, done


def _ant_goal_spec() -> RoboticsTaskSpec:
    # AntMaze's spec (same ant, dimensions and step) with this task's env, limit and goal vector; no
    # maze_map: features 27-28 are the goal vector, not a position to draw in the maze
    return dataclasses.replace(
        ROBOTICS_TASKS["antmaze-umaze"],
        name="ant-goal",
        gym_id="csirl/ant-goal-v0",
        env_options=(),
        maze_map=None,
        entry_point=f"{__name__}:AntGoalEnv",
        max_steps=AntGoalEnv.max_steps,
        finish_position=None,
        observation_layout=MappingProxyType({**ANT_LAYOUT, "goal_vector": (27, 29)}),
        description=f"the U-maze ant reaching {CHAIN_HOPS} goals in a row, each 0.9-6.3 m on (the AntMaze expert's training task)",
    )


ANT_GOAL_SPEC = _ant_goal_spec()


def _route_points(position: np.ndarray, goal: np.ndarray, maze: Any) -> list[np.ndarray]:
    """Centres of the cells from the ant's cell to the goal's, the last replaced by the goal."""
    cell = tuple(int(v) for v in maze.cell_xy_to_rowcol(position))
    goal_cell = tuple(int(v) for v in maze.cell_xy_to_rowcol(goal))
    if maze.maze_map[cell[0]][cell[1]] == 1:  # inside a wall cell (a leg over the edge): head for the goal
        return [goal]
    route = maze_cell_route(maze.maze_map, cell, goal_cell)
    points = [np.asarray(maze.cell_rowcol_to_xy(np.array(c)), dtype=np.float64) for c in route]
    points[-1] = goal
    return points


def next_waypoint(position: np.ndarray, goal: np.ndarray, maze: Any) -> np.ndarray:
    """The waypoint toward ``goal``: the centre of the next cell on the cell route, or the goal itself.

    Args:
        position: the ant's (x, y) [m].
        goal: the goal (x, y) [m].
        maze: a gymnasium-robotics ``Maze`` (``cell_xy_to_rowcol``, ``cell_rowcol_to_xy``, ``maze_map``).

    Examples:
        >>> from torchrl_csirl.tasks.robotics import AntMazeUMazeEnv
        >>> maze = AntMazeUMazeEnv().maze
        >>> next_waypoint(np.array([-4.0, 4.0]), np.array([-4.0, -4.0]), maze).tolist()
        [0.0, 4.0]
    """
    points = _route_points(np.asarray(position, dtype=np.float64), np.asarray(goal, dtype=np.float64), maze)
    return points[min(1, len(points) - 1)]  # the next cell's centre, or the goal from its cell and the one before


def pursuit_waypoint(position: np.ndarray, goal: np.ndarray, maze: Any, lookahead: float = 3.0) -> np.ndarray:
    """Pure pursuit along the cell route: the point ``lookahead`` metres on from the ant's foot on it.

    The route is the polyline through the centres of the cells from the ant's cell to the goal's
    (:func:`~torchrl_csirl.tasks.robotics.maze_cell_route`), ending at the goal. The waypoint is
    found by projecting the ant onto that polyline and walking ``lookahead`` metres along it
    (the goal if the route ends sooner). Unlike :func:`next_waypoint`, whose waypoint jumps to the
    next cell's centre as soon as the ant enters a cell, and then lies round the corner of a wall,
    it turns corners on the centre line: the ant is never sent diagonally across a wall's corner.

    Args:
        position: the ant's (x, y) [m].
        goal: the goal (x, y) [m].
        maze: a gymnasium-robotics ``Maze`` (``cell_xy_to_rowcol``, ``cell_rowcol_to_xy``, ``maze_map``).
        lookahead: metres along the route ahead of the ant. Defaults to ``3.0`` (cells are 4 m).

    Examples:
        >>> from torchrl_csirl.tasks.robotics import AntMazeUMazeEnv
        >>> maze = AntMazeUMazeEnv().maze
        >>> pursuit_waypoint(np.array([-4.0, 4.0]), np.array([-4.0, -4.0]), maze).tolist()
        [-1.0, 4.0]
        >>> pursuit_waypoint(np.array([3.0, 4.5]), np.array([-4.0, -4.0]), maze).tolist()  # round the corner
        [4.0, 1.0]
    """
    if lookahead <= 0:
        raise ValueError(f"lookahead must be > 0 metres, got {lookahead}.")
    position = np.asarray(position, dtype=np.float64)
    points = _route_points(position, np.asarray(goal, dtype=np.float64), maze)
    if len(points) == 1:
        return points[0]
    return np.asarray(Route(points).point_ahead(position[0], position[1], float(lookahead)), dtype=np.float64)


class WaypointAntExpert:
    """The AntMaze expert: a goal-reaching ant policy driven through the maze by waypoints.

    Interface of every expert (``reset(env)``, ``act(env)``) on an
    :class:`~torchrl_csirl.tasks.robotics.AntMazeUMazeEnv`.

    The waypoint is :func:`pursuit_waypoint` (``lookahead`` metres ahead on the route through
    the cell centres), and the policy's mean action is multiplied by ``action_gain``: the shipped
    ant, trained at full gain on open ground, flips in the maze's corridors at full gain
    (docs/experts.md, "AntMaze expert": 0.80 success at gain 1 with :func:`next_waypoint`,
    0.99 on the same seeds at gain 0.6 with a 3 m look-ahead).

    Args:
        policy: the goal-reaching actor (a :func:`~torchrl_csirl.modules.save_policy` file or
            run directory of ``recipes/train_ant_expert.py``, or the loaded actor), acting with
            its mean action on :func:`ant_goal_observation`. Default: the shipped ant
            (:data:`ANT_POLICY_PATH`).

    Keyword Args:
        lookahead (float or None): metres of pure pursuit along the route. ``None``: the
            next cell's centre (:func:`next_waypoint`, the rule before 2026-11-26).
            Defaults to ``3.0``.
        action_gain (float): multiplies the policy's action, in ``(0, 1]``. Defaults to ``0.6``.

    Raises:
        FileNotFoundError: no policy file there.
        ValueError: the policy's dimensions are not the ant's (29 inputs, 8 actions), or a
            ``lookahead`` / ``action_gain`` out of range.

    Examples:
        >>> from torchrl_csirl.tasks import make_gym_env
        >>> env = make_gym_env("antmaze-umaze")
        >>> _ = env.reset(seed=0)
        >>> WaypointAntExpert().act(env).shape
        (8,)
    """

    def __init__(self, policy: Any = None, *, lookahead: float | None = 3.0, action_gain: float = 0.6) -> None:
        from torchrl_csirl.modules import load_policy

        if lookahead is not None and lookahead <= 0:
            raise ValueError(f"lookahead must be > 0 metres (or None: the next cell's centre), got {lookahead}.")
        if not 0 < action_gain <= 1:
            raise ValueError(f"action_gain must lie in (0, 1], got {action_gain}.")
        self.lookahead = lookahead
        self.action_gain = float(action_gain)
        if policy is None:
            policy = ANT_POLICY_PATH
        self.policy = load_policy(policy) if isinstance(policy, (str, os.PathLike)) else policy
        meta = getattr(self.policy, "metadata", {})
        dims = (meta.get("obs_dim", 29), meta.get("action_dim", 8))
        if dims != (29, 8):
            raise ValueError(f"the ant expert needs a policy with 29 inputs and 8 actions, got {dims[0]} and {dims[1]}.")

    def reset(self, env: Any) -> None:
        """Nothing to reset: the waypoint is recomputed from the ant's cell at every step."""

    @torch.no_grad()
    def act(self, env: Any) -> np.ndarray:
        from tensordict import TensorDict
        from torchrl.envs.utils import ExplorationType, set_exploration_type

        position = env.position()
        waypoint = self.waypoint(position, env.goal, env.maze)
        ant = env.observation()[:27]
        obs = torch.as_tensor(ant_goal_observation(ant, position, waypoint), dtype=torch.float32)
        with set_exploration_type(ExplorationType.DETERMINISTIC):
            action = self.policy(TensorDict({"observation": obs}, []))["action"]
        return (self.action_gain * action).numpy().astype(np.float32)

    @property
    def settings(self) -> dict[str, float | None]:
        """The controller's settings (recorded in the datasets it writes)."""
        return {"lookahead": self.lookahead, "action_gain": self.action_gain}

    def waypoint(self, position: np.ndarray, goal: np.ndarray, maze: Any) -> np.ndarray:
        """The goal the ant policy is shown: :func:`pursuit_waypoint`, or :func:`next_waypoint` without look-ahead."""
        if self.lookahead is None:
            return next_waypoint(position, goal, maze)
        return pursuit_waypoint(position, goal, maze, self.lookahead)


def make_waypoint_ant_expert(name: str = "antmaze-umaze", policy: Any = None, *, lookahead: float | None = 3.0,
                             action_gain: float = 0.6) -> WaypointAntExpert:
    """The expert of ``"antmaze-umaze"`` (its :attr:`~torchrl_csirl.tasks.TaskSpec.expert`): a
    :class:`WaypointAntExpert` with these settings (``policy``: a policy file or run directory).

    Examples:
        >>> make_waypoint_ant_expert(action_gain=1.0).settings
        {'lookahead': 3.0, 'action_gain': 1.0}
    """
    return WaypointAntExpert(policy, lookahead=lookahead, action_gain=action_gain)
