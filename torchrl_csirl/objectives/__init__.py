"""Losses of the CSIRL learner (ensemble SAC, the meta-gradient reward loss, the actor's
behavioural-cloning term) and of the imitation baselines (docs/BASELINES.md)."""
from __future__ import annotations

from torchrl_csirl.objectives.behaviour_cloning import ActorBehaviourCloning
from torchrl_csirl.objectives.ensemble_sac import (
    EnsembleSACLoss,
    qvalue_dispersion,
    reinitialize_module,
)
from torchrl_csirl.objectives.meta_reward import MetaRewardLoss
from torchrl_csirl.objectives._imitation import SACHyperparameters, make_sac_learner, orthogonal_regularization
from torchrl_csirl.objectives.dac import (
    AbsorbingLogit,
    DACDiscriminatorLoss,
    DACHyperparameters,
    dac_discriminator_loss,
    make_dac_discriminator,
)
from torchrl_csirl.objectives.gail import GAILHyperparameters, gail_discriminator_input, make_gail_discriminator
from torchrl_csirl.objectives.sqil import SQILHyperparameters, sqil_batch, sqil_reward_labels

__all__ = [
    "AbsorbingLogit",
    "ActorBehaviourCloning",
    "DACDiscriminatorLoss",
    "DACHyperparameters",
    "GAILHyperparameters",
    "EnsembleSACLoss",
    "MetaRewardLoss",
    "SACHyperparameters",
    "SQILHyperparameters",
    "dac_discriminator_loss",
    "gail_discriminator_input",
    "make_dac_discriminator",
    "make_gail_discriminator",
    "make_sac_learner",
    "orthogonal_regularization",
    "qvalue_dispersion",
    "reinitialize_module",
    "sqil_batch",
    "sqil_reward_labels",
]
