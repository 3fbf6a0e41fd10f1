"""The robotics tasks' part of a recipe schema (AntMaze, Relocate): the sections that
``recipes/csirl_robotics.py`` and ``recipes/imitation_robotics.py`` put over their driving
recipe's schema (:class:`RoboticsSections`), and the checks both share.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

from omegaconf import DictConfig

from common import config as config_lib  # noqa: F401 - doctests
from common.config import CollectorConfig, ConfigError, ExpertConfig, ModelConfig, option
from torchrl_csirl.envs.robotics import ROBOTICS_TASKS

__all__ = ["RoboticsCollectorConfig", "RoboticsEnvConfig", "RoboticsExpertConfig", "RoboticsModelConfig",
           "RoboticsSections", "check_robotics_config", "resolve_task"]


@dataclass
class RoboticsEnvConfig:
    scenario: str = option("relocate", choices=tuple(ROBOTICS_TASKS), help="the robotics task")
    task: Optional[str] = option(None, choices=tuple(ROBOTICS_TASKS),
                                 help="the same as env.scenario (set either; null: env.scenario decides)")


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


def resolve_task(cfg: DictConfig, overrides: list[str] | None) -> None:
    """``env.task`` and ``env.scenario`` name the same thing: one value for both, or a ConfigError.

    Examples:
        >>> from common.csirl import CSIRLRoboticsConfig
        >>> cfg = config_lib.load_config(CSIRLRoboticsConfig, ["env.task=antmaze-umaze"])
        >>> resolve_task(cfg, ["env.task=antmaze-umaze"])
        >>> cfg.env.scenario, cfg.env.task
        ('antmaze-umaze', 'antmaze-umaze')
    """
    given = {key: value for key, _, value in (item.partition("=") for item in overrides or [])}
    task, scenario = given.get("env.task"), given.get("env.scenario")
    if task is not None and scenario is not None and task != scenario:
        raise ConfigError(f"env.task={task} and env.scenario={scenario}: the same setting, give one of them")
    if cfg.env.task is not None and task is not None:
        cfg.env.scenario = cfg.env.task
    cfg.env.task = cfg.env.scenario


def check_robotics_config(cfg: DictConfig, overrides: list[str] | None = None) -> DictConfig:
    """The checks every robotics recipe shares: ``env.task`` resolved, no ego-relative inputs."""
    resolve_task(cfg, overrides)
    if cfg.model.ego_relative_features:
        raise ConfigError("model.ego_relative_features=true: the other-vehicle offsets exist in driving scenes only")
    if cfg.model.lane_features:
        raise ConfigError("model.lane_features=true: lanes exist in driving scenes only")
    return cfg
