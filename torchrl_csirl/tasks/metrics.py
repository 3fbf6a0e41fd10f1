"""The paper's evaluation metric: the test accomplish rate (and success, AUC).

The accomplish rate of one episode is the fraction of the route to the finish position the
ego vehicle covered::

    clip((d_0 - d_min) / d_0, 0, 1)

with ``d`` the Euclidean distance of the ego vehicle to the scenario's finish position,
``d_0`` its value at reset and ``d_min`` the smallest value reached during the episode. The
scenarios report ``d`` as ``info["distance_to_finish"]``; :func:`make_env` puts it in the
TensorDict as ``"distance_to_finish"`` (reset) and ``("next", "distance_to_finish")``.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
import torch
from tensordict import TensorDictBase

__all__ = [
    "accomplish_rate",
    "accomplish_rate_from_rollout",
    "area_under_curve",
    "episode_success",
    "normalized_accomplish_rate",
    "success_from_rollout",
]


def _as_tensor(values) -> torch.Tensor:
    if isinstance(values, torch.Tensor):
        return values.to(torch.float64)
    return torch.as_tensor(np.asarray(values, dtype=np.float64))


def accomplish_rate(distances: Sequence[float] | np.ndarray | torch.Tensor) -> float | torch.Tensor:
    """Accomplish rate ``clip((d_0 - d_min) / d_0, 0, 1)`` of one or several episodes.

    Args:
        distances: distances to the finish position along an episode, the first entry being
            the distance at reset; shape ``(T,)`` for one episode or ``(*batch, T)`` for several
            of equal length. ``NaN`` entries (padding) are ignored.

    Returns:
        a float for a sequence/1-d input, else a tensor of shape ``batch`` (float64).
        An episode starting at the finish (``d_0 == 0``) scores 1.

    Examples:
        >>> accomplish_rate([100.0, 80.0, 30.0, 50.0])
        0.7
        >>> accomplish_rate([10.0, 12.0])  # moved away: clipped to 0
        0.0
        >>> import torch
        >>> accomplish_rate(torch.tensor([[4.0, 2.0], [4.0, 0.0]])).tolist()
        [0.5, 1.0]
    """
    d = _as_tensor(distances)
    if d.ndim == 0 or d.shape[-1] == 0:
        raise ValueError(
            f"accomplish_rate expects at least one distance per episode, got shape {tuple(d.shape)}."
        )
    if torch.isnan(d[..., 0]).any():
        raise ValueError("accomplish_rate: the reset distance d_0 must not be NaN.")
    if (d[..., 0] < 0).any():
        raise ValueError("accomplish_rate: distances must be non-negative.")
    d0 = d[..., 0]
    d_min = torch.where(torch.isnan(d), torch.full_like(d, float("inf")), d).amin(-1)
    rate = torch.where(d0 > 0, (d0 - d_min) / d0.clamp_min(1e-12), torch.ones_like(d0))
    rate = rate.clamp(0.0, 1.0)
    if d.ndim == 1:
        return float(rate)
    return rate


def _first_episode_mask(done: torch.Tensor) -> torch.Tensor:
    """True for steps up to and including the first done of each row (time = last dim)."""
    done = done.to(torch.int64)
    before = torch.cumsum(done, dim=-1) - done  # dones strictly before t
    return before == 0


def accomplish_rate_from_rollout(
    rollout: TensorDictBase, key: str = "distance_to_finish"
) -> torch.Tensor:
    """Accomplish rate of the first episode in each row of a TorchRL rollout.

    Args:
        rollout: TensorDict of shape ``(*batch, T)`` (time last), e.g. from
            ``env.rollout(max_steps)``, holding ``key`` (distance at each step's root, the first
            being the reset value) and ``("next", key)``; ``("next", "done")`` if present
            delimits the first episode (later steps, e.g. after an auto-reset, are ignored).
        key: the distance entry.

    Returns:
        tensor of shape ``batch`` (float64).

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> td = TensorDict({
        ...     "distance_to_finish": torch.tensor([[10.0], [8.0], [5.0]]),
        ...     "next": {"distance_to_finish": torch.tensor([[8.0], [5.0], [6.0]]),
        ...              "done": torch.tensor([[False], [False], [True]])},
        ... }, batch_size=[3])
        >>> accomplish_rate_from_rollout(td).item()
        0.5
    """
    if key not in rollout.keys() or ("next", key) not in rollout.keys(True):
        raise KeyError(
            f"accomplish_rate_from_rollout needs {key!r} and ('next', {key!r}) in the rollout."
        )
    if rollout.ndim == 0:
        raise ValueError("accomplish_rate_from_rollout expects a rollout with a time dimension.")
    root = rollout.get(key).to(torch.float64)
    nxt = rollout.get(("next", key)).to(torch.float64)
    if root.shape[-1] == 1 and root.ndim == rollout.ndim + 1:
        root, nxt = root.squeeze(-1), nxt.squeeze(-1)
    if ("next", "done") in rollout.keys(True):
        done = rollout.get(("next", "done")).reshape(nxt.shape)
        nxt = torch.where(_first_episode_mask(done), nxt, torch.full_like(nxt, float("nan")))
    distances = torch.cat([root[..., :1], nxt], dim=-1)
    out = accomplish_rate(distances)
    return out if isinstance(out, torch.Tensor) else torch.tensor(out, dtype=torch.float64)


def success_from_rollout(rollout: TensorDictBase, key: str = "success") -> torch.Tensor:
    """Whether the first episode of each rollout row reached the finish area without crashing.

    Args:
        rollout: TensorDict ``(*batch, T)`` with ``("next", key)`` (and optionally
            ``("next", "done")`` delimiting the first episode).
        key: the success flag written by the scenarios.

    Returns:
        bool tensor of shape ``batch``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> td = TensorDict({"next": {"success": torch.tensor([[False], [True]])}}, batch_size=[2])
        >>> success_from_rollout(td).item()
        True
    """
    if ("next", key) not in rollout.keys(True):
        raise KeyError(f"success_from_rollout needs ('next', {key!r}) in the rollout.")
    flag = rollout.get(("next", key))
    flag = flag.reshape(flag.shape[: rollout.ndim]).bool()
    if ("next", "done") in rollout.keys(True):
        done = rollout.get(("next", "done")).reshape(flag.shape)
        flag = flag & _first_episode_mask(done)
    return flag.any(-1)


def normalized_accomplish_rate(rate, expert_rate) -> float | torch.Tensor:
    """Accomplish rate divided by the expert's (the paper's table reports expert = 1.00).

    Examples:
        >>> normalized_accomplish_rate(0.45, 0.9)
        0.5
    """
    expert = _as_tensor(expert_rate)
    if (expert <= 0).any():
        raise ValueError(f"expert_rate must be positive, got {expert_rate}.")
    out = _as_tensor(rate) / expert
    return float(out) if out.ndim == 0 else out


def area_under_curve(rates: Sequence[float] | torch.Tensor) -> float:
    """AUC of a run: the mean accomplish rate over its successive evaluations.

    Examples:
        >>> area_under_curve([0.0, 0.5, 1.0])
        0.5
    """
    r = _as_tensor(rates)
    if r.numel() == 0:
        raise ValueError("area_under_curve needs at least one evaluation.")
    return float(r.mean())


def episode_success(rollout: TensorDictBase) -> torch.Tensor:
    """The first episode's success: the task's ``"success"`` flag, else a termination that is not a
    truncation (a task of your own without the flag).

    Examples:
        >>> from tensordict import TensorDict
        >>> import torch
        >>> td = TensorDict({"next": {"terminated": torch.tensor([False, True]),
        ...                           "truncated": torch.tensor([False, False])}}, batch_size=[2])
        >>> bool(episode_success(td))
        True
    """
    keys = rollout.keys(True)
    if ("next", "success") in keys:
        return success_from_rollout(rollout)
    if ("next", "terminated") not in keys:
        return torch.zeros(rollout.shape[:-1], dtype=torch.bool)
    terminated = rollout.get(("next", "terminated")).reshape(rollout.shape).bool()
    if ("next", "truncated") in keys:
        terminated = terminated & ~rollout.get(("next", "truncated")).reshape(rollout.shape).bool()
    return terminated.any(-1)

