"""The non-driving tasks' part of a recipe schema: the sections that ``recipes/csirl_robotics.py``
and ``recipes/imitation_robotics.py`` put over their driving recipe's schema
(:class:`RoboticsSections`), and the checks both share.

Besides the paper's robotics tasks (AntMaze, Relocate) these scripts run any other task: one
registered with :func:`~torchrl_csirl.tasks.register_task` in a module that ``env.module=`` imports,
or any gymnasium id with flat ``Box`` spaces (``env.gym_id=``, :func:`prepare_task`).
"""
from __future__ import annotations

import difflib
import os
from dataclasses import dataclass, field
from typing import Optional

from omegaconf import DictConfig, OmegaConf

from torchrl_csirl.run import config as config_lib  # noqa: F401 - doctests
from torchrl_csirl.run.config import (
    CollectorConfig,
    CommandLine,
    ConfigError,
    ExpertConfig,
    ModelConfig,
    option,
    parse_command_line,
)
from torchrl_csirl.tasks import import_task_module, make_gymnasium_task, resolve_scenario, task_names
from torchrl_csirl.tasks.robotics import ANT_GOAL_SPEC

__all__ = ["RoboticsCollectorConfig", "RoboticsEnvConfig", "RoboticsExpertConfig", "RoboticsModelConfig",
           "RoboticsSections", "check_task_sections", "name_task", "prepare_task", "requested_task", "schema_family",
           "task_choices"]


def task_choices() -> tuple[str, ...]:
    """The tasks these scripts run: every task but the driving scenes (and the ant expert's own)."""
    return tuple(name for name in task_names(driving=False) if name != ANT_GOAL_SPEC.name)


@dataclass
class RoboticsEnvConfig:
    task: str = option("relocate", choices=task_choices,
                       help="the task: a robotics task, one of your own (env.module), or env.gym_id's "
                            "(env.scenario: deprecated spelling)")
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


def _saved_env(run_dir: str | None) -> dict[str, str]:
    """A run directory's saved ``env`` section as ``{env.<key>: value as written}`` (empty: no run, or no such file);
    a saved ``env.scenario`` (the deprecated name) read as ``env.task``."""
    if run_dir is None or not os.path.isfile(os.path.join(run_dir, "config.yaml")):
        return {}
    env = OmegaConf.to_container(OmegaConf.load(os.path.join(run_dir, "config.yaml"))).get("env") or {}
    if env.get("task") is None and "scenario" in env:
        env["task"] = env["scenario"]
    return {f"env.{k}": ("null" if v is None else str(v)) for k, v in env.items() if k != "scenario"}


def name_task(command: CommandLine, run_dir: str | None = None,
              default_task: str | None = None) -> tuple[CommandLine, str | None]:
    """The task of a parsed command line, registered before the configuration is loaded: (the command line with
    ``env.task`` set where it follows from the line, the task's name; None: the schema's default).

    ``env.module`` is imported (its :func:`~torchrl_csirl.tasks.register_task` calls run);
    ``env.gym_id`` becomes a task (:func:`~torchrl_csirl.tasks.make_gymnasium_task`) with
    ``env.features`` and ``env.success``, and ``env.task`` is set to it. Resuming (``run_dir``),
    the run's saved ``env`` section is read under the command line; ``default_task``: a new run's task when the
    line names none.

    Raises:
        ConfigError: one line: a module that does not import, an id that is not a flat-Box gymnasium
            environment, bad feature indices, or ``env.task`` naming another task than ``env.gym_id``.
    """
    given = {**_saved_env(run_dir), **command.values}
    module = given.get("env.module", "null")
    gym_id = given.get("env.gym_id", "null")
    try:
        if module != "null":
            import_task_module(module)
        if gym_id != "null":
            features, success = given.get("env.features", "null"), given.get("env.success", "null")
            make_gymnasium_task(gym_id, features=None if features == "null" else features,
                                success=None if success == "null" else success)
    except ValueError as err:
        raise ConfigError(str(err)) from None
    if gym_id != "null":
        named = command.get("env.task")
        if named is not None and named != gym_id:
            raise ConfigError(f"env.task={named} and env.gym_id={gym_id}: the task is the gymnasium id; give one of them")
        if run_dir is None:
            command = command.with_values({"env.task": gym_id})
        return command, gym_id
    task = given.get("env.task", "null")
    if task != "null":
        return command, task
    if default_task is not None and run_dir is None:
        return command.with_values({"env.task": default_task}), default_task
    return command, None


def prepare_task(overrides: list[str] | None, run_dir: str | None = None) -> list[str]:
    """:func:`name_task` on ``key=value`` strings: registers the task they name; returns them (one per key, with
    ``env.task`` set to an ``env.gym_id``).

    Examples:
        >>> prepare_task(["env.gym_id=MountainCarContinuous-v0", "env.features=0"])
        ['env.gym_id=MountainCarContinuous-v0', 'env.features=0', 'env.task=MountainCarContinuous-v0']
    """
    return name_task(parse_command_line(overrides), run_dir)[0].strings()


def requested_task(overrides: list[str] | CommandLine | None, run_dir: str | None = None) -> str | None:
    """The task a command line names (``env.gym_id`` or ``env.task``, over a resumed run's saved ``env`` section);
    None when it names none.

    Examples:
        >>> requested_task(["seed=1", "env.task=relocate"]), requested_task(["seed=1"])
        ('relocate', None)
    """
    given = {**_saved_env(run_dir), **parse_command_line(overrides).values}
    for key in ("env.gym_id", "env.task"):
        if given.get(key, "null") != "null":
            return given[key]
    return None


def schema_family(task: str) -> str:
    """``"driving"`` for a driving scene, ``"task"`` for any other registered task: which of a recipe's two
    schemas configures it (:class:`~torchrl_csirl.run.recipes.Recipe`).

    Raises:
        ConfigError: an unknown task, with the known ones and how to bring one's own.

    Examples:
        >>> schema_family("merge"), schema_family("hopper")
        ('driving', 'task')
        >>> schema_family("mergee")  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        torchrl_csirl.run.config.ConfigError: env.task=mergee: unknown task (did you mean merge?); one of ...
    """
    try:
        family = resolve_scenario(task).family
    except ValueError:
        names = task_names()
        close = difflib.get_close_matches(task, names, n=1)
        hint = f" (did you mean {close[0]}?)" if close else ""
        raise ConfigError(f"env.task={task}: unknown task{hint}; one of {', '.join(names)}, or env.gym_id=<a gymnasium "
                          "id>, or env.module=<a module that registers yours>") from None
    return "driving" if family == "driving" else "task"


def check_task_sections(cfg: DictConfig) -> DictConfig:
    """The checks of a non-driving schema (a no-op on a driving one): no driving inputs."""
    if "gym_id" not in cfg.env or "model" not in cfg:
        return cfg
    if cfg.model.ego_relative_features:
        raise ConfigError("model.ego_relative_features=true: the other-vehicle offsets exist in driving scenes only")
    if cfg.model.lane_features:
        raise ConfigError("model.lane_features=true: lanes exist in driving scenes only")
    return cfg
