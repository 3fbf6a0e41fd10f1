"""The update steps of the imitation baselines (``update_step(trainer) -> dict`` of detached losses).

* SQIL is a :class:`~torchrl_csirl.trainers.SACUpdate` on balanced batches (no class of its own);
* :class:`AdversarialImitationUpdate`: GAIL and DAC, a discriminator step
  (:class:`DiscriminatorStep`) then a SAC step on the discriminator reward;
* :class:`ValueDICEUpdate`: ``nu`` and the policy on one min-max objective;
* IQ-Learn is a :class:`~torchrl_csirl.trainers.SACUpdate` whose loss is
  :class:`~torchrl_csirl.objectives.IQLearnLoss` and whose batch holds expert and replay parts.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

import torch
from tensordict import TensorDict, TensorDictBase
from torch import nn

from torchrl_csirl.objectives._imitation import sample
from torchrl_csirl.trainers.trainer import CSIRLTrainer, check_finite_losses
from torchrl_csirl.trainers.updates import SACUpdate, optimizer_parameters, update_location

__all__ = ["AdversarialImitationUpdate", "DiscriminatorStep", "ValueDICEUpdate"]


def _gradients(loss: torch.Tensor, optimizer: torch.optim.Optimizer, retain_graph: bool = False) -> list:
    """The gradient of ``loss`` with respect to the parameters of ``optimizer`` (None where unused)."""
    return list(torch.autograd.grad(loss, optimizer_parameters(optimizer), retain_graph=retain_graph, allow_unused=True))


def _step(grads: list, optimizer: torch.optim.Optimizer, max_grad_norm: float | None) -> None:
    """Sets ``grads`` on the optimiser's parameters, clips their norm, steps."""
    params = optimizer_parameters(optimizer)
    for param, grad in zip(params, grads):
        param.grad = grad
    if max_grad_norm is not None:
        torch.nn.utils.clip_grad_norm_(params, max_grad_norm)
    optimizer.step()


def _apply(losses: dict[str, torch.Tensor], optimizer: torch.optim.Optimizer, max_grad_norm: float | None) -> None:
    """One optimiser step on the sum of ``losses``."""
    _step(_gradients(sum(losses.values()), optimizer), optimizer, max_grad_norm)


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
        check_finite_losses(losses, update_location(trainer))
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


class ValueDICEUpdate:
    """One ValueDICE step: expert, replay and initial-state batches; ``nu`` descends ``J``, the actor ascends it.

    The gradients of ``loss_nu + loss_gradient_penalty`` are applied to ``nu``'s parameters only
    and those of ``loss_actor + loss_orthogonal`` (``-J`` plus the regulariser) to the actor's only;
    both come from one forward pass. A step returns the four losses and ``policy_scale`` (detached).

    Args:
        loss: the :class:`~torchrl_csirl.objectives.ValueDICELoss`.
        nu_optimizer: over ``nu``'s parameters.
        actor_optimizer: over the actor's parameters.
        online: the replay buffer.
        expert: the expert replay buffer.
        batch_size: expert and replay samples per step (and initial states).
        initial_observations: ``[N, D]`` initial observations to sample from (e.g. the expert
            trajectories' first states); None: the expert batch's own states, as the authors' code.
        max_grad_norm: gradient-norm clipping of each network (None: none).
    """

    NU_KEYS = ("loss_nu", "loss_gradient_penalty")
    ACTOR_KEYS = ("loss_actor", "loss_orthogonal")
    METRIC_KEYS = ("policy_scale",)

    def __init__(self, loss: nn.Module, nu_optimizer: torch.optim.Optimizer, actor_optimizer: torch.optim.Optimizer,
                 online: Any, expert: Any, batch_size: int, initial_observations: torch.Tensor | None = None,
                 max_grad_norm: float | None = None) -> None:
        if initial_observations is not None and (initial_observations.ndim != 2 or not len(initial_observations)):
            raise ValueError(f"initial_observations must be a non-empty [N, D] tensor, got {tuple(initial_observations.shape)}.")
        self.loss = loss
        self.nu_optimizer = nu_optimizer
        self.actor_optimizer = actor_optimizer
        self.online = online
        self.expert = expert
        self.initial_observations = initial_observations
        self.batch_size = int(batch_size)
        self.max_grad_norm = max_grad_norm

    def batch(self) -> TensorDictBase:
        """Expert, replay and initial-state samples, as :class:`ValueDICELoss` reads them."""
        expert = sample(self.expert, self.batch_size)
        obs_key = self.loss.tensor_keys.observation
        if self.initial_observations is None:
            starts = expert.get(obs_key)
        else:
            index = torch.randint(len(self.initial_observations), (self.batch_size,),
                                  device=self.initial_observations.device)
            starts = self.initial_observations[index]
        initial = TensorDict({obs_key: starts}, starts.shape[:1])
        return TensorDict({"expert": expert, "collector": sample(self.online, self.batch_size), "initial": initial}, [])

    def __call__(self, trainer: CSIRLTrainer) -> dict[str, torch.Tensor]:
        out = self.loss(self.batch())
        losses = {key: out.get(key) for key in self.NU_KEYS + self.ACTOR_KEYS}
        check_finite_losses(losses, update_location(trainer))
        nu_loss = losses["loss_nu"] + losses["loss_gradient_penalty"]
        actor_loss = losses["loss_actor"] + losses["loss_orthogonal"]
        # both gradients are taken before either network moves
        nu_grads = _gradients(nu_loss, self.nu_optimizer, retain_graph=True)
        actor_grads = _gradients(actor_loss, self.actor_optimizer)
        for grads, optimizer in ((nu_grads, self.nu_optimizer), (actor_grads, self.actor_optimizer)):
            _step(grads, optimizer, self.max_grad_norm)
        metrics = {key: out.get(key) for key in self.METRIC_KEYS if key in out.keys()}
        return {key: value.detach() for key, value in {**losses, **metrics}.items()}
