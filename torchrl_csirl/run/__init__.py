"""The run layer: from a typed configuration to a finished, resumable run, for any method and task.

Configuration stops here: the rest of the package (``torchrl_csirl.objectives``, ``transforms``,
``trainers``, ...) takes plain arguments, and these modules turn a validated configuration into
those arguments, the way TorchRL's ``torchrl.trainers.algorithms`` pairs a trainer with its
config. The scripts users run (``recipes/*.py``, or ``python -m torchrl_csirl.scripts.<name>`` from
an installed wheel) are thin calls into this layer. Its modules:

* :mod:`torchrl_csirl.run.config`: the typed-configuration machinery (:func:`option`, presets
  and ``key=value`` overrides, validation with one-line :class:`ConfigError`, ``--help`` via
  :func:`~torchrl_csirl.run.config.describe`) and the sections every schema shares (``env``,
  ``collector``, ``expert``, ``replay_buffer``, ``model``, ``optim``, ``eval``, ``logger``,
  ``checkpoint``). Defaults live there, once.
* :mod:`torchrl_csirl.run.run`: the run directory (never overwritten), device, resume point,
  summary and the scripts' error handling (:func:`run_script`: SIGTERM and Ctrl-C checkpoint).
* :mod:`torchrl_csirl.run.recipes`: one registry of recipes (:class:`Recipe`: methods, schemas, presets,
  checks, trainer, finish); a method's recipe by name (:func:`recipe_for`).
* the shared builders, one concern each (gathered in :mod:`torchrl_csirl.run.builders`):
  :mod:`~torchrl_csirl.run.experts` (demonstrations), :mod:`~torchrl_csirl.run.collection`
  (environments, collector), :mod:`~torchrl_csirl.run.assembly` (buffer, logger, :class:`Run`, the trainer),
  :mod:`~torchrl_csirl.run.lifecycle` (start, resume, train, :func:`run_recipe`),
  :mod:`~torchrl_csirl.run.final` (the final test and summary).
* :mod:`torchrl_csirl.run.provenance`: a run's ``provenance.json`` (commit, dirty tree, package versions, CPU).
* :mod:`torchrl_csirl.run.processes`: a local sweep's cell processes (pid files; SIGTERM stops
  them at a checkpoint before the sweep exits).
* :mod:`torchrl_csirl.run.task_schemas`: the non-driving tasks' schema sections, the task a command line
  names and its schema family.
* :mod:`torchrl_csirl.run.video`: the final evaluation's video.

The methods themselves (:mod:`torchrl_csirl.methods`) are built on this layer and register their recipes
here; the registry imports them by name on its first look-up (:data:`~torchrl_csirl.run.recipes.RECIPE_MODULES`),
so nothing here imports a method.

:func:`recipe_schemas` names every recipe's schemas as ``module:class`` (the configuration reference in
the docs is generated from them).

Examples:
    >>> "torchrl_csirl.methods.csirl:CSIRLTaskConfig" in recipe_schemas()
    True
    >>> from torchrl_csirl.run import load_config_for
    >>> load_config_for("csirl")(["seed=3", "env.task=roundabout"]).env.task
    'roundabout'
"""
from torchrl_csirl.run.config import ConfigError, load_config, load_run_config, option
from torchrl_csirl.run.recipes import (
    Recipe,
    known_methods,
    load_config_for,
    recipe_for,
    recipe_schemas,
    register_recipe,
    registered_recipes,
)
from torchrl_csirl.run.run import ExpertDataError, resolve_device, run_script, write_summary

__all__ = [
    "ConfigError",
    "ExpertDataError",
    "Recipe",
    "known_methods",
    "load_config",
    "load_config_for",
    "load_run_config",
    "option",
    "recipe_for",
    "recipe_schemas",
    "register_recipe",
    "registered_recipes",
    "resolve_device",
    "run_script",
    "write_summary",
]
