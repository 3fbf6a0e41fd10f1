"""The recipe glue: everything the scripts in ``recipes/`` share, and every recipe's typed
configuration schema. Configuration stops here: the library (``torchrl_csirl``) takes plain
arguments, and these modules turn a validated configuration into those arguments.

Recipes (and the analysis scripts in ``tools/``) put ``recipes/`` on ``sys.path`` and import
``common``. Its modules:

* :mod:`common.config`: the typed-configuration machinery (:func:`~common.config.option`,
  loading presets and ``key=value`` overrides, validation, ``--help`` via
  :func:`~common.config.describe`) and the sections every schema shares (``env``,
  ``collector``, ``expert``, ``replay_buffer``, ``model``, ``optim``, ``eval``, ``logger``,
  ``checkpoint``).
* :mod:`common.run`: the run directory, device, resume point, summary and the scripts' error
  handling.
* :mod:`common.builders`: environments, collector, buffers, logging, evaluation, checkpoints and
  the trainer every recipe assembles (:func:`~common.builders.assemble_trainer`).
* :mod:`common.registry`: which recipe trains a method (its configuration loader by method name).
* :mod:`common.summaries`: finished runs' ``summary.json`` files, mean / std over seeds, Welch's test.
* :mod:`common.csirl`: CSIRL's schemas (driving and robotics) and its builders (learner, reward
  network, meta-gradient, curriculum, matching reward) for ``csirl_highway.py`` and
  ``csirl_robotics.py``.
* :mod:`common.imitation`: the baselines' schemas (driving and robotics) and builders for
  ``imitation_highway.py`` and ``imitation_robotics.py``.
* :mod:`common.robotics`: the robotics tasks' schema sections and checks, shared by both
  robotics recipes.
* :mod:`common.ant_expert`: the schema of ``train_ant_expert.py``.

:data:`RECIPE_SCHEMAS` names each recipe's schema as ``module:class`` (a configuration reference
imports it with ``recipes/`` on ``sys.path``, then reads :func:`common.config.describe` and
:func:`common.config.attribute_docs`).

Examples:
    >>> import importlib
    >>> module, _, name = RECIPE_SCHEMAS["csirl_highway"].partition(":")
    >>> getattr(importlib.import_module(module), name).__name__
    'CSIRLHighwayConfig'
"""

#: recipe script (``recipes/<name>.py``) -> its configuration schema, ``module:class``
RECIPE_SCHEMAS = {
    "csirl_highway": "common.csirl:CSIRLHighwayConfig",
    "csirl_robotics": "common.csirl:CSIRLRoboticsConfig",
    "imitation_highway": "common.imitation:ImitationHighwayConfig",
    "imitation_robotics": "common.imitation:ImitationRoboticsConfig",
    "train_ant_expert": "common.ant_expert:AntExpertConfig",
}
