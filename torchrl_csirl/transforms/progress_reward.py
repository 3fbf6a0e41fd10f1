"""The "true distance reward" of the paper's SAC baseline: progress toward the scenario's finish.

For a transition ``(s, s')`` and a scenario whose finish position ``f`` (world metres) maps to
``h(f)`` in the observation's normalised coordinates (:meth:`ScenarioSpec.normalize_position`):

    :func:`progress_reward`: ``r = scale * (|| h(s) - h(f) ||_2 - || h(s') - h(f) ||_2)``

with ``h(x)`` the ego's position features of the observation (``x`` on highway-fast and merge,
``(x, y)`` on roundabout and intersection: the scenario spec's ``position_feature_indices``). It
is the CSIRL matching potential (:func:`~torchrl_csirl.transforms.matching_potential`) with the
target fixed at the finish instead of a curricular subgoal, so the two rewards have the same
units; with the default ``scale`` (the scenario's published ``matching_scale``) an episode that
drives from its start to the finish earns about ``scale * || h(s_0) - h(f) ||``. The reward
reads the observation only (no simulator state), so it is defined on any transition, online or
expert, and can be recomputed at sampling time like the other reward transforms.
"""
from __future__ import annotations

from collections.abc import Sequence

import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey

from torchrl_csirl.transforms._utils import TransitionRewardTransform
from torchrl_csirl.transforms.subgoal_matching import matching_potential

__all__ = ["ProgressReward", "progress_reward"]


def progress_reward(positions: torch.Tensor, next_positions: torch.Tensor, finish: torch.Tensor,
                    scale: float = 1.0) -> torch.Tensor:
    """``scale * (psi(s) - psi(s'))`` with ``psi(x) = || h(x) - h(f) ||_2`` (position features selected).

    Args:
        positions (torch.Tensor): ``[B, P]`` position features of ``s``.
        next_positions (torch.Tensor): ``[B, P]`` position features of ``s'``.
        finish (torch.Tensor): ``[P]`` position features of the finish.
        scale (float): reward scale. Defaults to ``1.0``.

    Returns:
        torch.Tensor: ``[B]`` rewards, positive when ``s'`` is closer to the finish.

    Examples:
        >>> progress_reward(torch.tensor([[0.0], [0.5]]), torch.tensor([[0.2], [0.4]]), torch.tensor([1.0]))
        tensor([ 0.2000, -0.1000])
    """
    finish = finish.to(positions)
    return scale * (matching_potential(positions, finish) - matching_potential(next_positions, finish))


class ProgressReward(TransitionRewardTransform):
    """Writes :func:`progress_reward` toward a fixed finish into ``("next", out_key)``.

    Use it as a replay-buffer transform (the SAC baseline's reward, recomputed at sampling time)
    or in a :class:`~torchrl.envs.TransformedEnv`; follow it with
    :class:`~torchrl_csirl.transforms.CombineRewards` to make it the training reward.

    Args:
        finish (sequence of float): the finish position in the observation's normalised
            coordinates, one entry per position feature.
        position_feature_indices (sequence of int): observation entries of the ego position.
        scale (float): reward scale. Defaults to ``1.0``.
        in_key (NestedKey): observation key. Defaults to ``"observation"``.
        out_key (NestedKey): output key inside ``"next"``. Defaults to ``"progress_reward"``.

    Examples:
        >>> from tensordict import TensorDict
        >>> from torchrl_csirl.tasks import SCENARIOS
        >>> t = ProgressReward.from_scenario(SCENARIOS["merge"])  # finish x = 400 m, i.e. 0.8
        >>> obs = torch.zeros(1, 25)
        >>> next_obs = obs.clone()
        >>> next_obs[:, 1] = 0.01  # 5 m closer to the finish
        >>> td = t(TensorDict({"observation": obs, "next": {"observation": next_obs}}, [1]))
        >>> round(td["next", "progress_reward"].item(), 4)
        5.0
    """

    def __init__(self, finish: Sequence[float], position_feature_indices: Sequence[int], *, scale: float = 1.0,
                 in_key: NestedKey = "observation", out_key: NestedKey = "progress_reward") -> None:
        super().__init__(in_keys=[in_key], out_key=out_key)
        finish = torch.as_tensor(finish, dtype=torch.float32).reshape(-1)
        indices = torch.as_tensor(position_feature_indices, dtype=torch.long).reshape(-1)
        if finish.numel() != indices.numel() or indices.numel() == 0:
            raise ValueError(f"finish has {finish.numel()} entries but position_feature_indices has "
                             f"{indices.numel()}: give one finish coordinate per position feature.")
        if not torch.isfinite(finish).all():
            raise ValueError(f"finish must be finite, got {finish.tolist()}.")
        self.register_buffer("finish", finish)
        self.register_buffer("_pos_idx", indices)
        self.scale = float(scale)

    @classmethod
    def from_scenario(cls, spec, scale: float | None = None, **kwargs) -> ProgressReward:
        """Toward ``spec.finish_position`` on ``spec.position_feature_indices``; ``scale`` defaults to
        ``spec.matching_scale`` (the CSIRL matching reward's units)."""
        return cls(spec.normalize_position(spec.finish_position).tolist(), spec.position_feature_indices,
                   scale=spec.matching_scale if scale is None else scale, **kwargs)

    def _transition_reward(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase) -> torch.Tensor:
        key = self.in_keys[0]
        obs, next_obs = tensordict.get(key), next_tensordict.get(key)
        positions = obs.index_select(-1, self._pos_idx.to(obs.device)).to(self.finish.dtype)
        next_positions = next_obs.index_select(-1, self._pos_idx.to(obs.device)).to(self.finish.dtype)
        return progress_reward(positions, next_positions, self.finish, self.scale)

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(finish={self.finish.tolist()}, position_feature_indices="
                f"{self._pos_idx.tolist()}, scale={self.scale}, out_key={self.out_key!r})")
