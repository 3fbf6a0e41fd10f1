"""Training batches that mix online transitions with expert transitions, rewarded alike."""
from __future__ import annotations

import warnings
from collections.abc import Callable

import torch
from tensordict import TensorDictBase

__all__ = ["DemonstrationMixer"]


class DemonstrationMixer:
    """Samples SAC batches made of online transitions and a fixed share of expert transitions.

    Each :meth:`sample` draws ``batch_size - n`` transitions from ``online`` and ``n =
    round(expert_fraction * batch_size)`` from ``expert``, passes the expert part through
    ``transform`` (the online buffer's reward transforms, e.g. the matching reward for the
    *current* subgoal and ``r_w``, so that both parts are rewarded by the same function) and
    concatenates the entries the two parts share. The environment reward is never used.

    This is "RL from demonstrations" in the style of DDPGfD / RLPD: the critic sees the expert's
    transitions (in merge, the manoeuvre past the slow vehicles) from the first update on,
    instead of waiting for the policy to stumble on them. It is not in the CSIRL paper nor in its
    published code (the recipe key ``replay_buffer.expert_fraction=0``, as in ``preset=paper``, turns it off).

    Args:
        online: the online replay buffer (its ``sample(batch_size)`` applies its own transform).
        expert: a replay buffer of expert transitions (e.g.
            :meth:`~torchrl_csirl.data.ExpertDemonstrations.as_replay_buffer`); its own
            transform, if any, runs first.
        expert_fraction: share of expert transitions in every batch, in ``[0, 1)``.
        batch_size: transitions per batch (defaults to the online buffer's batch size).
        transform: applied to the expert part (defaults to the online buffer's transform).

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
        >>> def transitions(n, value):
        ...     return TensorDict({"observation": torch.full((n, 2), value), "action": torch.zeros(n, 1),
        ...                        "next": {"observation": torch.zeros(n, 2)}}, [n])
        >>> online = TensorDictReplayBuffer(storage=LazyTensorStorage(100), batch_size=8)
        >>> _ = online.extend(transitions(50, 0.0))
        >>> expert = TensorDictReplayBuffer(storage=LazyTensorStorage(100), batch_size=8)
        >>> _ = expert.extend(transitions(20, 1.0))
        >>> batch = DemonstrationMixer(online, expert, expert_fraction=0.25).sample()
        >>> batch.batch_size, int(batch["observation"][:, 0].sum())  # 6 online + 2 expert
        (torch.Size([8]), 2)
    """

    def __init__(
        self,
        online: object,
        expert: object,
        expert_fraction: float,
        *,
        batch_size: int | None = None,
        transform: Callable[[TensorDictBase], TensorDictBase] | None = None,
    ) -> None:
        if not 0.0 <= float(expert_fraction) < 1.0:
            raise ValueError(f"expert_fraction must be in [0, 1), got {expert_fraction!r}.")
        batch_size = online.batch_size if batch_size is None else batch_size
        if not isinstance(batch_size, int) or batch_size <= 0:
            raise ValueError(f"batch_size must be a positive int (or the online buffer's), got {batch_size!r}.")
        self.online = online
        self.expert = expert
        self.expert_fraction = float(expert_fraction)
        self.batch_size = batch_size
        self.num_expert = round(self.expert_fraction * batch_size)
        self.transform = online.transform if transform is None else transform

    def sample(self) -> TensorDictBase:
        """A batch of ``batch_size`` transitions, the expert ones last."""
        if not self.num_expert:
            return self.online.sample(self.batch_size)
        with warnings.catch_warnings():
            # the buffers' own batch sizes differ from the shares asked for here, on purpose
            warnings.filterwarnings("ignore", message="Got conflicting batch_sizes")
            online = self.online.sample(self.batch_size - self.num_expert)
            expert = self.transform(self.expert.sample(self.num_expert))
        keys = [key for key in expert.keys(True, True) if key in online.keys(True, True)]
        return torch.cat([online.select(*keys), expert.select(*keys)], 0)
