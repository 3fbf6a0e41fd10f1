"""The update steps of the imitation baselines (``update_step(trainer) -> dict`` of detached losses).

* SQIL is a :class:`~torchrl_csirl.trainers.SACUpdate` on balanced batches (no class of its own);
* :class:`AdversarialImitationUpdate`: GAIL and DAC, a discriminator step
  (:class:`DiscriminatorStep`) then a SAC step on the discriminator reward;
* :class:`ValueDICEUpdate` and :class:`IQLearnUpdate`: their joint objectives.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import torch
from tensordict import TensorDictBase
from torch import nn

from torchrl_csirl.objectives._imitation import sample
from torchrl_csirl.trainers.trainer import CSIRLTrainer, check_finite_losses
from torchrl_csirl.trainers.updates import SACUpdate

__all__ = ["AdversarialImitationUpdate", "DiscriminatorStep"]


def _where(trainer: CSIRLTrainer) -> str:
    return f"update {trainer.updates + 1} (frames {trainer.frames})"


def _apply(losses: dict[str, torch.Tensor], optimizer: torch.optim.Optimizer, max_grad_norm: float | None) -> None:
    optimizer.zero_grad(set_to_none=True)
    sum(losses.values()).backward()
    if max_grad_norm is not None:
        params = [p for group in optimizer.param_groups for p in group["params"]]
        torch.nn.utils.clip_grad_norm_(params, max_grad_norm)
    optimizer.step()


class DiscriminatorStep:
    """One discriminator step: an expert and an agent batch, the loss, Adam.

    Args:
        loss: the discriminator loss module (TorchRL's ``GAILLoss``, :class:`~torchrl_csirl.objectives.DACDiscriminatorLoss`).
        optimizer: over the discriminator's parameters.
        make_input: ``(expert_batch, agent_batch) -> loss input``.
        online: the online replay buffer (agent samples).
        expert: the expert replay buffer.
        batch_size: samples drawn from each buffer.
        loss_keys: ``{name in the loss output: name in the returned dict}`` of the terms to
            minimise; every other scalar of the output is returned (detached) for logging.
    """

    def __init__(self, loss: nn.Module, optimizer: torch.optim.Optimizer,
                 make_input: Callable[[TensorDictBase, TensorDictBase], TensorDictBase], online: Any, expert: Any,
                 batch_size: int, loss_keys: dict[str, str], max_grad_norm: float | None = None) -> None:
        self.loss = loss
        self.optimizer = optimizer
        self.make_input = make_input
        self.online = online
        self.expert = expert
        self.batch_size = int(batch_size)
        self.loss_keys = dict(loss_keys)
        self.max_grad_norm = max_grad_norm

    def __call__(self, trainer: CSIRLTrainer) -> dict[str, torch.Tensor]:
        out = self.loss(self.make_input(sample(self.expert, self.batch_size), sample(self.online, self.batch_size)))
        losses = {name: out.get(key) for key, name in self.loss_keys.items()}
        check_finite_losses(losses, _where(trainer))
        _apply(losses, self.optimizer, self.max_grad_norm)
        logs = {key: out.get(key).detach() for key in out.keys() if key not in self.loss_keys}
        return {**{k: v.detach() for k, v in losses.items()}, **logs}


class AdversarialImitationUpdate:
    """GAIL / DAC: a discriminator step every ``discriminator_every`` updates, then a SAC step.

    The SAC step's reward is the online buffer's :class:`~torchrl_csirl.transforms.DiscriminatorReward`,
    recomputed at sampling time with the discriminator just updated.

    Args:
        discriminator_step: the :class:`DiscriminatorStep`.
        sac_update: the :class:`~torchrl_csirl.trainers.SACUpdate` of the policy.
        discriminator_every: cadence of the discriminator step.
    """

    def __init__(self, discriminator_step: DiscriminatorStep, sac_update: SACUpdate, discriminator_every: int = 1) -> None:
        if discriminator_every < 1:
            raise ValueError(f"discriminator_every must be >= 1, got {discriminator_every}.")
        self.discriminator_step = discriminator_step
        self.sac_update = sac_update
        self.discriminator_every = int(discriminator_every)

    def __call__(self, trainer: CSIRLTrainer) -> dict[str, torch.Tensor]:
        out = {}
        if trainer.updates % self.discriminator_every == 0:
            out.update(self.discriminator_step(trainer))
        out.update(self.sac_update(trainer))
        return out


def split_parameters(*groups: Sequence[nn.Parameter]) -> list[list[nn.Parameter]]:
    """The parameter groups with ``requires_grad``, checked to be disjoint."""
    seen: set[int] = set()
    out = []
    for group in groups:
        params = [p for p in group if p.requires_grad]
        if any(id(p) in seen for p in params):
            raise ValueError("parameter groups overlap.")
        seen.update(id(p) for p in params)
        out.append(params)
    return out
