"""torchrl-csirl: Curricular Subgoals for Inverse Reinforcement Learning as TorchRL components.

Subpackages:

* :mod:`torchrl_csirl.objectives` -- the ensemble SAC objective and the meta-gradient reward loss.
* :mod:`torchrl_csirl.transforms` -- the subgoal matching reward and the learned intrinsic reward.
* :mod:`torchrl_csirl.curriculum` -- uncertainty-driven curricular subgoal selection.
* :mod:`torchrl_csirl.data` -- expert demonstrations: container, on-disk format, importers.
* :mod:`torchrl_csirl.modules` -- network builders (actor, critic ensemble, reward network).
* :mod:`torchrl_csirl.tasks` -- the paper's driving scenarios and the accomplish-rate metric.
"""
from __future__ import annotations

__version__ = "0.1.0"

from torchrl_csirl import _moved

_moved.install()
