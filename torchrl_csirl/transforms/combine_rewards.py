"""Sums reward entries (matching, intrinsic...) into the training reward."""
from __future__ import annotations

from collections.abc import Sequence

import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey
from torchrl.data import Composite, TensorSpec, Unbounded
from torchrl.envs.transforms import Transform

__all__ = ["CombineRewards"]


class CombineRewards(Transform):
    """Writes ``sum_k weight_k * next[in_key_k]`` into ``next[out_key]`` (default: the reward).

    Keys are relative to the ``"next"`` sub-tensordict, as for the reward itself. Overwriting
    ``"reward"`` keeps ``env.reward_key`` (and the loss's default ``("next", "reward")``) intact:
    the reward spec becomes unbounded float32, nothing else changes. The replaced value can be
    kept under ``keep_original`` (declared as an observation) for logging.

    Use it after :class:`~torchrl_csirl.transforms.SubgoalMatchingReward` and
    :class:`~torchrl_csirl.transforms.IntrinsicReward`, in a
    :class:`~torchrl.envs.TransformedEnv` or as a replay-buffer transform (then :meth:`forward`
    works on the sampled transitions' ``"next"`` entries).

    Args:
        in_keys (sequence of NestedKey): the reward entries to add (inside ``"next"``).

    Keyword Args:
        out_key (NestedKey): the entry written (inside ``"next"``). Defaults to ``"reward"``.
        weights (sequence of float, optional): one weight per input. Defaults to ones.
        keep_original (NestedKey, optional): where to keep the previous ``out_key`` value.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> td = TensorDict({"next": {"matching_reward": torch.ones(2, 1),
        ...                           "intrinsic_reward": torch.full((2, 1), 0.5),
        ...                           "reward": torch.zeros(2, 1)}}, [2])
        >>> t = CombineRewards(["matching_reward", "intrinsic_reward"], keep_original="env_reward")
        >>> t(td)["next", "reward"].squeeze(-1).tolist(), td["next", "env_reward"].squeeze(-1).tolist()
        ([1.5, 1.5], [0.0, 0.0])
    """

    def __init__(
        self,
        in_keys: Sequence[NestedKey],
        *,
        out_key: NestedKey = "reward",
        weights: Sequence[float] | None = None,
        keep_original: NestedKey | None = None,
    ) -> None:
        in_keys = list(in_keys)
        if not in_keys:
            raise ValueError("CombineRewards needs at least one in_key.")
        if weights is None:
            weights = [1.0] * len(in_keys)
        weights = [float(w) for w in weights]
        if len(weights) != len(in_keys):
            raise ValueError(f"got {len(weights)} weights for {len(in_keys)} in_keys.")
        super().__init__(in_keys=in_keys, out_keys=[out_key])
        self.weights = weights
        self.keep_original = keep_original

    def _combine(self, next_tensordict: TensorDictBase) -> TensorDictBase:
        total = None
        for key, weight in zip(self.in_keys, self.weights):
            value = next_tensordict.get(key, None)
            if value is None:
                raise KeyError(f"CombineRewards: {key!r} not found in the 'next' entries.")
            value = weight * value.to(torch.float32)
            total = value if total is None else total + value
        out_key = self.out_keys[0]
        if self.keep_original is not None:
            original = next_tensordict.get(out_key, None)
            if original is not None:
                next_tensordict.set(self.keep_original, original)
        next_tensordict.set(out_key, total)
        return next_tensordict

    def _call(self, next_tensordict: TensorDictBase) -> TensorDictBase:
        return self._combine(next_tensordict)

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        next_tensordict = tensordict.get("next", None)
        if next_tensordict is None:
            raise KeyError("CombineRewards needs a 'next' sub-tensordict (a transition).")
        self._combine(next_tensordict)
        return tensordict

    def _reset(self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase) -> TensorDictBase:
        if self.keep_original is not None:
            tensordict_reset.set(
                self.keep_original,
                torch.zeros(*tensordict_reset.batch_size, 1, device=tensordict_reset.device),
            )
        return tensordict_reset

    def transform_reward_spec(self, reward_spec: TensorSpec) -> TensorSpec:
        out_key = self.out_keys[0]
        if isinstance(reward_spec, Composite) and out_key in reward_spec.keys(True):
            old = reward_spec[out_key]
            reward_spec[out_key] = Unbounded(shape=old.shape, dtype=torch.float32, device=old.device)
        return reward_spec

    def transform_observation_spec(self, observation_spec: TensorSpec) -> TensorSpec:
        if self.keep_original is not None:
            parent = self.parent
            shape = (*observation_spec.shape, 1)
            if parent is not None and self.out_keys[0] in parent.full_reward_spec.keys(True):
                shape = parent.full_reward_spec[self.out_keys[0]].shape
            observation_spec[self.keep_original] = Unbounded(
                shape=shape, dtype=torch.float32, device=observation_spec.device
            )
        return observation_spec
