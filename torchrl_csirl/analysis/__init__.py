"""What finished runs say: their health, their pictures, their summaries over seeds and the verdicts between methods.

* :mod:`torchrl_csirl.analysis.diagnostics`: why a run failed, its health report (``health.json``, ``health.png``).
* :mod:`torchrl_csirl.analysis.visualization`: pictures of a run (learning curve, curriculum, scene, videos).
* :mod:`torchrl_csirl.analysis.summaries`: finished runs' ``summary.json`` files, mean / std over seeds.
* :mod:`torchrl_csirl.analysis.verdicts`: the one rule for verdict words (Welch's test, Holm's correction, the
  minimum detectable difference, the seeds a difference needs).

This package's ``__init__`` imports none of them (the pictures need matplotlib, the summaries only the standard library).
"""
