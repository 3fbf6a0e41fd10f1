"""Losses of the CSIRL learner: ensemble SAC and the meta-gradient reward loss."""
from __future__ import annotations

from torchrl_csirl.objectives.ensemble_sac import (
    EnsembleSACLoss,
    qvalue_dispersion,
    reinitialize_module,
)
from torchrl_csirl.objectives.meta_reward import MetaRewardLoss

__all__ = ["EnsembleSACLoss", "MetaRewardLoss", "qvalue_dispersion", "reinitialize_module"]
