"""The paper's robotics tasks on gymnasium-robotics: AntMaze U-maze and Adroit Relocate.

* :data:`ROBOTICS_TASKS` / :class:`RoboticsTaskSpec`: the tasks' specs (the same
  :class:`~torchrl_csirl.tasks.spec.TaskSpec` as the driving scenarios), reached through
  :func:`torchrl_csirl.tasks.make_env` (``"antmaze-umaze"``, ``"relocate"``).
* :class:`AntMazeUMazeEnv`, :class:`RelocateEnv`: the gymnasium environments.
* :class:`DAPGRelocatePolicy`: the shipped DAPG expert of Relocate.
* :class:`AntGoalEnv` (task ``"ant-goal"``) and :class:`WaypointAntExpert`: the AntMaze expert's
  training task and the waypoint controller driving the trained ant through the maze.
"""
from __future__ import annotations

from torchrl_csirl.tasks.robotics.ant_goal import (
    ANT_GOAL_SPEC,
    ANT_POLICY_PATH,
    AntGoalEnv,
    WaypointAntExpert,
    next_waypoint,
    pursuit_waypoint,
)
from torchrl_csirl.tasks.robotics.tasks import (
    ANTMAZE_UMAZE_MAP,
    ROBOTICS_TASKS,
    AntMazeUMazeEnv,
    RelocateEnv,
    RoboticsTaskSpec,
    is_flipped,
    maze_cell_route,
    route_remaining_length,
)

__all__ = [
    "ANT_GOAL_SPEC",
    "ANT_POLICY_PATH",
    "ANTMAZE_UMAZE_MAP",
    "AntGoalEnv",
    "WaypointAntExpert",
    "next_waypoint",
    "pursuit_waypoint",
    "ROBOTICS_TASKS",
    "AntMazeUMazeEnv",
    "RelocateEnv",
    "RoboticsTaskSpec",
    "is_flipped",
    "maze_cell_route",
    "route_remaining_length",
]
