"""CSIRL on a robotics task, end to end: ``python recipes/csirl_robotics.py env.task=relocate [key=value ...]``.

The driving recipe (``recipes/csirl_highway.py``) on the paper's robotics tasks
(``env.task=relocate | antmaze-umaze``, also spelled ``env.scenario``, docs/scenarios.md): the same learner, matching
reward, curriculum, meta-learned reward, outputs, logging, checkpoints, resume and final JSON
line; the task's spec supplies the dimensions, the matching features ``h(s)`` and the episode
limit. Differences from the driving recipe's configuration:

* ``expert.curriculum=expert``: the task's shipped file (Relocate: 25 DAPG trajectories; AntMaze:
  25 trajectories of the waypoint-driven ant, docs/experts.md), or ``expert.path=<.npz>``;
* ``model.ego_relative_features=false`` (that input map is the driving scenes');
* ``collector.frames_per_batch=1400`` so that each of 2 workers' environments runs whole
  AntMaze episodes (700 steps; collection resets every environment at each batch start);
* the summary's ``return`` is the paper's metric here (the mean test return); the accomplish
  rate is the task's progress measure; the curriculum picture is the maze from above with the
  subgoals (AntMaze) or the matching features along the curriculum trajectory (Relocate).

Budgets are not tuned yet (docs/studies/robotics.md, docs/studies/index.md).

Any other task runs here too (docs/own-task.md): ``env.gym_id=MountainCarContinuous-v0
expert.path=<.npz or minari:<id>>`` for a gymnasium id with flat ``Box`` spaces (``env.features``
picks the matching features, ``env.success`` the success flag), or ``env.module=<module>
env.scenario=<name>`` for a task the module registers with ``register_task``.
"""
from __future__ import annotations

from functools import partial

from omegaconf import DictConfig

from torchrl_csirl.launch import config as config_lib
from torchrl_csirl.launch.builders import Run, check_collector
from torchrl_csirl.launch.csirl import CSIRLRoboticsConfig, learner_precision
from torchrl_csirl.launch.robotics import check_robotics_config, prepare_task
from torchrl_csirl.launch.run import run_script
from torchrl_csirl.scripts import csirl_highway

__all__ = ["CSIRLRoboticsConfig", "load_config", "load_run_config", "main"]


def _check(cfg: DictConfig, overrides: list[str] | None = None) -> DictConfig:
    check_collector(cfg.collector)
    learner_precision(cfg)
    return check_robotics_config(cfg, overrides)


def load_config(overrides: list[str] | None = None) -> DictConfig:
    """Defaults and ``key=value`` overrides (``preset=default`` only).

    Examples:
        >>> cfg = load_config(["env.scenario=relocate", "seed=2"])
        >>> cfg.env.scenario, cfg.expert.curriculum, cfg.model.ego_relative_features
        ('relocate', 'expert', False)
    """
    overrides = prepare_task(overrides)
    return _check(config_lib.load_config(CSIRLRoboticsConfig, overrides), overrides)


def load_run_config(run_dir: str, overrides: list[str] | None = None) -> DictConfig:
    """The configuration saved in ``run_dir/config.yaml``, updated by ``overrides`` (resume)."""
    overrides = prepare_task(overrides, run_dir)
    return _check(config_lib.load_run_config(CSIRLRoboticsConfig, run_dir, overrides), overrides)


def build(argv: list[str]) -> Run:
    """As the driving recipe's, with this recipe's configuration."""
    return csirl_highway.build(argv, load=load_config, load_run=load_run_config)


def finish(run: Run) -> dict[str, object]:
    """As the driving recipe's, with the task's curriculum picture (the maze, or the matching features)."""
    from torchrl_csirl.visualization import plot_robotics_curriculum

    return csirl_highway.finish(run, picture=plot_robotics_curriculum)


main = partial(csirl_highway.main, schema=CSIRLRoboticsConfig, doc=__doc__, build_run=build, finish_run=finish)


if __name__ == "__main__":
    run_script(main)
