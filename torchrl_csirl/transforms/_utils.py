"""Shared plumbing of the per-transition reward transforms (private)."""
from __future__ import annotations

import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey
from torchrl.data import Composite, TensorSpec, Unbounded
from torchrl.envs.transforms import Transform

from torchrl_csirl._compat import replay_buffer_prefetch, sampling_replay_buffer

__all__ = ["TransitionRewardTransform", "detached_if_recording", "refuse_prefetching_buffer"]


def refuse_prefetching_buffer(transform: Transform) -> None:
    """A reward transform on a replay buffer that prefetches: one ``ValueError`` line.

    Such a buffer computes the batches it hands out ahead of time, on its own thread, so a batch
    sampled just after a subgoal or a reward-network change would carry the old reward.
    """
    buffer = sampling_replay_buffer()
    prefetch = replay_buffer_prefetch(buffer) if buffer is not None else 0
    if prefetch:
        raise ValueError(
            f"{type(transform).__name__} on a replay buffer with prefetch={prefetch}: the buffer computes its batches "
            "ahead of time on another thread, so a batch sampled after a subgoal or reward-network change would carry "
            "the old reward; build the buffer without prefetch, or keep prefetch without the reward transforms and "
            "apply them to each sampled batch (batch = transform(buffer.sample())).")


def detached_if_recording(tensordict: TensorDictBase) -> TensorDictBase:
    """``tensordict`` without its autograd graph when it carries one (data collected outside ``torch.no_grad()``).

    Stored in a replay buffer, a graph-carrying entry would make the buffer's storage part of the graph,
    and the second backward through sampled data would fail.

    Examples:
        >>> from tensordict import TensorDict
        >>> td = TensorDict({"action": torch.ones(2, requires_grad=True) * 2}, [2])
        >>> detached_if_recording(td)["action"].requires_grad
        False
    """
    if any(value.requires_grad for value in tensordict.values(True, True) if isinstance(value, torch.Tensor)):
        return tensordict.detach()
    return tensordict


class TransitionRewardTransform(Transform):
    """Base class of transforms computing a reward from a transition and writing it in ``"next"``.

    Subclasses implement :meth:`_transition_reward` ``(tensordict, next_tensordict) -> [*B, 1]``,
    where ``tensordict`` holds the step's inputs (``"observation"``, ``"action"``) and
    ``next_tensordict`` its outputs (the next ``"observation"``).

    * In a :class:`~torchrl.envs.TransformedEnv`: :meth:`_step` writes ``next_tensordict[out_key]``
      (``("next", out_key)`` in a rollout); the key is declared in the observation spec (so
      ``env.reward_key`` stays the env's single reward) and zero-filled at reset.
    * As a replay-buffer transform (or called directly): :meth:`forward` reads the root
      tensordict and its ``"next"`` sub-tensordict and writes ``("next", out_key)``, when the batch is
      sampled, with the current subgoal or network; a buffer that prefetches (computing batches ahead
      of time, on another thread) is refused in one line. What ``extend`` stores is detached
      (:meth:`_inv_call`): a rollout collected outside ``torch.no_grad()`` keeps no graph there.
    """

    def __init__(self, in_keys: list[NestedKey], out_key: NestedKey) -> None:
        super().__init__(in_keys=in_keys, out_keys=[out_key])

    @property
    def out_key(self) -> NestedKey:
        return self.out_keys[0]

    def _transition_reward(
        self, tensordict: TensorDictBase, next_tensordict: TensorDictBase
    ) -> torch.Tensor:
        raise NotImplementedError

    def _step(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase) -> TensorDictBase:
        reward = self._transition_reward(tensordict, next_tensordict)
        next_tensordict.set(self.out_key, reward.reshape(*next_tensordict.batch_size, 1))
        return next_tensordict

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        refuse_prefetching_buffer(self)
        next_tensordict = tensordict.get("next", None)
        if next_tensordict is None:
            raise KeyError(
                f"{type(self).__name__} needs a 'next' sub-tensordict (a transition), got keys "
                f"{list(tensordict.keys())}."
            )
        reward = self._transition_reward(tensordict, next_tensordict)
        tensordict.set(("next", self.out_key), reward.reshape(*tensordict.batch_size, 1))
        return tensordict

    def _inv_call(self, tensordict: TensorDictBase) -> TensorDictBase:
        # a replay buffer's extend (and a TransformedEnv's action on its way to the base env)
        return detached_if_recording(super()._inv_call(tensordict))

    def _call(self, next_tensordict: TensorDictBase) -> TensorDictBase:  # pragma: no cover
        raise RuntimeError(f"{type(self).__name__} needs the whole transition; use forward/_step.")

    def _reset(self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase) -> TensorDictBase:
        # the entry is declared in the observation spec: give resets a (meaningless) zero
        tensordict_reset.set(
            self.out_key,
            torch.zeros(*tensordict_reset.batch_size, 1, device=tensordict_reset.device),
        )
        return tensordict_reset

    def transform_observation_spec(self, observation_spec: TensorSpec) -> TensorSpec:
        if not isinstance(observation_spec, Composite):
            raise TypeError(f"expected a Composite observation spec, got {type(observation_spec).__name__}.")
        observation_spec[self.out_key] = Unbounded(
            shape=(*observation_spec.shape, 1), dtype=torch.float32, device=observation_spec.device
        )
        return observation_spec
