"""Argument checks shared by several components."""
from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import torch
from tensordict import TensorDictBase

__all__ = ["SubgoalSource", "expert_observation_tensor", "validate_subgoal"]


def validate_subgoal(subgoal: Any, length: int) -> int:
    """Returns ``subgoal`` as an int in ``[0, length - 1]``, or raises a clear error.

    Accepts Python ints and one-element integer tensors.

    Examples:
        >>> validate_subgoal(torch.tensor(3), 10)
        3
    """
    if isinstance(subgoal, torch.Tensor) and subgoal.numel() == 1 and not subgoal.is_floating_point():
        subgoal = int(subgoal.item())
    if isinstance(subgoal, bool) or not isinstance(subgoal, int):
        raise TypeError(f"subgoal must be an int, got {type(subgoal).__name__}.")
    if not 0 <= subgoal < length:
        raise ValueError(f"subgoal must be in [0, {length - 1}], got {subgoal}.")
    return int(subgoal)


@runtime_checkable
class SubgoalSource(Protocol):
    """What owns the current subgoal (e.g. :class:`~torchrl_csirl.curriculum.SubgoalCurriculum`):
    readers such as :class:`~torchrl_csirl.transforms.SubgoalMatchingReward` read ``subgoal``."""

    subgoal: int


def expert_observation_tensor(expert: Any, include_final: bool) -> torch.Tensor:
    """``[L, D]`` states from a tensor, a trajectory TensorDict or an ExpertDemonstrations.

    Shared by the matching reward and the curriculum, which both read a curriculum trajectory.

    Examples:
        >>> expert_observation_tensor([[0.0, 1.0], [2.0, 3.0]], include_final=False).shape
        torch.Size([2, 2])
    """
    from torchrl_csirl.data.expert import ExpertDemonstrations

    if isinstance(expert, ExpertDemonstrations):
        return expert.trajectory_observations(0, include_final=include_final)
    if isinstance(expert, TensorDictBase):
        obs = expert.get("observation")
        if include_final:
            obs = torch.cat([obs, expert.get(("next", "observation"))[-1:]], 0)
        return obs
    try:
        return torch.as_tensor(expert)
    except Exception as err:  # noqa: BLE001
        raise TypeError(
            "expert_observations must be a [L, D] tensor, a trajectory TensorDict or "
            f"ExpertDemonstrations, got {type(expert).__name__}."
        ) from err
