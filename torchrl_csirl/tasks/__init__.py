"""The paper's tasks: driving scenarios (highway-env based), robotics tasks, the metrics; and beyond the
paper gymnasium's MuJoCo locomotion (``hopper``, ``halfcheetah``: :mod:`torchrl_csirl.tasks.locomotion`).

Importing this package registers the gymnasium ids ``csirl/highway-fast-v0``,
``csirl/merge-v0``, ``csirl/roundabout-v0``, ``csirl/intersection-v0`` and the robotics tasks'
``csirl/antmaze-umaze-v0`` and ``csirl/relocate-v0`` (:mod:`torchrl_csirl.tasks.robotics`).

* :class:`TaskSpec`: what every task is (observation layout, matching features, finish/goal,
  episode limit); :data:`TASKS` all of them by name; :func:`register_task` adds your own (with the
  factory of its TorchRL environment), :func:`make_gymnasium_task` any gymnasium id with flat
  ``Box`` spaces.
* :data:`SCENARIOS` / :class:`ScenarioSpec`: the driving scenarios (plus the Kinematics feature
  ranges, the highway-env config, the published matching-reward scale).
* :func:`sample_lane_centres`: a driving scene's lane centre lines (``ScenarioSpec.lane_centres``).
* :func:`make_gym_env` (gymnasium), :func:`make_env` (TorchRL ``GymEnv``) and
  :func:`make_serial_env` (several copies in one process, e.g. per collector worker).
* :class:`YieldingParallelEnv`: a ``ParallelEnv`` whose main process sleeps while the workers step.
* :func:`accomplish_rate` and friends: the paper's evaluation metric.
"""
from __future__ import annotations

from torchrl_csirl._compat import gym_env_of
from torchrl_csirl.tasks.catalog import (
    SCENARIOS,
    TASKS,
    ScenarioSpec,
    make_gym_env,
    register_scenarios,
    resolve_scenario,
    sample_lane_centres,
    scenario_config_overrides,
)
from torchrl_csirl.tasks.gymnasium_env import make_gymnasium_env
from torchrl_csirl.tasks.gymnasium_task import make_gymnasium_task
from torchrl_csirl.tasks.info import FAILURE_KEYS, INFO_KEYS, info_spec
from torchrl_csirl.tasks.locomotion import LOCOMOTION_TASKS, LocomotionExpert, make_locomotion_env
from torchrl_csirl.tasks.metrics import (
    accomplish_rate,
    accomplish_rate_from_rollout,
    area_under_curve,
    episode_success,
    normalized_accomplish_rate,
    success_from_rollout,
)
from torchrl_csirl.tasks.parallel import YieldingParallelEnv
from torchrl_csirl.tasks.registry import env_factory, import_task_module, register_task, task_names
from torchrl_csirl.tasks.spec import TaskSpec
from torchrl_csirl.tasks.torchrl_env import make_env, make_serial_env

register_scenarios()

__all__ = [
    "FAILURE_KEYS",
    "INFO_KEYS",
    "LOCOMOTION_TASKS",
    "LocomotionExpert",
    "SCENARIOS",
    "ScenarioSpec",
    "TASKS",
    "TaskSpec",
    "accomplish_rate",
    "accomplish_rate_from_rollout",
    "area_under_curve",
    "episode_success",
    "gym_env_of",
    "env_factory",
    "import_task_module",
    "info_spec",
    "make_env",
    "make_gymnasium_env",
    "make_gymnasium_task",
    "make_locomotion_env",
    "make_gym_env",
    "make_serial_env",
    "normalized_accomplish_rate",
    "register_scenarios",
    "register_task",
    "resolve_scenario",
    "sample_lane_centres",
    "scenario_config_overrides",
    "success_from_rollout",
    "task_names",
    "YieldingParallelEnv",
]
