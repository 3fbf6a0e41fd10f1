"""The matching reward of a goal-conditioned task: each transition matched against the demonstration of its goal.

CSIRL (paper and published code) follows one curriculum trajectory: every episode is shaped toward that
demonstration's states and goal. A goal-conditioned task (PointMaze: a new goal cell every episode, read from the
observation's ``desired_goal``) then pays the policy for going to the first demonstration's goal whatever the
episode's own (docs/studies/outside-driving.md measures it). This extension of ours keeps the curriculum on the
first demonstration and matches each transition against the demonstration whose goal is nearest the transition's:

1. :func:`nearest_goal_demonstration`: ``k = argmin_k || goal(s) - goal(tau_k) ||`` on the goal features;
2. :func:`subgoal_on_demonstration`: the curriculum's subgoal ``g`` on the first demonstration (length ``L_0``) as
   the same fraction of demonstration ``k``: ``g_k = round(g (L_k - 1) / (L_0 - 1))``;
3. the matching reward of :mod:`~torchrl_csirl.transforms.subgoal_matching` on ``tau_k`` toward ``g_k``.

With demonstrations that share one goal the first one is not always chosen (their goals differ by the task's
noise), which is as good: each is a path to that goal.
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch
from tensordict import TensorDictBase

from torchrl_csirl._validation import SubgoalSource
from torchrl_csirl.transforms.subgoal_matching import (
    SubgoalMatchingReward,
    _check_indices,
    _path_geometry,
    _project,
    distinct_expert_states,
    failed_termination_potential,
    matching_potential,
    matching_target_index,
)

__all__ = ["GoalConditionedMatchingReward", "nearest_goal_demonstration", "subgoal_on_demonstration"]


def nearest_goal_demonstration(goals: torch.Tensor, demonstration_goals: torch.Tensor) -> torch.Tensor:
    """Index of the demonstration whose goal is nearest each goal (Euclidean; ties to the first).

    Args:
        goals (torch.Tensor): ``[B, G]`` the transitions' goals.
        demonstration_goals (torch.Tensor): ``[K, G]`` each demonstration's goal.

    Returns:
        torch.Tensor: ``[B]`` int64 indices in ``[0, K-1]``.

    Examples:
        >>> import torch
        >>> nearest_goal_demonstration(torch.tensor([[0.9, 0.0], [0.0, 0.2]]), torch.tensor([[0.0, 0.0], [1.0, 0.0]]))
        tensor([1, 0])
    """
    return torch.cdist(goals, demonstration_goals.to(goals.dtype)).argmin(dim=-1)


def subgoals_on_demonstrations(subgoal: int, curriculum_length: int, lengths: torch.Tensor) -> torch.Tensor:
    """:func:`subgoal_on_demonstration` for a ``[B]`` tensor of demonstration lengths (the same rounding)."""
    if curriculum_length <= 1:
        return lengths - 1
    share = torch.round(subgoal * (lengths - 1).double() / (curriculum_length - 1)).long()
    return torch.minimum(share, lengths - 1)


def subgoal_on_demonstration(subgoal: int, curriculum_length: int, length: int) -> int:
    """The curriculum's subgoal (on a trajectory of ``curriculum_length`` states) as the same share of a
    demonstration of ``length`` states.

    Examples:
        >>> subgoal_on_demonstration(50, 101, 41), subgoal_on_demonstration(100, 101, 41), subgoal_on_demonstration(3, 1, 9)
        (20, 40, 8)
    """
    return int(subgoals_on_demonstrations(subgoal, curriculum_length, torch.tensor([length]))[0])


def _padded(tensors: list[torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
    """``[K, N_max, *]`` the tensors padded with zeros along their first dimension, and ``[K, N_max]`` the real rows."""
    padded = torch.nn.utils.rnn.pad_sequence(tensors, batch_first=True)
    valid = torch.arange(padded.shape[1], device=padded.device) < torch.tensor(
        [t.shape[0] for t in tensors], device=padded.device).unsqueeze(-1)
    return padded, valid


class GoalConditionedMatchingReward(SubgoalMatchingReward):
    """:class:`SubgoalMatchingReward` over several demonstrations, each transition matched against the
    demonstration of its goal (:func:`nearest_goal_demonstration`), toward the curriculum's subgoal as a share of
    that demonstration (:func:`subgoal_on_demonstration`).

    The first demonstration is the curriculum trajectory: :attr:`subgoal`, :attr:`length` and
    :attr:`expert_observations` are its, as in :class:`SubgoalMatchingReward`, so a
    :class:`~torchrl_csirl.curriculum.SubgoalCurriculum` drives this transform as it drives that one. A batch is
    computed at once: each transition's distances to the states of its own demonstration, ``[B, L_max]`` (the
    demonstrations padded to the longest).

    Args:
        demonstrations: ``[L_k, D]`` observation tensors, the curriculum trajectory first.

    Keyword Args:
        goal_feature_indices (sequence of int): the observation entries of the episode's goal (a
            goal-conditioned task's ``desired_goal``); constant along an episode.
        **kwargs: as :class:`SubgoalMatchingReward` (``subgoal``, ``ego_feature_indices``,
            ``position_feature_indices``, ``scale``, ``target``, ``sign``, ``in_key``, ``out_key``,
            ``failure_keys``).

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> # [x, goal]: two demonstrations from 0, one to the goal +2, one to the goal -2
        >>> right = torch.tensor([[0.0, 2.0], [1.0, 2.0], [2.0, 2.0]])
        >>> left = torch.tensor([[0.0, -2.0], [-1.0, -2.0], [-2.0, -2.0]])
        >>> t = GoalConditionedMatchingReward([right, left], goal_feature_indices=[1], subgoal=2,
        ...                                   ego_feature_indices=[0], position_feature_indices=[0])
        >>> td = TensorDict({"observation": torch.tensor([[0.0, 2.0], [0.0, -2.0]]),
        ...                  "next": {"observation": torch.tensor([[-0.5, 2.0], [-0.5, -2.0]])}}, [2])
        >>> t(td)["next", "matching_reward"].squeeze(-1)  # moving left: away from +2, toward -2
        tensor([-0.5000,  0.5000])
    """

    def __init__(self, demonstrations: Sequence[torch.Tensor], *, goal_feature_indices: Sequence[int],
                 subgoal: int | SubgoalSource = 0, **kwargs: Any) -> None:
        demonstrations = [torch.as_tensor(d) for d in demonstrations]
        if not demonstrations:
            raise ValueError("demonstrations: at least one [L, D] tensor is needed.")
        super().__init__(demonstrations[0], subgoal=subgoal, **kwargs)
        dim = self.expert_observations.shape[-1]
        bad = [k for k, d in enumerate(demonstrations) if d.ndim != 2 or d.shape[0] < 1 or d.shape[-1] != dim]
        if bad:
            raise ValueError(f"demonstrations {bad}: each must have shape [L, {dim}] with L >= 1 (the first's width), "
                             f"got {[tuple(demonstrations[k].shape) for k in bad]}.")
        if not all(torch.isfinite(d).all() for d in demonstrations):
            raise ValueError("demonstrations contain NaN or infinite values.")
        goal = _check_indices(goal_feature_indices, dim, "goal_feature_indices")
        if goal is None:
            raise ValueError("goal_feature_indices: the observation entries of the goal are required.")
        device, dtype = self.expert_observations.device, self.expert_observations.dtype
        self.register_buffer("_goal_idx", goal.to(device))
        states = [d.detach().to(device=device, dtype=dtype) for d in demonstrations]
        self._register_demonstrations(states)

    def _register_demonstrations(self, states: list[torch.Tensor]) -> None:
        """Every demonstration's goal, positions, distinct search rows and path segments; the rows and segments
        padded to the longest demonstration's (``[K, R, F]``, with a mask of the real ones)."""
        lengths = torch.tensor([d.shape[0] for d in states], device=states[0].device)
        self.register_buffer("_lengths", lengths)
        self.register_buffer("_offsets", torch.cat([lengths.new_zeros(1), lengths.cumsum(0)[:-1]]))
        self.register_buffer("_demonstration_goals", torch.stack([d[0].index_select(-1, self._goal_idx) for d in states]))
        distinct = [distinct_expert_states(d.index_select(-1, self._ego_idx)) for d in states]  # by decreasing index
        rows, valid = _padded([r for r, _ in distinct])
        self.register_buffer("_rows", rows)
        self.register_buffer("_row_valid", valid)
        self.register_buffer("_row_index", _padded([i for _, i in distinct])[0])
        positions = [d.index_select(-1, self._pos_idx) for d in states]
        self.register_buffer("_positions", torch.cat(positions))
        geometry = [_path_geometry(p) for p in positions]  # (start, step, length, cumulative) per demonstration
        self.register_buffer("_segment_start", _padded([g[0] for g in geometry])[0])
        self.register_buffer("_segment_step", _padded([g[1] for g in geometry])[0])
        length, segment_valid = _padded([g[2] for g in geometry])
        self.register_buffer("_segment_length", length)
        self.register_buffer("_segment_valid", segment_valid)
        self.register_buffer("_segment_arc", _padded([g[3][:-1] for g in geometry])[0])  # arc length at its start
        self.register_buffer("_arc", torch.cat([g[3][: p.shape[0]] for g, p in zip(geometry, positions)]))

    @property
    def lengths(self) -> tuple[int, ...]:
        """tuple of int: each demonstration's length ``L_k`` (the curriculum trajectory's first)."""
        return tuple(self._lengths.tolist())

    @property
    def num_demonstrations(self) -> int:
        """int: the demonstrations matched against (the curriculum trajectory included)."""
        return int(self._lengths.shape[0])

    @property
    def demonstration_goals(self) -> torch.Tensor:
        """torch.Tensor: ``[K, G]`` each demonstration's goal (its first observation's goal entries)."""
        return self._demonstration_goals

    def goal_of(self, observation: torch.Tensor) -> torch.Tensor:
        """``[*B, G]`` each observation's goal entries (``goal_feature_indices``)."""
        return observation.index_select(-1, self._goal_idx.to(observation.device))

    def demonstration_of(self, observation: torch.Tensor) -> torch.Tensor:
        """``[*B]`` the demonstration each observation's goal selects."""
        goals = observation.reshape(-1, observation.shape[-1]).to(self._demonstration_goals.dtype)
        chosen = nearest_goal_demonstration(goals.index_select(-1, self._goal_idx), self._demonstration_goals)
        return chosen.reshape(observation.shape[:-1])

    def demonstration_positions(self, index: int) -> torch.Tensor:
        """``[L_k, P]`` demonstration ``index``'s matching (position) features."""
        start = int(self._offsets[index])
        return self._positions[start: start + int(self._lengths[index])]

    def _nearest(self, ego: torch.Tensor, chosen: torch.Tensor) -> torch.Tensor:
        """``[B]`` the nearest state's index within each transition's demonstration (ties: the later one)."""
        rows = self._rows.to(ego.dtype)[chosen]  # [B, R, F]
        scores = (rows * rows).sum(-1) - 2.0 * (rows @ ego.unsqueeze(-1)).squeeze(-1)
        scores.masked_fill_(~self._row_valid[chosen], float("inf"))
        return self._row_index[chosen].gather(-1, scores.argmin(dim=-1, keepdim=True)).squeeze(-1)

    def _path_potential(self, positions: torch.Tensor, chosen: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        """:func:`~torchrl_csirl.transforms.subgoal_matching.path_potential` along each transition's demonstration."""
        segments = (t.to(positions.dtype)[chosen] for t in (self._segment_start, self._segment_step,
                                                             self._segment_length, self._segment_arc))
        arc, offset = _project(positions, *segments, valid=self._segment_valid[chosen])
        return offset + (self._arc.to(positions.dtype)[self._offsets[chosen] + target] - arc).abs()

    def _transition_reward(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase) -> torch.Tensor:
        obs, next_obs, batch_shape = self._flat_observations(tensordict, next_tensordict)
        failed = self._failed(next_tensordict, obs.shape[0])
        chosen = self.demonstration_of(obs)
        lengths = self._lengths[chosen]
        subgoals = subgoals_on_demonstrations(self.subgoal, self.length, lengths)
        nearest = self._nearest(obs.index_select(-1, self._ego_idx), chosen)
        target = matching_target_index(nearest, subgoals, lengths, self.target)
        position, next_position = obs.index_select(-1, self._pos_idx), next_obs.index_select(-1, self._pos_idx)
        if self.target == "path":
            def potential(x: torch.Tensor) -> torch.Tensor:
                return self._path_potential(x, chosen, target)
        else:
            target_position = self._positions.to(obs.dtype)[self._offsets[chosen] + target]

            def potential(x: torch.Tensor) -> torch.Tensor:
                return matching_potential(x, target_position)
        next_potential = potential(next_position)
        if failed is not None:
            start = self._positions.to(obs.dtype)[self._offsets[chosen]]
            next_potential = failed_termination_potential(next_potential, potential(start), failed)
        reward = (potential(position) - next_potential).mul_(self.sign * self.scale)
        return reward.reshape(batch_shape).to(torch.float32)

    def __repr__(self) -> str:
        return super().__repr__()[:-1] + f", demonstrations={self.num_demonstrations})"
