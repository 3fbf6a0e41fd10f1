"""The CSIRL steps as :class:`~torchrl_csirl.trainers.CSIRLTrainer` hooks.

* :class:`SACUpdate` / :class:`MetaRewardUpdate`: the trainer's ``update_step``;
* :class:`SubgoalSelectionHook`: ``round_end``, the curricular subgoal selection (Alg. 1);
* :class:`EvaluationHook`: ``round_end``, the deterministic policy's accomplish rate;
* :class:`CheckpointHook`: ``post_round`` and ``train_end``, atomic checkpoints with the
  replay buffer, for exact resume.
"""
from __future__ import annotations

import os
import shutil
from collections.abc import Callable
from typing import Any

import torch
from tensordict import TensorDictBase
from torch import nn
from torchrl.envs.utils import ExplorationType, set_exploration_type

from torchrl_csirl.trainers.trainer import CSIRLTrainer, check_finite_losses

__all__ = [
    "ActorBehaviourCloning",
    "CheckpointHook",
    "EvaluationHook",
    "MetaRewardUpdate",
    "SACUpdate",
    "SubgoalSelectionHook",
    "load_checkpoint",
]


def _detached(out: TensorDictBase, keys: tuple[str, ...]) -> dict[str, torch.Tensor]:
    return {key: out.get(key).detach() for key in keys if key in out.keys()}


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
    """

    LOSS_KEYS = ("loss_qvalue", "loss_actor", "loss_alpha")
    LOG_KEYS = ("alpha", "entropy")

    def __init__(self, loss: nn.Module, optimizer: torch.optim.Optimizer, target_updater: Any,
                 max_grad_norm: float | None = None,
                 sample: Callable[[], TensorDictBase] | None = None,
                 actor_bc: ActorBehaviourCloning | None = None) -> None:
        self.loss = loss
        self.optimizer = optimizer
        self.target_updater = target_updater
        self.max_grad_norm = max_grad_norm
        self._sample = sample
        self.actor_bc = actor_bc

    def sample(self, trainer: CSIRLTrainer) -> TensorDictBase:
        """A training batch: ``sample()`` if given, else one of the trainer's online buffer."""
        return self._sample() if self._sample is not None else trainer.online_buffer.sample()

    def with_actor_bc(self, losses: dict[str, torch.Tensor]) -> tuple[dict[str, torch.Tensor], dict[str, torch.Tensor]]:
        """``losses`` with the behavioural-cloning term (if any), and its diagnostics."""
        if self.actor_bc is None:
            return losses, {}
        bc_losses, logs = self.actor_bc(losses["loss_actor"])
        return {**losses, **bc_losses}, logs

    def step(self, losses: dict[str, torch.Tensor], trainer: CSIRLTrainer) -> None:
        """Checks, backpropagates and applies ``losses`` (sum) with the SAC optimiser."""
        check_finite_losses(losses, f"update {trainer.updates + 1} (frames {trainer.frames})")
        self.optimizer.zero_grad(set_to_none=True)
        sum(losses.values()).backward()
        if self.max_grad_norm is not None:
            params = [p for group in self.optimizer.param_groups for p in group["params"]]
            torch.nn.utils.clip_grad_norm_(params, self.max_grad_norm)
        self.optimizer.step()
        self.target_updater.step()

    def __call__(self, trainer: CSIRLTrainer) -> dict[str, torch.Tensor]:
        out = self.loss(self.sample(trainer))
        losses, logs = self.with_actor_bc({key: out.get(key) for key in self.LOSS_KEYS if key in out.keys()})
        self.step(losses, trainer)
        return {**{key: value.detach() for key, value in losses.items()}, **_detached(out, self.LOG_KEYS), **logs}


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
        meta_every: cadence of the meta step (1 = every update, as the paper).
    """

    META_KEYS = ("loss_meta", "loss_imitation", "loss_reward_l1", "intrinsic_reward_mean", "meta_grad_norm",
                 "meta_grad_norm_imitation", "meta_grad_norm_l1")

    def __init__(self, meta_loss: nn.Module, sac_update: SACUpdate, reward_optimizer: torch.optim.Optimizer,
                 expert_buffer: Any, meta_every: int = 1) -> None:
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
        out = self.meta_loss(online, self.expert_buffer.sample(), regularizer=trainer.online_buffer.sample())
        sac_losses, logs = self.sac_update.with_actor_bc(
            {key: out.get(key) for key in SACUpdate.LOSS_KEYS if key in out.keys()})
        meta = out.get("loss_meta")
        check_finite_losses({**sac_losses, "loss_meta": meta}, f"update {trainer.updates + 1} (frames {trainer.frames})")
        self.reward_optimizer.zero_grad(set_to_none=True)
        # one backward: the SAC losses reach the actor/critics, the meta-loss the reward net only
        self.sac_update.step({**sac_losses, "loss_meta": meta}, trainer)
        self.reward_optimizer.step()
        return {**{k: v.detach() for k, v in sac_losses.items()}, **_detached(out, SACUpdate.LOG_KEYS + self.META_KEYS),
                **logs}


class SubgoalSelectionHook:
    """``round_end``: moves the subgoal with the curriculum and updates the matching transform.

    Keeps the selection history (frames, subgoal, uncertainty profile, scan ratios) for the plots,
    records ``subgoal`` and ``subgoal_changed`` in the metrics row and shows the subgoal on the bar.

    Args:
        curriculum: the :class:`~torchrl_csirl.curriculum.SubgoalCurriculum`.
        matching: transforms whose ``set_subgoal`` must follow (the matching reward).
    """

    def __init__(self, curriculum: Any, *matching: Any) -> None:
        self.curriculum = curriculum
        self.matching = matching
        self.history: list[dict[str, Any]] = []
        self._sync()

    def _sync(self) -> None:
        for transform in self.matching:
            transform.set_subgoal(self.curriculum.subgoal)

    def __call__(self, trainer: CSIRLTrainer) -> None:
        selection = self.curriculum.step()
        self._sync()
        self.history.append(
            {
                "frames": trainer.frames,
                "updates": trainer.updates,
                "round": trainer.rounds,
                "subgoal": selection.subgoal,
                "previous": selection.previous,
                "profile": selection.profile.tolist(),
                "ratios": selection.ratios.tolist(),
            }
        )
        trainer.record(subgoal=selection.subgoal, subgoal_changed=int(selection.changed))
        trainer.postfix["subgoal"] = f"{selection.subgoal}/{self.curriculum.length - 1}"

    def state_dict(self) -> dict[str, Any]:
        return {"curriculum": self.curriculum.state_dict(), "history": list(self.history)}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.curriculum.load_state_dict(state["curriculum"])
        self.history = list(state["history"])
        self._sync()


class EvaluationHook:
    """``round_end``: evaluates the policy every ``every_rounds`` rounds.

    Args:
        evaluate: ``callable() -> dict`` of metrics (e.g. a partial of
            :func:`~torchrl_csirl.trainers.evaluate_policy`), holding ``accomplish_rate``.
        every_rounds: evaluation cadence in rounds.
    """

    def __init__(self, evaluate: Callable[[], dict[str, float]], every_rounds: int = 1) -> None:
        if every_rounds < 1:
            raise ValueError(f"every_rounds must be >= 1, got {every_rounds}.")
        self.evaluate = evaluate
        self.every_rounds = int(every_rounds)
        self.history: list[dict[str, Any]] = []

    def run(self, trainer: CSIRLTrainer) -> dict[str, float]:
        """Evaluates now, records ``eval_*`` metrics and the history entry."""
        metrics = self.evaluate()
        self.history.append({"frames": trainer.frames, "updates": trainer.updates, **metrics})
        trainer.record(**{f"eval_{key}": value for key, value in metrics.items()})
        trainer.postfix["eval"] = f"{metrics['accomplish_rate']:.2f}"
        return metrics

    def __call__(self, trainer: CSIRLTrainer) -> None:
        if (trainer.rounds + 1) % self.every_rounds == 0:
            self.run(trainer)

    def state_dict(self) -> dict[str, Any]:
        return {"history": list(self.history)}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.history = list(state["history"])


class CheckpointHook:
    """``post_round`` / ``train_end``: writes the trainer state and the online buffer, atomically.

    The checkpoint is the directory ``<directory>/last``: ``state.pt`` (counters, modules,
    optimisers, curriculum, histories, RNG states) and ``online_buffer/`` (the replay buffer's own
    ``dumps``). It is written to a temporary directory first and swapped in by rename, so a run
    killed while saving keeps its previous checkpoint.

    Args:
        directory: where ``last`` lives (the run's ``checkpoints`` directory).
        online_buffer: buffer to save (None: not saved).
        every_rounds: cadence in rounds (0: only at the end of training).
    """

    def __init__(self, directory: str | os.PathLike, online_buffer: Any = None, every_rounds: int = 1) -> None:
        self.directory = os.fspath(directory)
        self.online_buffer = online_buffer
        self.every_rounds = int(every_rounds)
        self.saved = 0

    @property
    def path(self) -> str:
        return os.path.join(self.directory, "last")

    def save(self, trainer: CSIRLTrainer) -> str:
        """Writes the checkpoint now and returns its path."""
        os.makedirs(self.directory, exist_ok=True)
        tmp = os.path.join(self.directory, "last.tmp")
        shutil.rmtree(tmp, ignore_errors=True)
        os.makedirs(tmp)
        torch.save(trainer.state_dict(), os.path.join(tmp, "state.pt"))
        if self.online_buffer is not None:
            self.online_buffer.dumps(os.path.join(tmp, "online_buffer"))
        old = os.path.join(self.directory, "last.old")
        shutil.rmtree(old, ignore_errors=True)
        if os.path.exists(self.path):
            os.replace(self.path, old)
        os.replace(tmp, self.path)
        shutil.rmtree(old, ignore_errors=True)
        self.saved += 1
        return self.path

    def __call__(self, trainer: CSIRLTrainer) -> None:
        if self.every_rounds and trainer.rounds % self.every_rounds == 0:
            self.save(trainer)


def load_checkpoint(trainer: CSIRLTrainer, path: str | os.PathLike, online_buffer: Any = None) -> None:
    """Restores a :class:`CheckpointHook` checkpoint into a trainer built like the saved one.

    Raises:
        FileNotFoundError: when ``path`` holds no ``state.pt``.
    """
    path = os.fspath(path)
    state_file = os.path.join(path, "state.pt")
    if not os.path.isfile(state_file):
        raise FileNotFoundError(f"No checkpoint at {path!r} (expected {state_file}).")
    buffer_dir = os.path.join(path, "online_buffer")
    if online_buffer is not None and os.path.isdir(buffer_dir):
        online_buffer.loads(buffer_dir)
    trainer.load_state_dict(torch.load(state_file, weights_only=False))
