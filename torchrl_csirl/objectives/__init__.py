"""Losses of the CSIRL learner: ensemble SAC, the meta-gradient reward loss, and the actor's
behavioural-cloning term (a recipe option)."""
from __future__ import annotations

from torchrl_csirl.objectives.behaviour_cloning import ActorBehaviourCloning
from torchrl_csirl.objectives.ensemble_sac import (
    EnsembleSACLoss,
    qvalue_dispersion,
    reinitialize_module,
)
from torchrl_csirl.objectives.meta_reward import MetaRewardLoss

__all__ = ["ActorBehaviourCloning", "EnsembleSACLoss", "MetaRewardLoss", "qvalue_dispersion", "reinitialize_module"]
