"""DAC: Discriminator-Actor-Critic (Kostrikov, Agrawal, Dwibedi, Levine and Tompson, ICLR 2019).

Adversarial imitation made sample efficient and unbiased:

* **off-policy**: the discriminator compares expert pairs with pairs from the replay buffer,
  and the policy is learned by an off-policy actor-critic on the discriminator reward
  ``r(s, a) = log D(s, a) - log(1 - D(s, a))`` (the logit);
* **absorbing states**: terminal transitions lead to an absorbing state whose
  reward is learned (:class:`~torchrl_csirl.transforms.AbsorbingStates` on both buffers;
  :class:`AbsorbingLogit` reads the absorbing indicator as an input feature);
* **gradient penalty** (Gulrajani et al. 2017, weight 10): at points interpolated between an
  expert pair and an agent pair with *one mixing weight per sample* (TorchRL's ``GAILLoss`` draws
  one per element, which is why this loss is written here).

The learner is SAC (the paper uses TD3): every SAC-based baseline, and CSIRL, then share one learner.

The values were checked against the authors' published code (``google-research/dac``); section and
equation numbers of the paper are not quoted (docs/baselines.md gives every source).
"""
from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModule
from tensordict.utils import NestedKey
from torchrl.objectives import LossModule

from torchrl_csirl.objectives._imitation import (
    AbsorbingLogit,
    AbsorbingStateSettings,
    SACHyperparameters,
    gradient_penalty,
    logit_network,
    require_keys,
)
from torchrl_csirl.transforms.absorbing_states import absorbing_self_loops, check_self_loop_count

__all__ = ["AbsorbingLogit", "DACDiscriminatorLoss", "DACHyperparameters", "dac_discriminator_loss", "make_dac_discriminator"]


@dataclass
class DACHyperparameters(AbsorbingStateSettings, SACHyperparameters):
    """DAC's settings: the SAC learner's (:class:`SACHyperparameters`), the absorbing states' and the discriminator's.

    Attributes:
        discriminator_lr: Adam learning rate of the discriminator (1e-3: Adam's default, used by
            the authors' code, ``google-research/dac``).
        discriminator_batch_size: expert and agent transitions per discriminator step (each).
        discriminator_every: a discriminator step every this many actor-critic updates.
        gp_lambda: gradient-penalty weight (10, after Gulrajani et al. 2017).

    The absorbing-state fields are :class:`AbsorbingStateSettings`'s.
    """

    discriminator_lr: float = 1e-3
    discriminator_batch_size: int = 256
    discriminator_every: int = 1
    gp_lambda: float = 10.0


def make_dac_discriminator(qvalue: TensorDictModule, absorbing_states: bool = True,
                           absorbing_key: NestedKey = "absorbing") -> TensorDictModule:
    """DAC's discriminator, of the critic's architecture, writing ``"discriminator_logit"``.

    With ``absorbing_states`` it reads ``[observation, absorbing, action]`` (:class:`AbsorbingLogit`),
    else ``[observation, action]``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl_csirl.modules import make_qvalue
        >>> d = make_dac_discriminator(make_qvalue(3, 1, hidden=(8,)))
        >>> d.in_keys
        ['observation', 'absorbing', 'action']
    """
    return logit_network(qvalue, "discriminator_logit", absorbing_key if absorbing_states else None)


def dac_discriminator_loss(expert_logit: torch.Tensor, agent_logit: torch.Tensor) -> torch.Tensor:
    """Binary cross-entropy of ``D = sigmoid(logit)``: expert pairs labelled 1, agent pairs 0.

    Examples:
        >>> import torch
        >>> round(float(dac_discriminator_loss(torch.zeros(3), torch.zeros(5))), 4)  # 2 log 2
        1.3863
    """
    return (F.binary_cross_entropy_with_logits(expert_logit, torch.ones_like(expert_logit))
            + F.binary_cross_entropy_with_logits(agent_logit, torch.zeros_like(agent_logit)))


class DACDiscriminatorLoss(LossModule):
    """DAC's discriminator loss: cross-entropy plus a gradient penalty with one mixing weight per sample.

    The input holds two sub-tensordicts, ``"expert"`` and ``"collector"`` (of any sizes), each
    with observation and action. When the discriminator reads the absorbing indicator, the
    samples carry the entries of :class:`~torchrl_csirl.transforms.AbsorbingStates`, and each
    transition entering the absorbing state adds one absorbing self-loop sample to its side
    (:func:`~torchrl_csirl.transforms.absorbing_states.absorbing_self_loops`), as the paper's
    replay buffer holds one absorbing transition per terminated episode. The penalty is taken at
    ``x = eps * x_E + (1 - eps) * x_agent`` with ``eps ~ U[0, 1]`` per sample, over random pairs of
    expert and agent samples (absorbing ones included, the indicator interpolated as a number).

    Args:
        discriminator_network (TensorDictModule): writes the logit (see
            :func:`make_dac_discriminator`).

    Keyword Args:
        gp_lambda (float): penalty weight. Defaults to ``10``.
        self_loops_per_termination (int): absorbing self-loop samples per agent transition entering the
            absorbing state (the expert's: one), the absorbing state's weight on the agent's side. Defaults to ``1``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl_csirl.modules import make_qvalue
        >>> loss = DACDiscriminatorLoss(make_dac_discriminator(make_qvalue(3, 1, hidden=(8,))))
        >>> def pairs(n):  # as written by AbsorbingStates: real states, none entering s_a
        ...     return TensorDict({"observation": torch.randn(n, 3), "action": torch.rand(n, 1),
        ...                        "absorbing": torch.zeros(n, 1, dtype=torch.bool),
        ...                        "next": {"observation": torch.randn(n, 3),
        ...                                 "absorbing": torch.zeros(n, 1, dtype=torch.bool)}}, [n])
        >>> td = TensorDict({"expert": pairs(4), "collector": pairs(6)}, [])
        >>> sorted(loss(td).keys())
        ['agent_probability', 'expert_probability', 'loss_discriminator', 'loss_gradient_penalty']
    """

    @dataclass
    class _AcceptedKeys:
        """Configurable tensordict keys (``set_keys``).

        Attributes:
            expert: sub-tensordict of expert samples. Defaults to ``"expert"``.
            collector: sub-tensordict of agent samples. Defaults to ``"collector"``.
            observation: Defaults to ``"observation"``.
            action: Defaults to ``"action"``.
            absorbing: the absorbing-state indicator. Defaults to ``"absorbing"``.
            logit: the discriminator's output. Defaults to ``"discriminator_logit"``.
        """

        expert: NestedKey = "expert"
        collector: NestedKey = "collector"
        observation: NestedKey = "observation"
        action: NestedKey = "action"
        absorbing: NestedKey = "absorbing"
        logit: NestedKey = "discriminator_logit"

    tensor_keys: _AcceptedKeys
    default_keys = _AcceptedKeys
    out_keys = ["loss_discriminator", "loss_gradient_penalty", "expert_probability", "agent_probability"]

    def __init__(self, discriminator_network: TensorDictModule, *, gp_lambda: float = 10.0,
                 self_loops_per_termination: int = 1) -> None:
        super().__init__()
        if gp_lambda < 0:
            raise ValueError(f"gp_lambda must be >= 0, got {gp_lambda}.")
        check_self_loop_count(self_loops_per_termination, "self_loops_per_termination")
        self.self_loops_per_termination = int(self_loops_per_termination)
        self.discriminator_network = discriminator_network
        self.gp_lambda = float(gp_lambda)

    def _forward_value_estimator_keys(self, **kwargs) -> None:
        pass

    @property
    def in_keys(self):
        return [(self.tensor_keys.expert, key) for key in self.discriminator_network.in_keys] + [
            (self.tensor_keys.collector, key) for key in self.discriminator_network.in_keys]

    def _logit(self, samples: TensorDictBase) -> torch.Tensor:
        return self.discriminator_network(samples.select(*self.discriminator_network.in_keys)).get(
            self.tensor_keys.logit).squeeze(-1)

    @property
    def _reads_absorbing(self) -> bool:
        return self.tensor_keys.absorbing in self.discriminator_network.in_keys

    def _with_self_loops(self, samples: TensorDictBase, copies: int = 1) -> TensorDictBase:
        """The samples (the discriminator's inputs) followed by ``copies`` absorbing samples per entry into ``s_a``."""
        real = samples.select(*self.discriminator_network.in_keys)
        if not self._reads_absorbing:
            return real
        require_keys(samples, [("next", self.tensor_keys.absorbing), ("next", self.tensor_keys.observation)],
                     "DAC discriminator (absorbing states)")
        keys = (self.tensor_keys.observation, self.tensor_keys.action)
        loops = absorbing_self_loops(samples, absorbing_key=self.tensor_keys.absorbing, keys=keys, copies=copies)
        return torch.cat([real, loops.select(*real.keys(True, True))], 0)

    def _penalty(self, expert: TensorDictBase, agent: TensorDictBase) -> torch.Tensor:
        """WGAN-GP at ``eps * x_E + (1 - eps) * x_agent``, one ``eps`` per pair of random partners.

        ``x`` is every discriminator input (observation, action and, with absorbing states, the
        indicator as a number), so the absorbing state's output is penalised like the others.
        """
        n = min(expert.numel(), agent.numel())
        if n == 0 or self.gp_lambda == 0:
            return torch.zeros((), device=self._logit_device())
        keys = list(self.discriminator_network.in_keys)
        expert = expert[torch.randperm(expert.numel(), device=expert.device)[:n]]
        agent = agent[torch.randperm(agent.numel(), device=agent.device)[:n]]
        eps = torch.rand(n, 1, device=expert.device)  # one mixing weight per sample
        mixed = [eps * expert.get(k).float() + (1 - eps) * agent.get(k).float() for k in keys]

        def logit(*inputs: torch.Tensor) -> torch.Tensor:
            return self._logit(TensorDict(dict(zip(keys, inputs)), [n]))

        return self.gp_lambda * gradient_penalty(logit, mixed)

    def _logit_device(self) -> torch.device:
        return next(self.discriminator_network.parameters()).device

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        expert = tensordict.get(self.tensor_keys.expert)
        agent = tensordict.get(self.tensor_keys.collector)
        require_keys(expert, self.discriminator_network.in_keys, "DAC discriminator, expert samples")
        require_keys(agent, self.discriminator_network.in_keys, "DAC discriminator, agent samples")
        expert, agent = self._with_self_loops(expert), self._with_self_loops(agent, self.self_loops_per_termination)
        expert_logit, agent_logit = self._logit(expert), self._logit(agent)
        return TensorDict({
            "loss_discriminator": dac_discriminator_loss(expert_logit, agent_logit),
            "loss_gradient_penalty": self._penalty(expert, agent),
            "expert_probability": torch.sigmoid(expert_logit).mean().detach(),
            "agent_probability": torch.sigmoid(agent_logit).mean().detach(),
        }, [])
