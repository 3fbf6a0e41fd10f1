"""The non-driving tasks' part of a recipe schema: the sections that ``recipes/csirl_robotics.py``
and ``recipes/imitation_robotics.py`` put over their driving recipe's schema
(:class:`RoboticsSections`), and the checks both share.

Besides the paper's robotics tasks (AntMaze, Relocate) these scripts run any other task: one
registered with :func:`~torchrl_csirl.envs.register_task` in a module that ``env.module=`` imports,
or any gymnasium id with flat ``Box`` spaces (``env.gym_id=``, :func:`prepare_task`).
"""
from __future__ import annotations

import difflib
import os
from dataclasses import dataclass, field
from typing import Optional

from omegaconf import DictConfig, OmegaConf

from torchrl_csirl.envs import import_task_module, make_gymnasium_task, resolve_scenario, task_names
from torchrl_csirl.envs.robotics import ANT_GOAL_SPEC
from torchrl_csirl.launch import config as config_lib  # noqa: F401 - doctests
from torchrl_csirl.launch.config import CollectorConfig, ConfigError, ExpertConfig, ModelConfig, option, override_strings

__all__ = ["RoboticsCollectorConfig", "RoboticsEnvConfig", "RoboticsExpertConfig", "RoboticsModelConfig",
           "RoboticsSections", "check_task_sections", "prepare_task", "requested_task", "resolve_task", "schema_family",
           "task_choices"]


def task_choices() -> tuple[str, ...]:
    """The tasks these scripts run: every task but the driving scenes (and the ant expert's own)."""
    return tuple(name for name in task_names(driving=False) if name != ANT_GOAL_SPEC.name)


@dataclass
class RoboticsEnvConfig:
    scenario: str = option("relocate", choices=task_choices,
                           help="the task: a robotics task, one of your own (env.module), or env.gym_id's")
    task: Optional[str] = option(None, choices=task_choices,
                                 help="the same as env.scenario (set either; null: env.scenario decides)")
    gym_id: Optional[str] = option(
        None, help="any gymnasium id with flat Box spaces (e.g. MountainCarContinuous-v0): the task, by that name")
    features: Optional[str] = option(
        None, help="env.gym_id: the matching features h(s), observation indices such as 0,2 or names (null: "
                   "achieved_goal for a goal-conditioned task, else all entries)")
    success: Optional[str] = option(
        None, help="env.gym_id: evaluation's success flag: termination | none | the name of an info entry "
                   "(null: the env's info success for a goal-conditioned task, else termination)")
    module: Optional[str] = option(
        None, help="a module to import first (dotted name): it registers tasks of your own with register_task")


@dataclass
class RoboticsExpertConfig(ExpertConfig):
    curriculum: str = option("expert", choices=("expert",),
                             help="the shipped file (Relocate: 25 DAPG trajectories; AntMaze: 25 of the "
                                  "waypoint-driven ant); trajectory 0 is the curriculum")


@dataclass
class RoboticsModelConfig(ModelConfig):
    ego_relative_features: bool = option(False, help="must stay false: the other-vehicle offsets are the driving scenes'")


@dataclass
class RoboticsCollectorConfig(CollectorConfig):
    frames_per_batch: int = option(1400, above=0, help="frames per collected batch (AntMaze: >= 700 per environment)")


@dataclass
class RoboticsSections:
    """The sections a robotics recipe's schema puts over its driving recipe's (a base listed first)."""

    env: RoboticsEnvConfig = field(default_factory=RoboticsEnvConfig)
    model: RoboticsModelConfig = field(default_factory=RoboticsModelConfig)
    collector: RoboticsCollectorConfig = field(default_factory=RoboticsCollectorConfig)


def _saved_env(run_dir: str | None) -> dict:
    """A run directory's saved ``env`` section (empty: no run, or no such file)."""
    if run_dir is None or not os.path.isfile(os.path.join(run_dir, "config.yaml")):
        return {}
    return OmegaConf.to_container(OmegaConf.load(os.path.join(run_dir, "config.yaml"))).get("env") or {}


def prepare_task(overrides: list[str] | None, run_dir: str | None = None) -> list[str]:
    """Registers the task the configuration names before it is checked; returns the overrides.

    ``env.module`` is imported (its :func:`~torchrl_csirl.envs.register_task` calls run);
    ``env.gym_id`` becomes a task (:func:`~torchrl_csirl.envs.make_gymnasium_task`) with
    ``env.features`` and ``env.success``, and ``env.scenario`` is set to it. Resuming (``run_dir``),
    the run's saved ``env`` section is read first.

    Raises:
        ConfigError: one line: a module that does not import, an id that is not a flat-Box gymnasium
            environment, bad feature indices, or ``env.scenario`` naming another task.

    Examples:
        >>> prepare_task(["env.gym_id=MountainCarContinuous-v0", "env.features=0"])
        ['env.gym_id=MountainCarContinuous-v0', 'env.features=0', 'env.scenario=MountainCarContinuous-v0']
    """
    overrides = list(overrides or [])
    given = {**{f"env.{k}": ("null" if v is None else str(v)) for k, v in _saved_env(run_dir).items()},
             **override_strings(overrides)}
    module = given.get("env.module", "null")
    try:
        if module != "null":
            import_task_module(module)
        gym_id = given.get("env.gym_id", "null")
        if gym_id == "null":
            return overrides
        features = given.get("env.features", "null")
        success = given.get("env.success", "null")
        make_gymnasium_task(gym_id, features=None if features == "null" else features,
                            success=None if success == "null" else success)
    except ValueError as err:
        raise ConfigError(str(err)) from None
    named = override_strings(overrides)
    for key in ("env.scenario", "env.task"):
        if named.get(key, gym_id) != gym_id:
            raise ConfigError(f"{key}={named[key]} and env.gym_id={gym_id}: the task is the gymnasium id; give one of them")
    if run_dir is None and "env.scenario" not in named:
        overrides.append(f"env.scenario={gym_id}")
    return overrides


def requested_task(overrides: list[str] | None, run_dir: str | None = None) -> str | None:
    """The task a command line names (``env.gym_id``, ``env.task`` or ``env.scenario``, over a resumed
    run's saved ``env`` section); None when it names none.

    Examples:
        >>> requested_task(["seed=1", "env.task=relocate"]), requested_task(["seed=1"])
        ('relocate', None)
    """
    given = {**{f"env.{k}": ("null" if v is None else str(v)) for k, v in _saved_env(run_dir).items()},
             **override_strings(overrides)}
    for key in ("env.gym_id", "env.task", "env.scenario"):
        if given.get(key, "null") != "null":
            return given[key]
    return None


def schema_family(task: str) -> str:
    """``"driving"`` for a driving scene, ``"task"`` for any other registered task: which of a recipe's two
    schemas configures it (:class:`~torchrl_csirl.launch.recipes.Recipe`).

    Raises:
        ConfigError: an unknown task, with the known ones and how to bring one's own.

    Examples:
        >>> schema_family("merge"), schema_family("hopper")
        ('driving', 'task')
        >>> schema_family("mergee")  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        torchrl_csirl.launch.config.ConfigError: env.scenario=mergee: unknown task (did you mean merge?); one of ...
    """
    try:
        family = resolve_scenario(task).family
    except ValueError:
        names = task_names()
        close = difflib.get_close_matches(task, names, n=1)
        hint = f" (did you mean {close[0]}?)" if close else ""
        raise ConfigError(f"env.scenario={task}: unknown task{hint}; one of {', '.join(names)}, or env.gym_id=<a gymnasium "
                          "id>, or env.module=<a module that registers yours>") from None
    return "driving" if family == "driving" else "task"


def resolve_task(cfg: DictConfig, overrides: list[str] | None) -> None:
    """``env.task`` and ``env.scenario`` name the same thing: one value for both, or a ConfigError.

    Examples:
        >>> from torchrl_csirl.launch.csirl import CSIRLRoboticsConfig
        >>> cfg = config_lib.load_config(CSIRLRoboticsConfig, ["env.task=antmaze-umaze"])
        >>> resolve_task(cfg, ["env.task=antmaze-umaze"])
        >>> cfg.env.scenario, cfg.env.task
        ('antmaze-umaze', 'antmaze-umaze')
    """
    given = override_strings(overrides)
    task, scenario = given.get("env.task"), given.get("env.scenario")
    if task is not None and scenario is not None and task != scenario:
        raise ConfigError(f"env.task={task} and env.scenario={scenario}: the same setting, give one of them")
    if cfg.env.task is not None and task is not None:
        cfg.env.scenario = cfg.env.task
    cfg.env.task = cfg.env.scenario


def check_task_sections(cfg: DictConfig, overrides: list[str] | None = None) -> DictConfig:
    """The checks of a non-driving schema (a no-op on a driving one): ``env.task`` resolved, no driving inputs."""
    if "task" not in cfg.env:
        return cfg
    resolve_task(cfg, overrides)
    if "model" not in cfg:
        return cfg
    if cfg.model.ego_relative_features:
        raise ConfigError("model.ego_relative_features=true: the other-vehicle offsets exist in driving scenes only")
    if cfg.model.lane_features:
        raise ConfigError("model.lane_features=true: lanes exist in driving scenes only")
    return cfg
