"""IQ-Learn, continuous actions: inverse soft-Q learning (Garg, Chakraborty, Cundy, Song and Ermon, NeurIPS 2021).

Written from the paper only (its official code is under a research-only licence with a patent
notice and was not read). IQ-Learn learns a single soft Q-function whose *implicit* reward
``r(s, a) = Q(s, a) - gamma V^pi(s')`` makes the expert optimal, with the soft value
``V^pi(s) = E_{a ~ pi}[Q(s, a) - alpha log pi(a | s)]``. The critic maximises the inverse soft-Q
objective

``J(Q) = E_{rho_E}[phi(Q(s, a) - gamma V^pi(s'))] - (1 - gamma) E_{rho_0}[V^pi(s_0)]``,

with the chi-squared divergence's ``phi(x) = x - x^2 / (4 c)``; and the policy is updated as in
SAC on the learned Q (the actor-critic form of the paper's continuous-action algorithm). Three
choices of the authors for online imitation are used:

* the **"value" initial-state term**: ``(1 - gamma) E_{rho_0}[V(s_0)] = E_{(s, s') ~ mu}[V(s) - gamma V(s')]``
  for the occupancy ``mu`` of any policy (a telescoping sum), estimated on the mixture of expert
  and replay transitions instead of the few expert initial states;
* the **chi-squared regulariser on the mixture**: the quadratic term of ``phi`` is averaged over
  expert *and* replay transitions, which bounds the implicit reward on the agent's data as well;
* the **target critics for** ``V(s')`` (the authors' posted continuous-control settings use a target
  network, ``train.use_target=True``; where it enters is our reading: the successor values, as in SAC's
  TD target, while ``Q(s, a)`` and ``V(s)`` use the trained critics).

The SAC parts (actor and temperature losses, critic ensemble) are TorchRL's, through
:class:`~torchrl_csirl.objectives.EnsembleSACLoss`.
"""
from __future__ import annotations

from dataclasses import dataclass

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.utils import NestedKey
from torchrl.envs.utils import ExplorationType, set_exploration_type
from torchrl.objectives.sac import compute_rsample_log_prob

from torchrl_csirl._compat import sac_alpha, sac_reduced_alpha_loss
from torchrl_csirl.objectives._imitation import SACHyperparameters, _check_num_critics, concat_shared, require_keys
from torchrl_csirl.objectives.ensemble_sac import EnsembleSACLoss

__all__ = ["IQLearnHyperparameters", "IQLearnLoss", "inverse_soft_q_objective"]


#: the initial-state term's forms (the authors' ``method.loss``)
VALUE_LOSSES = ("value", "v0")


@dataclass
class IQLearnHyperparameters(SACHyperparameters):
    """IQ-Learn's settings (continuous control).

    Attributes:
        lr: Adam learning rate of the critics (3e-4; the actor has ``actor_lr``).
        chi2_coefficient: ``c`` of ``phi(x) = x - x^2 / (4 c)`` (the chi-squared divergence; the
            paper's ``alpha`` of the regulariser), 0.5 (the authors' ``r^2 / (4 * 0.5)``).
        expert_fraction: share of expert transitions per batch (half, as the paper's batches of
            expert and policy samples).
        num_qvalue_nets: soft Q-functions, each trained on its own objective, the actor on their
            minimum (2, clipped double-Q as in the other SAC-based baselines; the paper describes
            a single Q-function. :class:`EnsembleSACLoss` needs at least 2: with one critic
            TorchRL's SACLoss does not register the critic's parameters).
        alpha_init: SAC temperature, fixed at 0.01 (the authors' settings fix a small temperature per
            task, 1e-3 to 1e-2 on MuJoCo; docs/baselines.md gives the sources).
        fixed_alpha: keep the temperature fixed (the authors found SAC's learned temperature unstable
            with IQ-Learn).
        actor_lr: Adam learning rate of the actor (3e-5, the authors' continuous-control setting; the
            critics use ``lr``, 3e-4).
        use_target_value: ``V(s')`` from the target critics (the authors' setting).
        value_loss: the initial-state term (the authors' ``method.loss``): ``"value"``,
            ``E_mix[V(s) - gamma V(s')]`` (their HalfCheetah command), or ``"v0"``,
            ``(1 - gamma) E_E[V(s)]`` with the expert states as initial states (their Hopper command).
        chi2_policy_actions: the chi-squared regulariser's replay part ``r(s, a)`` at an action of the
            current policy, ``a ~ pi(s)``, instead of the replay's own (the authors' code, "use current policy
            for regularization instead of RB", with its MuJoCo commands' ``method.regularize=True``; the
            paper's mixture has the replay's actions).
    """

    chi2_coefficient: float = 0.5
    expert_fraction: float = 0.5
    num_qvalue_nets: int = 2
    alpha_init: float = 0.01
    fixed_alpha: bool = True
    actor_lr: float = 3e-5
    use_target_value: bool = True
    value_loss: str = "value"
    chi2_policy_actions: bool = False

    def __post_init__(self) -> None:
        if self.value_loss not in VALUE_LOSSES:
            raise ValueError(f"value_loss must be one of {VALUE_LOSSES}, got {self.value_loss!r}.")



def inverse_soft_q_objective(expert_reward: torch.Tensor, value_difference: torch.Tensor,
                             mixture_reward: torch.Tensor, chi2_coefficient: float) -> torch.Tensor:
    """The critic's loss ``-J(Q)``: ``-E_E[r] + E_mu[V(s) - gamma V(s')] + E_mu[r^2] / (4 c)``.

    Args:
        expert_reward: the implicit rewards ``r = Q(s, a) - gamma V(s')`` on expert transitions ``[..., B_E]``.
        value_difference: the initial-state term's samples: ``V(s) - gamma V(s')`` on the mixture ``mu``
            (the "value" form), or ``(1 - gamma) V(s)`` on the expert states (the "v0" form).
        mixture_reward: ``r`` on the mixture (the chi-squared regulariser's support).
        chi2_coefficient: ``c``.

    Examples:
        >>> import torch
        >>> inverse_soft_q_objective(torch.ones(4), torch.zeros(6), torch.full((6,), 2.0), 0.5)
        tensor(1.)
    """
    return (-expert_reward.mean(-1) + value_difference.mean(-1)
            + mixture_reward.pow(2).mean(-1) / (4.0 * chi2_coefficient)).sum()


class IQLearnLoss(EnsembleSACLoss):
    """IQ-Learn's critic objective and SAC's actor/temperature losses on the learned Q.

    The input holds two sub-tensordicts, ``"expert"`` and ``"collector"`` (replay), each with
    observation, action, ``("next", "observation")`` and ``("next", "terminated")`` (no reward is
    read). ``V^pi`` is estimated with one action sampled from the policy per state (detached: the
    critic loss does not reach the actor); ``V(s') = 0`` after a termination, and it is read from the
    target critics unless ``use_target_value=False``. With several critics
    each one gets its own objective (summed).

    Outputs ``loss_qvalue`` (``-J(Q)``, :func:`inverse_soft_q_objective`), ``loss_actor`` and
    ``loss_alpha`` (SAC's, on the states of both parts; the actor loss does not reach the critic),
    and for logging ``expert_reward`` / ``agent_reward`` (mean implicit rewards), ``alpha`` and
    ``entropy``.

    Args:
        actor_network: the policy.
        qvalue_network: one critic.

    Keyword Args:
        chi2_coefficient (float): ``c`` of the chi-squared regulariser. Defaults to ``0.5``.
        num_qvalue_nets (int): critics, at least 2. Defaults to ``2``.
        alpha_init (float): SAC temperature. Defaults to ``0.01``.
        use_target_value (bool): ``V(s')`` from the target critics (updated by the caller's
            :class:`~torchrl.objectives.SoftUpdate`). Defaults to ``True``.
        value_loss (str): the initial-state term, ``"value"`` or ``"v0"`` (:class:`IQLearnHyperparameters`).
            Defaults to ``"value"``.
        chi2_policy_actions (bool): the chi-squared regulariser's replay part at actions of the current policy
            (:class:`IQLearnHyperparameters`). Defaults to ``False``.
        **kwargs: forwarded to :class:`~torchrl_csirl.objectives.EnsembleSACLoss`.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl_csirl.modules import make_actor, make_qvalue
        >>> loss = IQLearnLoss(make_actor(3, 1, hidden=(8,)), make_qvalue(3, 1, hidden=(8,)))
        >>> def t(n):
        ...     return TensorDict({"observation": torch.randn(n, 3), "action": torch.rand(n, 1),
        ...                        "next": {"observation": torch.randn(n, 3),
        ...                                 "terminated": torch.zeros(n, 1, dtype=torch.bool)}}, [n])
        >>> out = loss(TensorDict({"expert": t(4), "collector": t(4)}, []))
        >>> sorted(k for k in out.keys() if k.startswith("loss"))
        ['loss_actor', 'loss_alpha', 'loss_qvalue']
    """

    @dataclass
    class _AcceptedKeys(EnsembleSACLoss._AcceptedKeys):
        """SAC's keys plus the two parts of the batch.

        Attributes:
            expert: sub-tensordict of expert transitions. Defaults to ``"expert"``.
            collector: sub-tensordict of replay transitions. Defaults to ``"collector"``.
        """

        expert: NestedKey = "expert"
        collector: NestedKey = "collector"

    tensor_keys: _AcceptedKeys
    default_keys = _AcceptedKeys

    def __init__(self, actor_network, qvalue_network, *, chi2_coefficient: float = 0.5, num_qvalue_nets: int = 2,
                 alpha_init: float = 0.01, use_target_value: bool = True, value_loss: str = "value",
                 chi2_policy_actions: bool = False, **kwargs) -> None:
        _check_num_critics(num_qvalue_nets)
        if value_loss not in VALUE_LOSSES:
            raise ValueError(f"value_loss must be one of {VALUE_LOSSES}, got {value_loss!r}.")
        if not chi2_coefficient > 0:
            raise ValueError(f"chi2_coefficient must be positive, got {chi2_coefficient}.")
        super().__init__(actor_network, qvalue_network, num_qvalue_nets=num_qvalue_nets, alpha_init=alpha_init,
                         **kwargs)
        self.chi2_coefficient = float(chi2_coefficient)
        self.discount = float(kwargs.get("gamma", 0.99))
        self.use_target_value = bool(use_target_value)
        self.value_loss = value_loss
        self.chi2_policy_actions = bool(chi2_policy_actions)

    def soft_value(self, observation: torch.Tensor, *, target: bool = False) -> torch.Tensor:
        """``V(s) = Q_k(s, a) - alpha log pi(a | s)``, ``a ~ pi(s)`` detached, per critic: ``[N, B]``.

        With ``target=True`` the target critics give ``Q_k`` (no gradient).
        """
        qvalues, log_prob = self._policy_qvalues(observation, target=target)
        return qvalues - sac_alpha(self) * log_prob

    def _policy_qvalues(self, observation: torch.Tensor, *, target: bool = False) -> tuple[torch.Tensor, torch.Tensor]:
        """``(Q_k(s, a), log pi(a | s))`` with ``a ~ pi(s)`` detached: ``[N, B]`` and ``[B]``."""
        obs_key = self.qvalue_network.in_keys[0]
        td = TensorDict({obs_key: observation}, observation.shape[:1])
        with torch.no_grad(), set_exploration_type(ExplorationType.RANDOM), \
                self.actor_network_params.to_module(self.actor_network):
            # SACLoss's own sampler: the log-probability of the tanh-squashed sample, computed stably
            action, log_prob = compute_rsample_log_prob(self.actor_network.get_dist(td))
        td.set(self.tensor_keys.action, action)
        with torch.set_grad_enabled(torch.is_grad_enabled() and not target):
            qvalues = self.qvalues(td, target=target)
        return qvalues, log_prob

    def _implicit_reward(self, transitions: TensorDictBase) -> tuple[torch.Tensor, ...]:
        """``(r, V(s), gamma V(s'), Q(s, a ~ pi))`` per critic, ``[N, B]`` each (``V`` and the last from one
        sampled action)."""
        obs_key = self.qvalue_network.in_keys[0]
        not_done = 1.0 - transitions.get(("next", self.tensor_keys.terminated)).float().reshape(1, -1)
        next_value = self.discount * not_done * self.soft_value(transitions.get(("next", obs_key)),
                                                                target=self.use_target_value)
        reward = self.qvalues(transitions) - next_value
        policy_q, log_prob = self._policy_qvalues(transitions.get(obs_key))
        return reward, policy_q - sac_alpha(self) * log_prob, next_value, policy_q

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        expert = tensordict.get(self.tensor_keys.expert)
        agent = tensordict.get(self.tensor_keys.collector)
        obs_key = self.qvalue_network.in_keys[0]
        needed = [obs_key, self.tensor_keys.action, ("next", obs_key), ("next", self.tensor_keys.terminated)]
        require_keys(expert, needed, "IQ-Learn expert transitions")
        require_keys(agent, needed, "IQ-Learn replay transitions")
        mixture = concat_shared(expert, agent)
        n_expert = expert.numel()
        reward, value, next_value, policy_q = self._implicit_reward(mixture)
        regularized = reward
        if self.chi2_policy_actions:  # the replay part at the policy's actions: Q(s, a ~ pi) - gamma V(s')
            regularized = torch.cat([reward[:, :n_expert], (policy_q - next_value)[:, n_expert:]], -1)
        if self.value_loss == "v0":  # (1 - gamma) V(s_0), the expert states (first in the mixture) as initial states
            value_difference = (1.0 - self.discount) * value[:, :n_expert]
        else:
            value_difference = value - next_value
        loss_qvalue = inverse_soft_q_objective(reward[:, :n_expert], value_difference, regularized, self.chi2_coefficient)
        loss_actor, metadata = self.actor_loss(mixture)
        loss_alpha = sac_reduced_alpha_loss(self, metadata["log_prob"], mixture)
        return TensorDict({
            "loss_qvalue": loss_qvalue, "loss_actor": loss_actor, "loss_alpha": loss_alpha,
            "expert_reward": reward[:, :n_expert].mean().detach(), "agent_reward": reward[:, n_expert:].mean().detach(),
            "alpha": sac_alpha(self), "entropy": -metadata["log_prob"].mean(),
        }, [])
