"""GAIL: generative adversarial imitation learning (Ho and Ermon, NeurIPS 2016), off-policy generator.

The discriminator is trained with TorchRL's :class:`~torchrl.objectives.GAILLoss` (binary cross
entropy, expert = 1, agent = 0). ``GAILLoss`` reads a *probability* under its
``"d_logits"`` key, so the discriminator built here writes its logit under
``"discriminator_logit"`` and its sigmoid under ``"d_logits"``; the generator reward
``-log(1 - D(s, a)) = softplus(logit)`` is computed from the logit
(:class:`~torchrl_csirl.transforms.DiscriminatorReward`).

**Generator (a deviation from the paper).** Ho and Ermon train the policy with TRPO, on-policy,
with about 5 000 environment steps per iteration and millions of steps in total. Every method
here gets the frame budget of the CSIRL recipe, a few tens of thousands of steps: an on-policy
learner would see a handful of batches and learn nothing, so the comparison would measure the
learner, not the imitation objective. The generator is therefore SAC on the discriminator reward
(off-policy, replaying every transition, the same learner as CSIRL's), which is how GAIL is run in
later off-policy comparisons (e.g. Kostrikov et al. 2019 use an off-policy TD3 generator). The
discriminator is trained on the replay buffer, not on the current policy's samples, with
``GAILLoss``'s gradient penalty (a second deviation: :class:`GAILHyperparameters`).
"""
from __future__ import annotations

from dataclasses import dataclass

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModule, TensorDictSequential

from torchrl_csirl.objectives._imitation import SACHyperparameters, logit_network, require_keys

__all__ = ["GAILHyperparameters", "gail_discriminator_input", "make_gail_discriminator"]


@dataclass
class GAILHyperparameters(SACHyperparameters):
    """GAIL's settings: the SAC generator's (:class:`SACHyperparameters`) plus the discriminator's.

    Attributes:
        discriminator_lr: Adam learning rate of the discriminator. The paper trains it with Adam
            without giving the rate; 3e-4 is TorchRL's GAIL example
            (``sota-implementations/gail/config.yaml``).
        discriminator_batch_size: expert and agent pairs per discriminator step (each).
        discriminator_every: a discriminator step every this many generator updates.
        use_grad_penalty: the gradient penalty of ``GAILLoss``, ``gp_lambda * (||grad D|| - 1) ** 2`` at
            mixtures of expert and agent pairs (one mixing weight per element; on ``D``'s probability, so
            it also pulls ``D`` away from 0 and 1 there). On by default, as in TorchRL's GAIL example; a
            deviation from the paper (Ho and Ermon do not regularise the discriminator), needed by the
            off-policy generator: without it the discriminator, one step per SAC update on replayed
            pairs, separates expert from agent within a few thousand updates and the reward
            ``softplus(logit)`` vanishes on every agent pair (HalfCheetah: docs/benchmark.md).
        gp_lambda: its weight when on.
    """

    discriminator_lr: float = 3e-4
    discriminator_batch_size: int = 256
    discriminator_every: int = 1
    use_grad_penalty: bool = True
    gp_lambda: float = 10.0


def make_gail_discriminator(qvalue: TensorDictModule) -> TensorDictSequential:
    """A discriminator ``D(s, a)`` of the critic's architecture: logit and probability.

    Writes ``"discriminator_logit"`` and ``"d_logits" = sigmoid(logit)`` (the probability that
    :class:`~torchrl.objectives.GAILLoss` reads, despite its name).

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl_csirl.modules import make_qvalue
        >>> d = make_gail_discriminator(make_qvalue(3, 1, hidden=(8,)))
        >>> out = d(TensorDict({"observation": torch.zeros(2, 3), "action": torch.zeros(2, 1)}, [2]))
        >>> bool(((out["d_logits"] > 0) & (out["d_logits"] < 1)).all())
        True
    """
    logit = logit_network(qvalue, "discriminator_logit")
    return TensorDictSequential(logit, TensorDictModule(torch.sigmoid, in_keys=["discriminator_logit"],
                                                        out_keys=["d_logits"]))


def gail_discriminator_input(expert: TensorDictBase, online: TensorDictBase, *, observation_key: str = "observation",
                             action_key: str = "action") -> TensorDictBase:
    """The input of :class:`~torchrl.objectives.GAILLoss`: expert pairs under the usual keys, agent
    pairs under ``"collector_observation"`` / ``"collector_action"`` (equal numbers of each).

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> e = TensorDict({"observation": torch.ones(2, 3), "action": torch.ones(2, 1)}, [2])
        >>> o = TensorDict({"observation": torch.zeros(2, 3), "action": torch.zeros(2, 1)}, [2])
        >>> sorted(gail_discriminator_input(e, o).keys())
        ['action', 'collector_action', 'collector_observation', 'observation']
    """
    require_keys(expert, [observation_key, action_key], "GAIL expert batch")
    require_keys(online, [observation_key, action_key], "GAIL agent batch")
    if expert.batch_size != online.batch_size:
        raise ValueError(f"GAILLoss needs as many expert as agent pairs, got {expert.batch_size} and {online.batch_size}.")
    return TensorDict({observation_key: expert.get(observation_key), action_key: expert.get(action_key),
                       "collector_observation": online.get(observation_key),
                       "collector_action": online.get(action_key)}, expert.batch_size)
