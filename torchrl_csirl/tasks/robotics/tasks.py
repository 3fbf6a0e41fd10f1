"""The paper's robotics tasks (AntMaze U-maze, Adroit Relocate): specs and gymnasium environments.

Each task is a plain :class:`gymnasium.Env` that owns a gymnasium-robotics environment and gives
it the interface of the driving scenarios:

* a flat float32 ``observation`` (AntMaze: the 27 ant values then the ant's (x, y), 29 in all;
  Relocate: the 39 values of ``AdroitHandRelocate-v1``);
* the episode limit as ``truncated`` (AntMaze 700 steps, Relocate 200), counted inside;
* ``info`` entries ``distance_to_finish``, ``progress``, ``arrived``, ``success`` (the same keys
  as the driving scenarios); AntMaze also reports ``crashed``: the ant lies on its back
  (:func:`is_flipped`; it never rights itself, and as in D4RL the episode goes on). ``offroad``
  does not happen and is not reported.

The progress measure (the accomplish rate's analogue) is ``clip(1 - d / d_0, 0, 1)`` with ``d``
the remaining distance to the goal and ``d_0`` its value at reset:

* AntMaze: ``d`` is the remaining length of the route through the maze: the ant's position
  projected on the polyline through the centres of the cells a breadth-first planner finds from
  the start cell to the goal cell (ending at the goal itself), plus the distance to that projection.
  The straight-line distance would be wrong in a U: the ant first moves away from the goal.
* Relocate: ``d`` is the object-target distance (``|obs[36:39]|``).

See ``docs/scenarios.md``.
"""
from __future__ import annotations

import contextlib
import math
import os
from collections import deque
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, Sequence

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from torchrl_csirl.tasks.headless import ensure_headless_gl
from torchrl_csirl.tasks.spec import TaskSpec

__all__ = [
    "ANTMAZE_UMAZE_MAP",
    "AntMazeUMazeEnv",
    "ROBOTICS_TASKS",
    "RelocateEnv",
    "RoboticsTaskSpec",
    "Route",
    "is_flipped",
    "maze_cell_route",
    "route_remaining_length",
]

# D4RL's U-maze: start ("r") and goal ("g") at the two ends of the U
ANTMAZE_UMAZE_MAP: tuple[tuple[Any, ...], ...] = (
    (1, 1, 1, 1, 1),
    (1, "r", 0, 0, 1),
    (1, 1, 1, 0, 1),
    (1, "g", 0, 0, 1),
    (1, 1, 1, 1, 1),
)
# reset and goal noise, as a fraction of the 4 m cell: +-0.1 m (gymnasium-robotics: +-1 m);
# D4RL's ant started at its cell centre with 0.1 qpos noise and a fixed goal
ANTMAZE_POSITION_NOISE = 0.025
ANTMAZE_SUCCESS_RADIUS = 0.45  # gymnasium-robotics' (and D4RL's) goal radius [m]
RELOCATE_SUCCESS_RADIUS = 0.1  # AdroitHandRelocate: object within 0.1 m of the target


def is_flipped(quaternion: np.ndarray) -> bool:
    """Whether the torso's up axis points below the horizon (``(w, x, y, z)`` quaternion).

    Examples:
        >>> is_flipped(np.array([1.0, 0.0, 0.0, 0.0])), is_flipped(np.array([0.0, 1.0, 0.0, 0.0]))
        (False, True)
    """
    _, x, y, _ = (float(v) for v in quaternion[:4])
    return 1.0 - 2.0 * (x * x + y * y) < 0.0


def maze_cell_route(maze_map: Sequence[Sequence[Any]], start: tuple[int, int], goal: tuple[int, int]) -> list[tuple[int, int]]:
    """Shortest route of (row, col) cells from ``start`` to ``goal`` (breadth-first, 4-neighbours).

    Walls are cells equal to ``1``.

    Examples:
        >>> maze_cell_route(ANTMAZE_UMAZE_MAP, (1, 1), (3, 1))
        [(1, 1), (1, 2), (1, 3), (2, 3), (3, 3), (3, 2), (3, 1)]
    """
    rows, cols = len(maze_map), len(maze_map[0])
    parent: dict[tuple[int, int], tuple[int, int] | None] = {tuple(start): None}
    queue = deque([tuple(start)])
    while queue:
        cell = queue.popleft()
        if cell == tuple(goal):
            route = []
            while cell is not None:
                route.append(cell)
                cell = parent[cell]
            return route[::-1]
        r, c = cell
        for nxt in ((r - 1, c), (r + 1, c), (r, c - 1), (r, c + 1)):
            if 0 <= nxt[0] < rows and 0 <= nxt[1] < cols and maze_map[nxt[0]][nxt[1]] != 1 and nxt not in parent:
                parent[nxt] = cell
                queue.append(nxt)
    raise ValueError(f"No route from cell {start} to cell {goal} in the maze.")


class Route:
    """A polyline route: :meth:`remaining` length to its end, :meth:`point_ahead` along it.

    A position is projected on the nearest segment (the first of equally near ones). Segments are
    precomputed: this runs every step (plain Python: a route has a handful of segments).

    Examples:
        >>> route = Route([(0.0, 0.0), (4.0, 0.0), (4.0, -4.0)])
        >>> route.remaining(1.0, 0.5)
        7.5
        >>> route.point_ahead(3.0, 0.5, 2.0)
        (4.0, -1.0)
    """

    def __init__(self, points: Sequence[Sequence[float]]) -> None:
        points = [(float(x), float(y)) for x, y in points]
        if len(points) < 2:
            raise ValueError(f"a route needs at least 2 points, got {len(points)}.")
        self.points = points
        segments = []
        after = 0.0
        for (ax, ay), (bx, by) in zip(points[-2::-1], points[:0:-1]):  # from the last segment back
            sx, sy = bx - ax, by - ay
            length = math.hypot(sx, sy)
            segments.append((ax, ay, sx, sy, length, max(length * length, 1e-12), after))
            after += length
        self._segments = segments[::-1]
        self.length = after

    def _project(self, x: float, y: float) -> tuple[int, float, float]:
        """The nearest segment's index, the projection's fraction ``t`` along it, and the distance to it."""
        best_off, best_k, best_t = math.inf, 0, 0.0
        for k, (ax, ay, sx, sy, _, length2, _) in enumerate(self._segments):
            t = ((x - ax) * sx + (y - ay) * sy) / length2
            t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
            off = math.hypot(x - ax - t * sx, y - ay - t * sy)
            if off < best_off:  # ties (a shared corner) give the same remaining length
                best_off, best_k, best_t = off, k, t
        return best_k, best_t, best_off

    def remaining(self, x: float, y: float) -> float:
        """Distance from ``(x, y)`` to its projection, plus the route's length from there to its end.

        A non-finite position (a simulation gone wrong) is infinitely far: ``inf``.
        """
        k, t, off = self._project(x, y)
        _, _, _, _, length, _, after = self._segments[k]
        return off + (1.0 - t) * length + after

    def point_ahead(self, x: float, y: float, distance: float) -> tuple[float, float]:
        """The point ``distance`` (>= 0) along the route from the projection of ``(x, y)`` (its end if nearer)."""
        if not distance >= 0.0:
            raise ValueError(f"distance must be >= 0 metres, got {distance}.")
        k, t, _ = self._project(x, y)
        _, _, _, _, length, _, after = self._segments[k]
        ahead = (1.0 - t) * length + after - distance  # the route left beyond the point
        if ahead <= 0.0:
            return self.points[-1]
        for ax, ay, sx, sy, length, _, after in self._segments[k:]:
            if ahead >= after:  # the point lies on this segment, ``ahead - after`` before its end
                u = 1.0 - (ahead - after) / length if length > 0.0 else 1.0
                return ax + u * sx, ay + u * sy
        return self.points[-1]


def route_remaining_length(route: Sequence[Sequence[float]], position: Sequence[float]) -> float:
    """Remaining length of a polyline route from a position to its end (see :class:`Route`).

    Examples:
        >>> route_remaining_length([(0.0, 0.0), (4.0, 0.0), (4.0, -4.0)], (1.0, 0.5))
        7.5
    """
    return Route(route).remaining(float(position[0]), float(position[1]))


def _remove_maze_xml(maze_env: Any) -> None:
    """Deletes the model file a gymnasium-robotics maze env left in the temp folder once MuJoCo read it.

    ``Maze.make_maze`` writes ``ant_maze<time>.xml`` next to (not inside) a temporary directory
    and never removes it: one 8 kB file per environment built, thousands over a test suite or a
    sweep. The model is loaded when the env is built, so the file is not needed afterwards.
    """
    with contextlib.suppress(OSError, AttributeError, TypeError):
        os.remove(maze_env.tmp_xml_file_path)


class _RoboticsTaskEnv(gym.Env):
    """A gymnasium-robotics environment with a flat observation, its own step limit and CSIRL info."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 20}
    max_steps: int = 0

    def __init__(self, render_mode: str | None = None) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}.")
        ensure_headless_gl(render_mode)
        self.render_mode = render_mode
        self._steps = 0
        self._initial_distance = 0.0

    # subclasses: _inner, _flatten(raw_obs) and _distance_and_success() -> (d, goal reached)
    def _info(self) -> dict[str, Any]:
        distance, success = self._distance_and_success()
        d0 = self._initial_distance
        progress = min(max(1.0 - distance / d0, 0.0), 1.0) if d0 > 0 else 1.0
        return {"distance_to_finish": distance, "progress": progress, "arrived": success, "success": success}

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        raw, _ = self._inner.reset(seed=seed, options=options)
        self._steps = 0
        self._on_reset()
        self._initial_distance = self._distance_and_success()[0]
        self._observation = self._flatten(raw)
        return self._observation.astype(np.float32), self._info()

    def observation(self) -> np.ndarray:
        """The current flat observation (float64; the env returns it as float32)."""
        return self._observation.copy()

    def _on_reset(self) -> None:
        pass

    def _inner_step(self, action) -> tuple[Any, float, bool]:
        raw, reward, terminated, _, _ = self._inner.step(action)
        return raw, reward, terminated

    def step(self, action):
        raw, reward, terminated = self._inner_step(action)
        self._steps += 1
        truncated = self._steps >= self.max_steps and not terminated
        self._observation = self._flatten(raw)
        return self._observation.astype(np.float32), float(reward), bool(terminated), bool(truncated), self._info()

    def render(self):
        return self._inner.render()

    def close(self) -> None:
        self._inner.close()
        super().close()


class AntMazeUMazeEnv(_RoboticsTaskEnv):
    """``AntMaze_UMaze-v5`` with D4RL's fixed start and goal; state = observation (27) + (x, y).

    Episodic (``continuing_task=False``: the episode terminates when the ant's (x, y) is within
    0.45 m of the goal, the sparse reward paying 1 there), contact forces left out of the
    observation, 700 steps. Start and goal carry +-0.1 m of noise.

    Examples:
        >>> env = AntMazeUMazeEnv()
        >>> obs, info = env.reset(seed=0)
        >>> obs.shape, round(info["distance_to_finish"])
        ((29,), 24)
    """

    max_steps = 700

    def __init__(self, render_mode: str | None = None, position_noise: float = ANTMAZE_POSITION_NOISE) -> None:
        super().__init__(render_mode)
        from gymnasium_robotics.envs.maze.ant_maze_v5 import AntMazeEnv

        self._inner = AntMazeEnv(
            render_mode=render_mode,
            maze_map=[list(row) for row in ANTMAZE_UMAZE_MAP],
            continuing_task=False,
            include_cfrc_ext_in_observation=False,
        )
        self._inner.position_noise_range = float(position_noise)
        _remove_maze_xml(self._inner)
        self.action_space = self._inner.action_space
        self.observation_space = spaces.Box(-np.inf, np.inf, (29,), np.float32)
        maze = self._inner.maze
        cells = maze_cell_route(ANTMAZE_UMAZE_MAP, self.start_cell, self.goal_cell)
        self.route_cells = cells
        self._route_points = [tuple(maze.cell_rowcol_to_xy(np.array(c)).tolist()) for c in cells]
        self._route = Route(self._route_points)

    start_cell = (1, 1)
    goal_cell = (3, 1)

    @property
    def goal(self) -> np.ndarray:
        """The goal (x, y) [m] of the current episode."""
        return np.asarray(self._inner.goal, dtype=np.float64)

    @property
    def maze(self) -> Any:
        """gymnasium-robotics' ``Maze`` (cells to coordinates and back, the map)."""
        return self._inner.maze

    def position(self) -> np.ndarray:
        """The ant's torso (x, y) [m]."""
        return np.asarray(self._inner.ant_env.data.qpos[:2], dtype=np.float64)

    def _on_reset(self) -> None:
        # the route ends at the (noisy) goal itself
        self._route = Route([*self._route_points[:-1], tuple(self.goal.tolist())])

    def _flatten(self, raw: dict | np.ndarray) -> np.ndarray:
        if isinstance(raw, dict):  # reset: AntMazeEnv's dict observation
            return np.concatenate([raw["observation"], raw["achieved_goal"]]).astype(np.float64)
        return raw  # _inner_step's, already flat

    def _inner_step(self, action) -> tuple[np.ndarray, float, bool]:
        """``AntMazeEnv.step`` for the episodic, fixed-goal task, with one distance per step.

        The ant steps exactly as in ``AntMazeEnv.step``; the sparse reward (1 within 0.45 m of
        the goal) and the termination there are computed from one ``hypot`` instead of three
        ``np.linalg.norm`` calls (``tests/test_robotics.py`` checks the trajectories are the
        raw environment's). The goal never moves (``continuing_task=False``).
        """
        ant_obs, _, _, _, _ = self._inner.ant_env.step(action)
        x, y = ant_obs[0], ant_obs[1]
        gx, gy = self._inner.goal
        reached = math.hypot(x - gx, y - gy) <= ANTMAZE_SUCCESS_RADIUS
        return np.concatenate([ant_obs[2:], ant_obs[:2]]), 1.0 if reached else 0.0, reached

    def _info(self) -> dict[str, Any]:
        return {**super()._info(), "crashed": is_flipped(self._inner.ant_env.data.qpos[3:7])}

    def _distance_and_success(self) -> tuple[float, bool]:
        x, y = self._inner.ant_env.data.qpos[:2]
        gx, gy = self._inner.goal
        success = math.hypot(x - gx, y - gy) <= ANTMAZE_SUCCESS_RADIUS
        return self._route.remaining(float(x), float(y)), bool(success)


class RelocateEnv(_RoboticsTaskEnv):
    """``AdroitHandRelocate-v1`` (dense reward, 39-value state, 30 actions, 200 steps).

    Never terminates (as gymnasium-robotics and D4RL); ``success`` marks the steps with the ball
    within 0.1 m of the target.

    Examples:
        >>> env = RelocateEnv()
        >>> obs, info = env.reset(seed=0)
        >>> obs.shape, env.action_space.shape, info["success"]
        ((39,), (30,), False)
    """

    max_steps = 200

    def __init__(self, render_mode: str | None = None) -> None:
        super().__init__(render_mode)
        from gymnasium_robotics.envs.adroit_hand.adroit_relocate import AdroitHandRelocateEnv

        self._inner = AdroitHandRelocateEnv(reward_type="dense", render_mode=render_mode)
        self.action_space = self._inner.action_space
        self.observation_space = spaces.Box(-np.inf, np.inf, (39,), np.float32)

    def _flatten(self, raw: np.ndarray) -> np.ndarray:
        return np.asarray(raw, dtype=np.float64)

    def _distance_and_success(self) -> tuple[float, bool]:
        inner = self._inner
        dx, dy, dz = inner.data.xpos[inner.obj_body_id] - inner.data.site_xpos[inner.target_obj_site_id]
        distance = math.sqrt(dx * dx + dy * dy + dz * dz)
        return distance, distance < RELOCATE_SUCCESS_RADIUS


@dataclass(frozen=True, kw_only=True)
class RoboticsTaskSpec(TaskSpec):
    """A robotics task (:class:`~torchrl_csirl.tasks.spec.TaskSpec`): overrides are constructor keywords.

    Attributes (besides :class:`~torchrl_csirl.tasks.spec.TaskSpec`'s):
        base_env: the gymnasium-robotics environment wrapped.
        env_options: the constructor keywords accepted as overrides.
        maze_map: the maze (rows of cells, ``1`` a wall; AntMaze) or ``None``; cell ``(row, col)``
            is centred at ``((col + 0.5) s - W s / 2, H s / 2 - (row + 0.5) s)`` with ``s`` =
            :attr:`maze_cell_size` [m] and ``H x W`` cells.
        maze_cell_size: the side of a maze cell [m].

    Examples:
        >>> from torchrl_csirl.tasks.robotics import ROBOTICS_TASKS
        >>> spec = ROBOTICS_TASKS["relocate"]
        >>> spec.obs_dim, spec.action_dim, spec.max_steps
        (39, 30, 200)
        >>> spec.matching_features[:2], spec.matching_features[-1]
        (('palm_to_object[0]', 'palm_to_object[1]'), 'object_to_target[2]')
    """

    base_env: str = ""
    env_options: tuple[str, ...] = ()
    maze_map: tuple[tuple[Any, ...], ...] | None = None
    maze_cell_size: float = 4.0

    def gym_make_kwargs(self, render_mode: str | None = None, **overrides: Any) -> dict[str, Any]:
        allowed = set(self.env_options)
        unknown = set(overrides) - allowed
        if unknown:
            raise ValueError(
                f"{self.name}: unknown environment options {sorted(unknown)}; accepted: {sorted(allowed)}."
            )
        kwargs = dict(overrides)
        if render_mode is not None:
            kwargs["render_mode"] = render_mode
        return kwargs


# the ant's 27 values: torso z, torso quaternion, 8 joint angles, torso linear and angular velocity,
# 8 joint velocities
ANT_LAYOUT: MappingProxyType = MappingProxyType({
    "z": (0, 1),
    "orientation": (1, 5),
    "joint_angles": (5, 13),
    "velocity": (13, 16),
    "angular_velocity": (16, 19),
    "joint_velocities": (19, 27),
})


def _antmaze_spec() -> RoboticsTaskSpec:
    # the ant's 27 values, then its (x, y)
    layout = {**ANT_LAYOUT, "x": (27, 28), "y": (28, 29)}
    return RoboticsTaskSpec(
        name="antmaze-umaze",
        gym_id="csirl/antmaze-umaze-v0",
        base_env="AntMaze_UMaze-v5",
        env_options=("position_noise",),
        maze_map=ANTMAZE_UMAZE_MAP,
        entry_point=f"{__name__}:AntMazeUMazeEnv",
        obs_dim=29,
        action_dim=8,
        max_steps=AntMazeUMazeEnv.max_steps,
        finish_position=(-4.0, -4.0),
        ego_feature_indices=(27, 28, 13, 14),
        position_feature_indices=(27, 28),
        matching_scale=100.0,
        dt=0.05,
        family="robotics",
        expert="torchrl_csirl.tasks.robotics.ant_goal:make_waypoint_ant_expert",
        observation_layout=MappingProxyType(layout),
        description="ant in D4RL's U-maze: start cell (1, 1) at (-4, 4), goal cell (3, 1) at (-4, -4)",
    )


def _relocate_spec() -> RoboticsTaskSpec:
    layout = {
        "hand_joints": (0, 30),
        "palm_to_object": (30, 33),
        "palm_to_target": (33, 36),
        "object_to_target": (36, 39),
    }
    return RoboticsTaskSpec(
        name="relocate",
        gym_id="csirl/relocate-v0",
        base_env="AdroitHandRelocate-v1",
        entry_point=f"{__name__}:RelocateEnv",
        obs_dim=39,
        action_dim=30,
        max_steps=RelocateEnv.max_steps,
        finish_position=None,
        episode_ends_at_goal=False,
        ego_feature_indices=tuple(range(30, 39)),
        position_feature_indices=(30, 31, 32, 36, 37, 38),
        matching_scale=100.0,
        dt=0.01,
        family="robotics",
        expert="torchrl_csirl.tasks.robotics.expert:make_relocate_expert",
        observation_layout=MappingProxyType(layout),
        description="Adroit hand picks up the ball and carries it to a random target (within 0.1 m)",
    )


ROBOTICS_TASKS: dict[str, RoboticsTaskSpec] = {spec.name: spec for spec in (_antmaze_spec(), _relocate_spec())}
