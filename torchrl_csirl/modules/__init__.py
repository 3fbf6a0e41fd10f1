"""Networks of the CSIRL learner: actor, critic and intrinsic reward."""
from __future__ import annotations

from torchrl_csirl.modules.actor_critic import (
    BoundedLogStdNormalParams,
    ConcatMLP,
    MaskedReLU,
    make_actor,
    make_qvalue,
)
from torchrl_csirl.modules.ensemble import FusedCriticEnsemble, fused_critic_ensemble
from torchrl_csirl.modules.exploration import MeanActionGaussianNoise
from torchrl_csirl.modules.export import load_policy, save_policy
from torchrl_csirl.modules.features import (
    DropFeatures,
    EgoRelativeFeatures,
    FeatureChain,
    StandardizeFeatures,
    find_standardization,
    make_input_features,
    with_standardization,
)
from torchrl_csirl.modules.fused_actor import FusedTanhNormalActor, fused_tanh_normal_actor
from torchrl_csirl.modules.input_memo import map_each_input_once, mapped_once
from torchrl_csirl.modules.lane_features import LaneFeatures
from torchrl_csirl.modules.precision import LearnerPrecision, PrecisionUnsupported, has_native_bf16
from torchrl_csirl.modules.reward import (
    REWARD_ACTIVATIONS,
    ExpertCenteredReward,
    expert_reference_states,
    make_reward_network,
)

__all__ = [
    "BoundedLogStdNormalParams",
    "ConcatMLP",
    "EgoRelativeFeatures",
    "ExpertCenteredReward",
    "FeatureChain",
    "FusedCriticEnsemble",
    "FusedTanhNormalActor",
    "LaneFeatures",
    "LearnerPrecision",
    "MaskedReLU",
    "MeanActionGaussianNoise",
    "PrecisionUnsupported",
    "REWARD_ACTIVATIONS",
    "fused_critic_ensemble",
    "fused_tanh_normal_actor",
    "has_native_bf16",
    "load_policy",
    "expert_reference_states",
    "make_actor",
    "make_input_features",
    "DropFeatures",
    "make_qvalue",
    "map_each_input_once",
    "mapped_once",
    "make_reward_network",
    "save_policy",
    "StandardizeFeatures",
    "find_standardization",
    "with_standardization",
]
