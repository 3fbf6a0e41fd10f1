"""Applies the learned intrinsic reward r_w to transitions, as an env or replay-buffer transform."""
from __future__ import annotations

import contextlib

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from tensordict.utils import NestedKey

from torchrl_csirl.transforms._utils import TransitionRewardTransform

__all__ = ["IntrinsicReward"]


class IntrinsicReward(TransitionRewardTransform):
    """Writes ``r_w(s)`` (or ``r_w(s, a)``) of each transition under ``("next", out_key)``.

    The reward network reads its ``in_keys`` (``"observation"``, optionally ``"action"``) from the
    step's input tensordict (the state ``s`` and action ``a`` of the transition). The network is
    held by reference: updates made by the meta-gradient step are visible at the next call.
    Keep the transform in the main process (a :class:`~torchrl.envs.TransformedEnv` over a
    serial/parallel env, or a replay-buffer transform); recomputing at sampling time is the
    usual choice since ``r_w`` changes every update.

    Args:
        reward_network (TensorDictModuleBase): e.g.
            :func:`~torchrl_csirl.modules.make_reward_network`.

    Keyword Args:
        out_key (NestedKey): key written inside ``"next"``. Defaults to ``"intrinsic_reward"``.
        no_grad (bool): evaluate without building a graph. Defaults to ``True``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl_csirl.modules.reward import make_reward_network
        >>> t = IntrinsicReward(make_reward_network(3))
        >>> td = TensorDict({"observation": torch.randn(4, 3),
        ...                  "next": {"observation": torch.randn(4, 3)}}, [4])
        >>> r = t(td)["next", "intrinsic_reward"]
        >>> r.shape, r.requires_grad
        (torch.Size([4, 1]), False)
    """

    def __init__(
        self,
        reward_network: TensorDictModuleBase,
        *,
        out_key: NestedKey = "intrinsic_reward",
        no_grad: bool = True,
    ) -> None:
        if not isinstance(reward_network, TensorDictModuleBase):
            raise TypeError(
                f"reward_network must be a TensorDictModule, got {type(reward_network).__name__}."
            )
        if len(reward_network.out_keys) < 1:
            raise ValueError("reward_network must have an out_key.")
        super().__init__(in_keys=list(reward_network.in_keys), out_key=out_key)
        self.reward_network = reward_network
        self.no_grad = bool(no_grad)

    def _transition_reward(
        self, tensordict: TensorDictBase, next_tensordict: TensorDictBase
    ) -> torch.Tensor:
        inputs = tensordict.select(*self.reward_network.in_keys, strict=True)
        context = torch.no_grad() if self.no_grad else contextlib.nullcontext()
        with context:
            out = self.reward_network(inputs)
        return out.get(self.reward_network.out_keys[0])
