"""A behavioural-cloning term for the actor, weighted like TD3+BC (an option of the CSIRL recipe)."""
from __future__ import annotations

from typing import Any

import torch
from torch import nn
from torchrl.envs.utils import ExplorationType, set_exploration_type

__all__ = ["ActorBehaviourCloning"]


class ActorBehaviourCloning:
    """A behavioural-cloning term for the actor, scaled like TD3+BC: ``coef * |L_actor| * BC``.

    ``BC`` is the mean squared error between the deterministic action of the policy and the
    expert's action on an expert batch (TorchRL's :class:`~torchrl.objectives.BCLoss` with
    ``loss_function="l2"``). Its weight follows the size of the actor's Q objective (``|L_actor|``
    = ``|mean(alpha log pi - min_k Q_k)|``, detached), as TD3+BC divides the Q term by
    ``mean |Q|``, so ``coef`` does not depend on the reward scale of a scenario (TD3+BC's offline
    setting corresponds to ``coef = 0.4``). Not in the CSIRL paper nor in its code: it is the
    learned reward's outer objective (Eq. 11) applied to the actor directly, so that the policy
    imitates the expert where the demonstrations cover the state space (``csirl.actor_bc_coef``).

    Args:
        bc_loss: a :class:`~torchrl.objectives.BCLoss` over the actor.
        expert_buffer: replay buffer of expert ``(observation, action)`` pairs.
        coef: the weight relative to ``|L_actor|``.

    Examples:
        >>> import torch
        >>> from torchrl.objectives import BCLoss
        >>> from torchrl_csirl.data import ExpertDemonstrations
        >>> from torchrl_csirl.modules import make_actor
        >>> ep = {"observation": torch.zeros(5, 4), "action": torch.full((5, 2), 0.5),
        ...       "next_observation": torch.ones(5, 4), "terminated": torch.zeros(5, dtype=torch.bool)}
        >>> expert = ExpertDemonstrations.from_episodes([ep]).as_replay_buffer(batch_size=4)
        >>> term = ActorBehaviourCloning(BCLoss(make_actor(4, 2), loss_function="l2"), expert, coef=0.1)
        >>> losses, logs = term(torch.tensor(-200.0))
        >>> sorted(losses), sorted(logs)
        (['loss_actor_bc'], ['actor_bc_mse'])
    """

    def __init__(self, bc_loss: nn.Module, expert_buffer: Any, coef: float) -> None:
        if not coef > 0:
            raise ValueError(f"coef must be positive, got {coef!r}.")
        self.bc_loss = bc_loss
        self.expert_buffer = expert_buffer
        self.coef = float(coef)

    def __call__(self, loss_actor: torch.Tensor) -> tuple[dict[str, torch.Tensor], dict[str, torch.Tensor]]:
        with set_exploration_type(ExplorationType.DETERMINISTIC):
            mse = self.bc_loss(self.expert_buffer.sample())["loss_bc"]
        weight = self.coef * loss_actor.detach().abs()
        return {"loss_actor_bc": weight * mse}, {"actor_bc_mse": mse.detach()}
