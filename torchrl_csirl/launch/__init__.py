"""The run layer: from a typed configuration to a finished, resumable run, for any method and task.

Configuration stops here: the rest of the package (``torchrl_csirl.objectives``, ``transforms``,
``trainers``, ...) takes plain arguments, and these modules turn a validated configuration into
those arguments, the way TorchRL's ``torchrl.trainers.algorithms`` pairs a trainer with its
config. The scripts users run (``recipes/*.py``, or ``python -m torchrl_csirl.scripts.<name>`` from
an installed wheel) are thin calls into this layer. Its modules:

* :mod:`torchrl_csirl.launch.config`: the typed-configuration machinery (:func:`option`, presets
  and ``key=value`` overrides, validation with one-line :class:`ConfigError`, ``--help`` via
  :func:`~torchrl_csirl.launch.config.describe`) and the sections every schema shares (``env``,
  ``collector``, ``expert``, ``replay_buffer``, ``model``, ``optim``, ``eval``, ``logger``,
  ``checkpoint``). Defaults live there, once.
* :mod:`torchrl_csirl.launch.run`: the run directory (never overwritten), device, resume point,
  summary and the scripts' error handling (:func:`run_script`: SIGTERM and Ctrl-C checkpoint).
* :mod:`torchrl_csirl.launch.builders`: environments, collector, buffers, logging, evaluation,
  checkpoints and the trainer every method assembles (:func:`open_run`, :func:`train_and_finish`).
* :mod:`torchrl_csirl.launch.registry`: which schema trains a method (its loader by method name).
* :mod:`torchrl_csirl.launch.summaries`: finished runs' ``summary.json`` files, mean / std over
  seeds, Welch's test.
* :mod:`torchrl_csirl.launch.processes`: a local sweep's cell processes (pid files; SIGTERM stops
  them at a checkpoint before the sweep exits).
* :mod:`torchrl_csirl.launch.csirl` / :mod:`torchrl_csirl.launch.imitation`: CSIRL's and the
  baselines' schemas (driving and robotics) and builders.
* :mod:`torchrl_csirl.launch.robotics`: the robotics tasks' schema sections and checks.
* :mod:`torchrl_csirl.launch.ant_expert` / :mod:`torchrl_csirl.launch.expert_training`: the schemas of
  the AntMaze expert's training and of an expert for any task (SAC, then its demonstrations).
* :mod:`torchrl_csirl.launch.video`: the final evaluation's video.

:data:`RECIPE_SCHEMAS` names each script's schema as ``module:class`` (the configuration
reference in the docs is generated from it).

Examples:
    >>> import importlib
    >>> module, _, name = RECIPE_SCHEMAS["csirl_highway"].partition(":")
    >>> getattr(importlib.import_module(module), name).__name__
    'CSIRLHighwayConfig'
    >>> from torchrl_csirl.launch import load_config_for
    >>> load_config_for("csirl")(["seed=3", "env.scenario=roundabout"]).env.scenario
    'roundabout'
"""
from torchrl_csirl.launch.config import ConfigError, load_config, load_run_config, option
from torchrl_csirl.launch.registry import known_methods, load_config_for, register_recipe
from torchrl_csirl.launch.run import ExpertDataError, resolve_device, run_script, write_summary

__all__ = [
    "RECIPE_SCHEMAS",
    "ConfigError",
    "ExpertDataError",
    "known_methods",
    "load_config",
    "load_config_for",
    "load_run_config",
    "option",
    "register_recipe",
    "resolve_device",
    "run_script",
    "write_summary",
]

#: script (``recipes/<name>.py`` = ``torchrl_csirl.scripts.<name>``) -> its configuration schema, ``module:class``
RECIPE_SCHEMAS = {
    "csirl_highway": "torchrl_csirl.launch.csirl:CSIRLHighwayConfig",
    "csirl_robotics": "torchrl_csirl.launch.csirl:CSIRLRoboticsConfig",
    "imitation_highway": "torchrl_csirl.launch.imitation:ImitationHighwayConfig",
    "imitation_robotics": "torchrl_csirl.launch.imitation:ImitationRoboticsConfig",
    "train_ant_expert": "torchrl_csirl.launch.ant_expert:AntExpertConfig",
    "train_expert": "torchrl_csirl.launch.expert_training:ExpertTrainingConfig",
}
