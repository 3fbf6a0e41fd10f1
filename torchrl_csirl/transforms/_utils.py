"""Shared plumbing of the per-transition reward transforms (private)."""
from __future__ import annotations

import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey
from torchrl.data import Composite, TensorSpec, Unbounded
from torchrl.envs.transforms import Transform

__all__ = ["TransitionRewardTransform"]


class TransitionRewardTransform(Transform):
    """Base class of transforms computing a reward from a transition and writing it in ``"next"``.

    Subclasses implement :meth:`_transition_reward` ``(tensordict, next_tensordict) -> [*B, 1]``,
    where ``tensordict`` holds the step's inputs (``"observation"``, ``"action"``) and
    ``next_tensordict`` its outputs (the next ``"observation"``).

    * In a :class:`~torchrl.envs.TransformedEnv`: :meth:`_step` writes ``next_tensordict[out_key]``
      (``("next", out_key)`` in a rollout); the key is declared in the observation spec (so
      ``env.reward_key`` stays the env's single reward) and zero-filled at reset.
    * As a replay-buffer transform (or called directly): :meth:`forward` reads the root
      tensordict and its ``"next"`` sub-tensordict and writes ``("next", out_key)``.
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
        next_tensordict = tensordict.get("next", None)
        if next_tensordict is None:
            raise KeyError(
                f"{type(self).__name__} needs a 'next' sub-tensordict (a transition), got keys "
                f"{list(tensordict.keys())}."
            )
        reward = self._transition_reward(tensordict, next_tensordict)
        tensordict.set(("next", self.out_key), reward.reshape(*tensordict.batch_size, 1))
        return tensordict

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
