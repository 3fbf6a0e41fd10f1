"""SQIL: soft Q imitation learning (Reddy, Dragan and Levine, ICLR 2020).

SQIL is soft Q-learning (here TorchRL's SAC, the continuous-action version the paper points to)
on a replay buffer where every demonstrated transition has reward 1 and every transition of the
agent reward 0, trained on balanced batches (half demonstrations, half the agent's own
transitions: the paper's ``lambda_samp = 1``). Nothing else changes in the RL algorithm, so this
module only holds the hyperparameters, the labels and the batch; the SAC equations are TorchRL's
:class:`~torchrl.objectives.SACLoss` (through :class:`~torchrl_csirl.objectives.EnsembleSACLoss`).
"""
from __future__ import annotations

from dataclasses import dataclass

from tensordict import TensorDictBase

from torchrl_csirl.objectives._imitation import SACHyperparameters, concat_shared
from torchrl_csirl.transforms.constant_reward import ConstantReward

__all__ = ["SQILHyperparameters", "sqil_batch", "sqil_reward_labels"]


@dataclass
class SQILHyperparameters(SACHyperparameters):
    """SQIL's settings: the SAC defaults plus the labels and the batch balance.

    Attributes:
        expert_fraction: share of demonstrations in each batch; 0.5 is the paper's balanced
            batch (``lambda_samp = 1``, Reddy et al. 2020, Algorithm 1).
        expert_reward: reward of a demonstrated transition (1, Algorithm 1).
        online_reward: reward of an agent transition (0, Algorithm 1).
    """

    expert_fraction: float = 0.5
    expert_reward: float = 1.0
    online_reward: float = 0.0


def sqil_reward_labels(hp: SQILHyperparameters | None = None) -> tuple[ConstantReward, ConstantReward]:
    """The (online, expert) reward-label transforms (Algorithm 1: 0 for the agent, 1 for the expert).

    Examples:
        >>> online, expert = sqil_reward_labels()
        >>> online.value, expert.value
        (0.0, 1.0)
    """
    hp = hp or SQILHyperparameters()
    return ConstantReward(hp.online_reward), ConstantReward(hp.expert_reward)


def sqil_batch(online: TensorDictBase, expert: TensorDictBase, hp: SQILHyperparameters | None = None) -> TensorDictBase:
    """One SQIL batch: the labelled agent and expert transitions concatenated (expert last).

    Args:
        online: agent transitions.
        expert: demonstrated transitions.
        hp: the labels.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> def t(n):
        ...     return TensorDict({"observation": torch.zeros(n, 2), "action": torch.zeros(n, 1),
        ...                        "next": {"observation": torch.zeros(n, 2)}}, [n])
        >>> sqil_batch(t(2), t(2))["next", "reward"].squeeze(-1).tolist()
        [0.0, 0.0, 1.0, 1.0]
    """
    online_label, expert_label = sqil_reward_labels(hp)
    return concat_shared(online_label(online.clone(False)), expert_label(expert.clone(False)))
