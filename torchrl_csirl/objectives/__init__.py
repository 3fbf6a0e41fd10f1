"""Losses of the CSIRL learner (ensemble SAC, the meta-gradient reward loss, the actor's
behavioural-cloning term; :func:`make_csirl_learner` builds them all) and of the imitation
baselines (docs/baselines.md)."""
from __future__ import annotations

from torchrl_csirl.objectives._imitation import SACHyperparameters, make_sac_learner, orthogonal_regularization
from torchrl_csirl.objectives.behaviour_cloning import ActorBehaviourCloning, pretrain_actor
from torchrl_csirl.objectives.csirl_learner import CSIRL_DEFAULTS, CSIRLHyperparameters, CSIRLLearner, make_csirl_learner
from torchrl_csirl.objectives.dac import (
    AbsorbingLogit,
    DACDiscriminatorLoss,
    DACHyperparameters,
    dac_discriminator_loss,
    make_dac_discriminator,
)
from torchrl_csirl.objectives.ensemble_sac import (
    EnsembleSACLoss,
    qvalue_dispersion,
    reinitialize_module,
)
from torchrl_csirl.objectives.gail import GAILHyperparameters, gail_discriminator_input, make_gail_discriminator
from torchrl_csirl.objectives.iq_learn import IQLearnHyperparameters, IQLearnLoss, inverse_soft_q_objective
from torchrl_csirl.objectives.meta_reward import MetaRewardLoss
from torchrl_csirl.objectives.sqil import SQILHyperparameters, sqil_batch, sqil_reward_labels
from torchrl_csirl.objectives.target_update import FusedSoftUpdate
from torchrl_csirl.objectives.valuedice import (
    ValueDICEHyperparameters,
    ValueDICELoss,
    initial_observations,
    valuedice_objective,
)

__all__ = [
    "AbsorbingLogit",
    "ActorBehaviourCloning",
    "CSIRL_DEFAULTS",
    "CSIRLHyperparameters",
    "CSIRLLearner",
    "DACDiscriminatorLoss",
    "DACHyperparameters",
    "EnsembleSACLoss",
    "FusedSoftUpdate",
    "GAILHyperparameters",
    "IQLearnHyperparameters",
    "IQLearnLoss",
    "MetaRewardLoss",
    "SACHyperparameters",
    "SQILHyperparameters",
    "ValueDICEHyperparameters",
    "ValueDICELoss",
    "dac_discriminator_loss",
    "gail_discriminator_input",
    "initial_observations",
    "inverse_soft_q_objective",
    "make_csirl_learner",
    "make_dac_discriminator",
    "make_gail_discriminator",
    "make_sac_learner",
    "orthogonal_regularization",
    "pretrain_actor",
    "qvalue_dispersion",
    "reinitialize_module",
    "sqil_batch",
    "sqil_reward_labels",
    "valuedice_objective",
]
