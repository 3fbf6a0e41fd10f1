"""The paper's comparison as a package: methods x scenarios x seeds, its sweep, tables and curves, one concern a
module (``python recipes/benchmark.py``, :mod:`torchrl_csirl.scripts.benchmark`, is the command line over them):

* :mod:`torchrl_csirl.sweep.published`: the published numbers set beside ours (the paper's Table I,
  IQ-Learn's Table 3 on the locomotion tasks).
* :mod:`torchrl_csirl.sweep.plan`: the table's rows and columns, every cell's budget and settings, the
  sweep's cells (one recipe command line each).
* :mod:`torchrl_csirl.sweep.runner`: running the cells as Ray Tune trials (local Ray or a cluster).
* :mod:`torchrl_csirl.sweep.results`: finished runs read into the table's rows (mean ± std over seeds,
  the difference from ``csirl``).
* :mod:`torchrl_csirl.sweep.report`: the rows as Markdown tables and CSV.
* :mod:`torchrl_csirl.sweep.curves`: the learning-curve figures.

The modules import nothing from here: this package's ``__init__`` loads none of them.
"""
