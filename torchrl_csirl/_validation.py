"""Argument checks shared by several components."""
from __future__ import annotations

from typing import Any

import torch

__all__ = ["validate_subgoal"]


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
