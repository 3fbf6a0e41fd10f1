"""What every recipe shares: the typed configuration (:mod:`common.config`), the run's directory,
device, resume point and summary (:mod:`common.run`), the builders of environments, collector,
buffers, logging, evaluation and checkpoints (:mod:`common.builders`), and the method registry
(:mod:`common.registry`). Recipes put ``recipes/`` on ``sys.path`` and import ``common``.
"""
