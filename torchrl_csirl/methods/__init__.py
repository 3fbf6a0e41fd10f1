"""The methods a run trains, one module per family: its configuration sections, its builders, its finish and its
recipe (:class:`~torchrl_csirl.run.recipes.Recipe`, registered on import).

* :mod:`torchrl_csirl.methods.csirl`: CSIRL (``csirl``, ``csirl-b``), a schema for the
  driving scenes and one for every other task; its presets in ``methods/config/``.
* :mod:`torchrl_csirl.methods.baselines`: the baselines (``bc``, ``gail``, ``dac``, ``valuedice``, ``sqil``,
  ``iqlearn``, ``sac``, the ``expert`` and ``random`` rows), one module as they share their builders.
* :mod:`torchrl_csirl.methods.expert`: an expert for any task (SAC, then its demonstrations).
* :mod:`torchrl_csirl.methods.ant_expert`: the AntMaze expert's training.

They import the run layer (:mod:`torchrl_csirl.run`), never the other way round; this package's ``__init__``
imports none of them (the run layer's registry does, by name, on its first look-up).

Examples:
    >>> from torchrl_csirl.run import recipe_for
    >>> recipe_for("gail").script
    'torchrl_csirl.scripts.imitation_highway'
"""
