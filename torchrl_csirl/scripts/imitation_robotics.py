"""One baseline on a robotics task: ``python recipes/imitation_robotics.py method=<name> env.task=relocate [key=value ...]``.

The driving baselines' recipe (``recipes/imitation_highway.py``) on the paper's robotics tasks
(``env.task=relocate | antmaze-umaze``, also spelled ``env.scenario``): the same methods,
budget, networks, demonstrations, evaluation, outputs, checkpoints and final JSON line, with the
robotics sections of ``recipes/csirl_robotics.py`` (the task's shipped 25 expert trajectories,
``model.ego_relative_features=false``, ``collector.frames_per_batch=1400``). Two rows differ
from driving: ``sac`` learns from the environment's own reward (the task's true reward:
Relocate's dense reward, AntMaze's goal indicator) and ``expert`` is the task's expert (the DAPG
hand, the waypoint-driven ant; docs/experts.md). The summary's ``return`` is the paper's metric
here. See docs/studies/robotics.md.

Example (BC on Relocate; ``python recipes/imitation_robotics.py --help`` lists every key)::

    python recipes/imitation_robotics.py method=bc env.task=relocate seed=0 collector.main_threads=1
"""
from __future__ import annotations

from functools import partial

from omegaconf import DictConfig

from torchrl_csirl.launch.imitation import ImitationRoboticsConfig, load_baseline_config
from torchrl_csirl.launch.robotics import check_robotics_config, prepare_task
from torchrl_csirl.launch.run import run_script
from torchrl_csirl.scripts import imitation_highway

__all__ = ["ImitationRoboticsConfig", "load_config", "load_run_config", "main"]

CSIRL_RECIPE = "recipes/csirl_robotics.py"


def load_config(overrides: list[str] | None = None) -> DictConfig:
    """The defaults and ``key=value`` overrides (``method=<name>`` required).

    Examples:
        >>> cfg = load_config(["method=bc", "env.task=antmaze-umaze"])
        >>> cfg.method, cfg.env.scenario, cfg.collector.frames_per_batch, cfg.model.ego_relative_features
        ('bc', 'antmaze-umaze', 1400, False)
    """
    overrides = prepare_task(overrides)
    return check_robotics_config(
        load_baseline_config(ImitationRoboticsConfig, overrides, csirl_recipe=CSIRL_RECIPE), overrides)


def load_run_config(run_dir: str, overrides: list[str] | None = None) -> DictConfig:
    """The configuration saved in ``run_dir/config.yaml``, updated by ``overrides`` (resume)."""
    overrides = prepare_task(overrides, run_dir)
    return check_robotics_config(
        load_baseline_config(ImitationRoboticsConfig, overrides, run_dir, CSIRL_RECIPE), overrides)


main = partial(imitation_highway.main, schema=ImitationRoboticsConfig, doc=__doc__, load=load_config,
               load_run=load_run_config)


if __name__ == "__main__":
    run_script(main)
