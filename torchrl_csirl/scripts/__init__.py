"""The scripts users run, as modules of the installed package: ``python -m torchrl_csirl.scripts.<name>``.

Each is what ``recipes/<name>.py`` in a checkout runs (the recipes are thin calls into these):

* ``csirl_highway`` / ``csirl_robotics``: CSIRL (and CSIRL-B) on a driving scene / robotics task;
* ``imitation_highway`` / ``imitation_robotics``: one baseline (``method=<name>``);
* ``benchmark``: the methods x tasks x seeds sweep on Ray, and its report (tables, t-tests, curves);
* ``watch``: videos of a trained agent; ``generate_experts``: expert demonstrations;
* ``train_ant_expert``: the AntMaze expert's goal-reaching ant; ``train_expert``: SAC on any task's
  own reward, then demonstrations of it;
* ``cli``: ``torchrl-csirl <command>``, which also runs the commands that read finished runs, their records or a
  saved policy: ``summarize``, ``compare``, ``curves``, ``record``, ``health_table`` (``health-table``),
  ``outcomes`` (``driving_outcomes``, ``robotics_outcomes``), ``off_demos`` (``off-demos``) and ``diagnose``.

Every training script takes ``key=value`` overrides of its typed schema (``--help`` lists them,
docs/configuration.md is generated from them), writes a run directory and ends with a JSON line.
"""
