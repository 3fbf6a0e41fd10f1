"""The update steps of :class:`~torchrl_csirl.trainers.CSIRLTrainer` (its ``update_step``).

* :class:`SACUpdate`: one ensemble-SAC step (CSIRL-B's whole update);
* :class:`MetaRewardUpdate`: CSIRL's update, a joint SAC + meta-gradient step every
  ``meta_every`` updates and a SAC step otherwise;
* :class:`BCUpdate`: one behavioural-cloning step on expert pairs (the BC baseline's update).
"""
from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import torch
from tensordict import TensorDictBase
from torch import nn
from torchrl.envs.utils import ExplorationType, set_exploration_type

from torchrl_csirl.hyperparameters import CSIRL_DEFAULTS
from torchrl_csirl.modules.precision import LearnerPrecision
from torchrl_csirl.trainers.trainer import CSIRLTrainer, check_finite_losses

if TYPE_CHECKING:
    from torchrl_csirl.objectives import ActorBehaviourCloning

__all__ = ["BCUpdate", "MetaRewardUpdate", "SACUpdate"]


def update_location(trainer: CSIRLTrainer) -> str:
    """Where an update stands, for error messages: ``"update N (frames F)"``."""
    return f"update {trainer.updates + 1} (frames {trainer.frames})"


def optimizer_parameters(optimizer: torch.optim.Optimizer) -> list[torch.Tensor]:
    """Every parameter ``optimizer`` steps, in its parameter groups' order."""
    return [p for group in optimizer.param_groups for p in group["params"]]


def backward_and_step(loss: torch.Tensor, optimizer: torch.optim.Optimizer, max_grad_norm: float | None) -> None:
    """Zero the gradients, backpropagate ``loss``, clip the gradient norm (unless None), step."""
    optimizer.zero_grad(set_to_none=True)
    loss.backward()
    if max_grad_norm is not None:
        torch.nn.utils.clip_grad_norm_(optimizer_parameters(optimizer), max_grad_norm)
    optimizer.step()


def _detached(out: TensorDictBase, keys: tuple[str, ...]) -> dict[str, torch.Tensor]:
    return {key: out.get(key).detach() for key in keys if key in out.keys()}


#: the rewards of a training batch whose means an update logs (``<key>_mean``): what the learner was paid
BATCH_REWARD_KEYS = ("matching_reward", "reward")


def batch_reward_means(batch: TensorDictBase) -> dict[str, torch.Tensor]:
    """``{"<key>_mean": ...}`` of the batch's ``("next", key)`` rewards (:data:`BATCH_REWARD_KEYS`) it holds.

    Examples:
        >>> from tensordict import TensorDict
        >>> batch = TensorDict({"next": {"matching_reward": torch.tensor([[1.0], [3.0]])}}, [2])
        >>> batch_reward_means(batch)
        {'matching_reward_mean': tensor(2.)}
    """
    found = {}
    for key in BATCH_REWARD_KEYS:
        value = batch.get(("next", key), None)
        if value is not None:
            found[f"{key}_mean"] = value.detach().float().mean()
    return found


class SACUpdate:
    """One ensemble-SAC step: sample a batch, critic + actor losses, Adam, Polyak.

    The batch comes from the trainer's online buffer, or from ``sample`` (e.g. online transitions
    mixed with expert ones, :class:`~torchrl_csirl.data.DemonstrationMixer`); ``actor_bc`` adds
    a behavioural-cloning term to the actor loss.

    The reward is whatever the buffer's transform writes to ``("next", "reward")`` (e.g.
    :class:`~torchrl_csirl.transforms.SubgoalMatchingReward` + :class:`IntrinsicReward` +
    :class:`CombineRewards`). This is the whole update of CSIRL-B.

    Args:
        loss: the :class:`~torchrl_csirl.objectives.EnsembleSACLoss`.
        optimizer: optimiser over the actor and critic parameters.
        target_updater: e.g. :class:`~torchrl.objectives.SoftUpdate`.
        max_grad_norm: clip the gradient norm (None: no clipping).
        sample: ``callable() -> TensorDict`` giving a training batch (e.g.
            :meth:`~torchrl_csirl.data.DemonstrationMixer.sample`). Defaults to sampling the
            trainer's online buffer.
        actor_bc: an :class:`ActorBehaviourCloning` term added to the actor loss (None: plain SAC).
        precision: the matmul precision of the losses' forward pass (``optim.precision``;
            :class:`~torchrl_csirl.modules.LearnerPrecision`). Defaults to float32.
        critic_warmup_updates: the first updates of a run step the critics' loss only: the actor, its
            cloning term and the temperature are held (``csirl.critic_warmup_updates``; their losses are
            still logged). Defaults to ``0`` (:data:`~torchrl_csirl.hyperparameters.CSIRL_DEFAULTS`): every update
            steps everything, as the paper.
    """

    LOSS_KEYS = ("loss_qvalue", "loss_actor", "loss_alpha")
    CRITIC_KEYS = ("loss_qvalue",)
    LOG_KEYS = ("alpha", "entropy")

    def __init__(self, loss: nn.Module, optimizer: torch.optim.Optimizer, target_updater: Any,
                 max_grad_norm: float | None = None,
                 sample: Callable[[], TensorDictBase] | None = None,
                 actor_bc: ActorBehaviourCloning | None = None, precision: LearnerPrecision | None = None,
                 critic_warmup_updates: int = CSIRL_DEFAULTS.critic_warmup_updates) -> None:
        if critic_warmup_updates < 0:
            raise ValueError(f"critic_warmup_updates must be >= 0, got {critic_warmup_updates}.")
        self.loss = loss
        self.optimizer = optimizer
        self.target_updater = target_updater
        self.max_grad_norm = max_grad_norm
        self._sample = sample
        self.actor_bc = actor_bc
        self.precision = precision if precision is not None else LearnerPrecision()
        self.critic_warmup_updates = int(critic_warmup_updates)

    def sample(self, trainer: CSIRLTrainer) -> TensorDictBase:
        """A training batch: ``sample()`` if given, else one of the trainer's online buffer."""
        return self._sample() if self._sample is not None else trainer.online_buffer.sample()

    def actor_held(self, trainer: CSIRLTrainer) -> bool:
        """Whether this update leaves the actor and the temperature as they are (the critics' warm-up)."""
        return trainer.updates < self.critic_warmup_updates

    def losses_to_step(self, losses: dict[str, torch.Tensor], trainer: CSIRLTrainer,
                       batch: TensorDictBase) -> tuple[dict[str, torch.Tensor], dict[str, torch.Tensor]]:
        """The losses this update steps on ``batch`` and what it logs besides: the critics' alone during the
        warm-up (the others logged), else ``losses`` with the behavioural-cloning term (if any) and its
        diagnostics."""
        if self.actor_held(trainer):
            held = {key: value.detach() for key, value in losses.items() if key not in self.CRITIC_KEYS}
            return {key: losses[key] for key in self.CRITIC_KEYS}, held
        if self.actor_bc is None:
            return losses, {}
        bc_losses, logs = self.actor_bc(losses["loss_actor"], batch)
        return {**losses, **bc_losses}, logs

    def step(self, losses: dict[str, torch.Tensor], trainer: CSIRLTrainer) -> None:
        """Checks, backpropagates and applies ``losses`` (sum) with the SAC optimiser."""
        check_finite_losses(losses, update_location(trainer))
        backward_and_step(sum(losses.values()), self.optimizer, self.max_grad_norm)
        self.target_updater.step()

    def __call__(self, trainer: CSIRLTrainer) -> dict[str, torch.Tensor]:
        batch = self.sample(trainer)
        with self.precision.autocast():
            out = self.loss(batch)
        losses, logs = self.losses_to_step({key: out.get(key) for key in self.LOSS_KEYS if key in out.keys()}, trainer,
                                           batch)
        self.step(losses, trainer)
        return {**{key: value.detach() for key, value in losses.items()}, **_detached(out, self.LOG_KEYS), **logs,
                **batch_reward_means(batch)}


class MetaRewardUpdate:
    """The CSIRL update: every ``meta_every``-th update a joint SAC + meta-gradient step, else SAC.

    The joint step (:class:`~torchrl_csirl.objectives.MetaRewardLoss` with
    ``joint_sac_update=True``) computes the real critic/actor losses and the meta-loss of the
    reward network from one critic pass; the SAC optimiser steps the actor and critics, the reward
    optimiser steps ``r_w``. The other updates are :class:`SACUpdate` steps whose reward is
    ``r_m + r_w(s)`` recomputed by the buffer transform.

    Args:
        meta_loss: the :class:`~torchrl_csirl.objectives.MetaRewardLoss` (``joint_sac_update=True``).
        sac_update: the plain step (shares the SAC optimiser and target updater).
        reward_optimizer: optimiser over the reward network.
        expert_buffer: replay buffer of expert transitions (the outer behavioural-cloning batch).
        meta_every: cadence of the meta step (1 = every update, as the paper). Defaults to ``2``
            (:data:`~torchrl_csirl.hyperparameters.CSIRL_DEFAULTS`, as the recipes).
    """

    META_KEYS = ("loss_meta", "loss_imitation", "loss_reward_l1", "intrinsic_reward_mean", "meta_grad_norm",
                 "meta_grad_norm_imitation", "meta_grad_norm_l1")

    def __init__(self, meta_loss: nn.Module, sac_update: SACUpdate, reward_optimizer: torch.optim.Optimizer,
                 expert_buffer: Any, meta_every: int = CSIRL_DEFAULTS.meta_every) -> None:
        if not getattr(meta_loss, "joint_sac_update", False):
            raise ValueError("MetaRewardUpdate needs a MetaRewardLoss built with joint_sac_update=True.")
        if meta_every < 1:
            raise ValueError(f"meta_every must be >= 1, got {meta_every}.")
        self.meta_loss = meta_loss
        self.sac_update = sac_update
        self.reward_optimizer = reward_optimizer
        self.expert_buffer = expert_buffer
        self.meta_every = int(meta_every)

    def __call__(self, trainer: CSIRLTrainer) -> dict[str, torch.Tensor]:
        if trainer.updates % self.meta_every:
            return self.sac_update(trainer)
        online = self.sac_update.sample(trainer)
        expert, regularizer = self.expert_buffer.sample(), trainer.online_buffer.sample()
        with self.sac_update.precision.autocast():  # the SAC update's precision
            out = self.meta_loss(online, expert, regularizer=regularizer)
        sac_losses, logs = self.sac_update.losses_to_step(
            {key: out.get(key) for key in SACUpdate.LOSS_KEYS if key in out.keys()}, trainer, online)
        meta = out.get("loss_meta")
        check_finite_losses({**sac_losses, "loss_meta": meta}, update_location(trainer))
        self.reward_optimizer.zero_grad(set_to_none=True)
        # one backward: the SAC losses reach the actor/critics, the meta-loss the reward net only
        self.sac_update.step({**sac_losses, "loss_meta": meta}, trainer)
        self.reward_optimizer.step()
        return {**{k: v.detach() for k, v in sac_losses.items()}, **_detached(out, SACUpdate.LOG_KEYS + self.META_KEYS),
                **logs, **batch_reward_means(online)}


class BCUpdate:
    """One behavioural-cloning step: an expert batch, the loss of the deterministic action, Adam.

    The policy acts deterministically while the loss is computed (the mode of a tanh-Gaussian
    actor), so an ``"l2"`` :class:`~torchrl.objectives.BCLoss` regresses the action the policy is
    evaluated with on the expert's action. The trainer's online buffer is not read.

    Args:
        loss: a :class:`~torchrl.objectives.BCLoss` over the actor.
        optimizer: optimiser over the actor's parameters.
        expert_buffer: replay buffer of expert ``(observation, action)`` pairs.
        max_grad_norm: clip the gradient norm (None: no clipping).

    Examples:
        >>> from types import SimpleNamespace
        >>> from torchrl.objectives import BCLoss
        >>> from torchrl_csirl.data import ExpertDemonstrations
        >>> from torchrl_csirl.modules import make_actor
        >>> ep = {"observation": torch.zeros(5, 4), "action": torch.full((5, 2), 0.5),
        ...       "next_observation": torch.ones(5, 4), "terminated": torch.zeros(5, dtype=torch.bool)}
        >>> expert = ExpertDemonstrations.from_episodes([ep]).as_replay_buffer(batch_size=4)
        >>> actor = make_actor(4, 2, hidden=(8,))
        >>> update = BCUpdate(BCLoss(actor, loss_function="l2"), torch.optim.Adam(actor.parameters()), expert)
        >>> sorted(update(SimpleNamespace(updates=0, frames=0)))
        ['loss_bc']
    """

    def __init__(self, loss: nn.Module, optimizer: torch.optim.Optimizer, expert_buffer: Any,
                 max_grad_norm: float | None = None) -> None:
        self.loss = loss
        self.optimizer = optimizer
        self.expert_buffer = expert_buffer
        self.max_grad_norm = max_grad_norm

    def __call__(self, trainer: CSIRLTrainer) -> dict[str, torch.Tensor]:
        with set_exploration_type(ExplorationType.DETERMINISTIC):
            loss = self.loss(self.expert_buffer.sample())["loss_bc"]
        check_finite_losses({"loss_bc": loss}, update_location(trainer))
        backward_and_step(loss, self.optimizer, self.max_grad_norm)
        return {"loss_bc": loss.detach()}
