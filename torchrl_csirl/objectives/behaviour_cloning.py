"""Behavioural cloning for the actor: a term weighted like TD3+BC, and a warm start before training (options of the
CSIRL recipe)."""
from __future__ import annotations

from typing import Any

import torch
from tensordict import TensorDictBase
from torch import nn
from torchrl.envs.utils import ExplorationType, set_exploration_type

__all__ = ["ActorBehaviourCloning", "pretrain_actor"]


class ActorBehaviourCloning:
    """A behavioural-cloning term for the actor, scaled like TD3+BC: ``coef * scale * BC``.

    ``BC`` is the mean squared error between the deterministic action of the policy and the
    expert's action on an expert batch (TorchRL's :class:`~torchrl.objectives.BCLoss` with
    ``loss_function="l2"``). Its weight follows the size of the actor's Q objective, as TD3+BC divides
    the Q term by ``mean |Q|``, so ``coef`` does not depend on the reward scale of a scenario (TD3+BC's
    offline setting corresponds to ``coef = 0.4``). ``scale`` is, without ``critic``, ``|L_actor|`` =
    ``|mean(alpha log pi - min_k Q_k)|`` (detached): it vanishes where the batch's values of either sign
    cancel, at the start (critics near zero) and where the values cross zero; with ``critic``, TD3+BC's
    own ``mean |min_k Q_k(s, mu(s))|`` over the training batch, ``mu`` the deterministic action (no
    cancellation; ``csirl.actor_bc_scale=qvalue``). Not in the CSIRL paper nor in its code: it is the
    learned reward's outer objective (Eq. 11) applied to the actor directly, so that the policy
    imitates the expert where the demonstrations cover the state space (``csirl.actor_bc_coef``).

    Args:
        bc_loss: a :class:`~torchrl.objectives.BCLoss` over the actor.
        expert_buffer: replay buffer of expert ``(observation, action)`` pairs.
        coef: the weight relative to the scale.

    Keyword Args:
        critic: the :class:`~torchrl_csirl.objectives.EnsembleSACLoss` whose critics give TD3+BC's
            scale (its ``qvalues``); ``None`` (default): ``|L_actor|``.

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
        >>> sorted(losses), sorted(logs), round(logs["actor_bc_weight"].item(), 3)
        (['loss_actor_bc'], ['actor_bc_mse', 'actor_bc_weight'], 20.0)
    """

    def __init__(self, bc_loss: nn.Module, expert_buffer: Any, coef: float, *, critic: nn.Module | None = None) -> None:
        if not coef > 0:
            raise ValueError(f"coef must be positive, got {coef!r}.")
        self.bc_loss = bc_loss
        self.expert_buffer = expert_buffer
        self.coef = float(coef)
        self.critic = critic

    def qvalue_scale(self, batch: TensorDictBase) -> torch.Tensor:
        """TD3+BC's ``mean |min_k Q_k(s, mu(s))|`` over ``batch``'s observations (no gradient)."""
        actor = self.bc_loss.actor_network
        with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
            acted = actor(batch.select(*actor.in_keys).copy())
            return self.critic.qvalues(acted).min(0).values.abs().mean()

    def __call__(self, loss_actor: torch.Tensor, batch: TensorDictBase | None = None
                 ) -> tuple[dict[str, torch.Tensor], dict[str, torch.Tensor]]:
        """The term and its diagnostics for an update whose actor loss is ``loss_actor`` on ``batch`` (the training
        batch: needed with ``critic``)."""
        if self.critic is None:
            scale = loss_actor.detach().abs()
        elif batch is None:
            raise ValueError("ActorBehaviourCloning with a critic scales by the training batch's Q: pass batch=.")
        else:
            scale = self.qvalue_scale(batch)
        with set_exploration_type(ExplorationType.DETERMINISTIC):
            mse = self.bc_loss(self.expert_buffer.sample())["loss_bc"]
        weight = self.coef * scale
        return {"loss_actor_bc": weight * mse}, {"actor_bc_mse": mse.detach(), "actor_bc_weight": weight}


def pretrain_actor(actor: nn.Module, expert_buffer: Any, updates: int, *, lr: float = 3e-4, batch_size: int = 256,
                   loss_function: str = "l2", progress_bar: bool = False) -> float:
    """Behavioural cloning of ``actor`` on the expert's ``(observation, action)`` pairs for ``updates`` Adam steps: a
    warm start, so that reinforcement learning begins from a policy that already imitates (``csirl.actor_pretrain_updates``).

    The actor's deterministic action is regressed on the expert's (TorchRL's :class:`~torchrl.objectives.BCLoss`),
    with an Adam optimiser of its own, discarded afterwards. Not in the CSIRL paper nor in its code.

    Args:
        actor: the policy (its parameters are trained in place: a loss built over it sees them).
        expert_buffer: replay buffer of expert transitions (``sample(batch_size)``).
        updates: gradient steps (0: nothing is done).
        lr: Adam's learning rate.
        batch_size: expert pairs per step.
        loss_function: ``"l2"`` or ``"l1"``.
        progress_bar: a progress bar over the updates (tqdm).

    Returns:
        float: the last batch's cloning loss (NaN when ``updates`` is 0).

    Examples:
        >>> import torch
        >>> from torchrl_csirl.data import ExpertDemonstrations
        >>> from torchrl_csirl.modules import make_actor
        >>> ep = {"observation": torch.zeros(5, 4), "action": torch.full((5, 2), 0.5),
        ...       "next_observation": torch.ones(5, 4), "terminated": torch.zeros(5, dtype=torch.bool)}
        >>> expert = ExpertDemonstrations.from_episodes([ep]).as_replay_buffer(batch_size=4)
        >>> _ = torch.manual_seed(0)
        >>> pretrain_actor(make_actor(4, 2), expert, 200, lr=1e-3, batch_size=5) < 1e-3
        True
    """
    from torchrl.objectives import BCLoss
    from tqdm.auto import trange

    if updates < 0:
        raise ValueError(f"updates must be >= 0, got {updates!r}.")
    loss = BCLoss(actor, loss_function=loss_function)
    optimizer = torch.optim.Adam(actor.parameters(), lr=lr)
    last = torch.tensor(float("nan"))
    with set_exploration_type(ExplorationType.DETERMINISTIC):
        for _ in trange(updates, desc="actor warm start", unit="update", disable=not progress_bar):
            last = loss(expert_buffer.sample(batch_size))["loss_bc"]
            optimizer.zero_grad(set_to_none=True)
            last.backward()
            optimizer.step()
    return float(last.detach())
