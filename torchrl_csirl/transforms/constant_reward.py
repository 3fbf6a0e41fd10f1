"""A constant reward label for every transition (SQIL's expert 1 / online 0)."""
from __future__ import annotations

import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey
from torchrl.envs.transforms import Transform

__all__ = ["ConstantReward"]


class ConstantReward(Transform):
    """Writes the constant ``value`` under ``("next", out_key)`` of every transition.

    SQIL (Reddy et al., 2020, Algorithm 1) labels every demonstrated transition with reward 1 and
    every transition of the agent with reward 0: append ``ConstantReward(1.0)`` to the expert
    replay buffer and ``ConstantReward(0.0)`` to the online one. The environment reward, if any, is
    overwritten.

    Args:
        value (float): the reward of every transition.

    Keyword Args:
        out_key (NestedKey): the key written inside ``"next"``. Defaults to ``"reward"``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> td = TensorDict({"observation": torch.zeros(3, 2), "next": {"observation": torch.zeros(3, 2)}}, [3])
        >>> ConstantReward(1.0)(td)["next", "reward"].squeeze(-1).tolist()
        [1.0, 1.0, 1.0]
    """

    def __init__(self, value: float, *, out_key: NestedKey = "reward") -> None:
        super().__init__(in_keys=[], out_keys=[out_key])
        self.value = float(value)

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        if "next" not in tensordict.keys():
            raise KeyError(f"ConstantReward needs a 'next' sub-tensordict (a transition), got keys {list(tensordict.keys())}.")
        label = torch.full((*tensordict.batch_size, 1), self.value, device=tensordict.device)
        tensordict.set(("next", self.out_keys[0]), label)
        return tensordict

    def _call(self, next_tensordict: TensorDictBase) -> TensorDictBase:
        next_tensordict.set(self.out_keys[0], torch.full((*next_tensordict.batch_size, 1), self.value,
                                                         device=next_tensordict.device))
        return next_tensordict
