"""The CSIRL matching reward r_m: potential-based shaping toward the current curricular subgoal.

For a transition ``(s, s')``, the curriculum trajectory ``s^e_0 .. s^e_{L-1}`` and subgoal ``g``:

1. :func:`nearest_expert_index`: ``j* = argmin_j || e(s) - e(s^e_j) ||_2`` on the ego features
   ``e`` (ties go to the later index);
2. :func:`matching_target_index`: ``t = g if j* < g`` else ``min(j* + 1, L - 1)`` (rule
   ``"next"``, the published code) or ``L - 1`` (rules ``"final"``, the paper's "head for s_T",
   and ``"path"``);
3. :func:`matching_potential`: ``psi(x) = || h(x) - h(s^e_t) ||_2`` on the position features ``h``
   (the straight line to the target); with rule ``"path"``, :func:`path_potential`: the distance
   to the target *along the expert's path* (the offset from the path plus the arc length between
   the projection and the target), so that a curved route is not cut across;
4. :func:`matching_reward`: ``r_m = sign * scale * (psi(s) - psi(s'))`` (``sign=+1``: positive when
   ``s'`` is closer to the target than ``s``).

All four are vectorised over the batch (a ``[B, L]`` distance matrix and an ``argmin``).
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey

from torchrl_csirl._validation import SubgoalSource, expert_observation_tensor, validate_subgoal
from torchrl_csirl.transforms._utils import TransitionRewardTransform

__all__ = [
    "SubgoalMatchingReward",
    "matching_potential",
    "matching_reward",
    "matching_target_index",
    "distinct_expert_states",
    "failed_termination_potential",
    "nearest_expert_index",
    "path_potential",
    "project_on_path",
]

_TARGET_RULES = ("next", "final", "path")


def nearest_expert_index(states: torch.Tensor, expert_states: torch.Tensor) -> torch.Tensor:
    """Index of the nearest expert state (Euclidean), ties broken toward the later index.

    Identical expert states resolve to the last occurrence exactly (they are merged before the
    search); equidistant *distinct* states resolve to the later index up to float rounding.

    Args:
        states (torch.Tensor): ``[B, F]`` query features.
        expert_states (torch.Tensor): ``[L, F]`` expert features.

    Returns:
        torch.Tensor: ``[B]`` int64 indices ``j*`` in ``[0, L-1]``.

    Examples:
        >>> import torch
        >>> expert = torch.tensor([[0.0], [1.0], [1.0], [2.0]])
        >>> nearest_expert_index(torch.tensor([[0.4], [1.1], [9.0]]), expert).tolist()
        [0, 2, 3]
    """
    rows, index = distinct_expert_states(expert_states)
    return _nearest_distinct(states, rows, index)


def distinct_expert_states(expert_states: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Distinct expert states, ordered by decreasing index of their last occurrence.

    Returns:
        (torch.Tensor, torch.Tensor): ``[U, F]`` rows and ``[U]`` their last-occurrence indices.
    """
    uniq, inverse = torch.unique(expert_states, dim=0, return_inverse=True)
    positions = torch.arange(expert_states.shape[0], device=expert_states.device)
    last = torch.full((uniq.shape[0],), -1, dtype=torch.int64, device=expert_states.device)
    last = last.scatter_reduce(0, inverse, positions, reduce="amax")
    order = last.argsort(descending=True)
    return uniq[order].contiguous(), last[order]


def _nearest_distinct(states: torch.Tensor, rows: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    # ||s - e||^2 - ||s||^2 = ||e||^2 - 2 s.e: one small matmul; argmin's first-occurrence rule
    # picks the latest expert index on ties since rows are ordered by decreasing index
    rows = rows.to(states.dtype)
    scores = torch.addmm((rows * rows).sum(-1), states, rows.T, alpha=-2.0)
    return index[scores.argmin(dim=-1)]


def matching_target_index(
    nearest: torch.Tensor, subgoal: int, length: int, rule: str = "next"
) -> torch.Tensor:
    """Index of the expert state the matching reward heads for.

    ``t = g`` while the agent is behind the subgoal (``j* < g``); once at or past it,
    ``t = min(j* + 1, L - 1)`` (``rule="next"``, published code) or ``t = L - 1``
    (``rule="final"``, the paper; ``rule="path"`` has the same targets).

    Args:
        nearest (torch.Tensor): ``[B]`` nearest expert indices ``j*``.
        subgoal (int or torch.Tensor): the current subgoal ``g`` (or ``[B]``, one per transition).
        length (int or torch.Tensor): the curriculum trajectory length ``L`` (or ``[B]``).
        rule (str): ``"next"`` (default), ``"final"`` or ``"path"``.

    Examples:
        >>> import torch
        >>> matching_target_index(torch.tensor([0, 2, 3, 4]), subgoal=2, length=5).tolist()
        [2, 3, 4, 4]
        >>> matching_target_index(torch.tensor([0, 2]), subgoal=2, length=5, rule="final").tolist()
        [2, 4]
    """
    last = torch.as_tensor(length, device=nearest.device) - 1
    if rule == "next":
        past = torch.minimum(nearest + 1, last)
    elif rule in ("final", "path"):
        past = last.expand_as(nearest)
    else:
        raise ValueError(f"target rule must be one of {_TARGET_RULES}, got {rule!r}.")
    subgoal = torch.as_tensor(subgoal, device=nearest.device).expand_as(nearest)
    return torch.where(nearest < subgoal, subgoal, past)


def matching_potential(positions: torch.Tensor, target_positions: torch.Tensor) -> torch.Tensor:
    """The potential ``psi(x) = || h(x) - h(s^e_t) ||_2`` (position features already selected).

    Args:
        positions (torch.Tensor): ``[B, P]`` position features ``h(x)``.
        target_positions (torch.Tensor): ``[B, P]`` position features of the targets.

    Examples:
        >>> import torch
        >>> matching_potential(torch.tensor([[3.0, 0.0]]), torch.tensor([[0.0, 4.0]])).tolist()
        [5.0]
    """
    return torch.linalg.vector_norm(positions - target_positions, dim=-1)


def project_on_path(positions: torch.Tensor, path: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Closest point of the polyline ``path`` to each position: its arc length and the distance.

    Args:
        positions (torch.Tensor): ``[B, P]`` position features.
        path (torch.Tensor): ``[L, P]`` the expert's positions, in order (consecutive repeats allowed).

    Returns:
        (torch.Tensor, torch.Tensor): ``[B]`` arc length from ``path[0]`` to the closest point,
        and ``[B]`` the distance to it (the offset from the path).

    Examples:
        >>> import torch
        >>> corner = torch.tensor([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]])  # an L-shaped route
        >>> arc, offset = project_on_path(torch.tensor([[1.0, 0.5], [3.0, 1.0]]), corner)
        >>> arc.tolist(), offset.tolist()
        ([1.0, 3.0], [0.5, 1.0])
    """
    return _project(positions, *_path_geometry(path.to(positions.dtype)))


def _path_geometry(path: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """``(start [L-1, P], step [L-1, P], length [L-1], cumulative [L])`` of the polyline's segments;
    ``cumulative[k]`` is the arc length from ``path[0]`` to ``path[k]``."""
    if path.shape[0] == 1:  # one state: a zero-length segment at it
        path = path.expand(2, -1)
    start, step = path[:-1], path[1:] - path[:-1]
    length = torch.linalg.vector_norm(step, dim=-1)
    return start, step, length, torch.cat([length.new_zeros(1), length.cumsum(0)])


def _project(positions: torch.Tensor, start: torch.Tensor, step: torch.Tensor, length: torch.Tensor,
             cumulative: torch.Tensor, valid: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`project_on_path` on the segments of :func:`_path_geometry` (``[S, ...]``, or ``[B, S, ...]``: each
    position its own path, with ``valid`` ``[B, S]`` marking its real segments among padded ones)."""
    along = ((positions.unsqueeze(-2) - start) * step).sum(-1) / (length * length).clamp_min(1e-12)
    along = along.clamp(0.0, 1.0)  # [B, S]: where on each segment the closest point lies
    distance = torch.linalg.vector_norm(positions.unsqueeze(-2) - (start + along.unsqueeze(-1) * step), dim=-1)
    if valid is not None:
        distance = distance.masked_fill(~valid, float("inf"))
    offset, segment = distance.min(dim=-1, keepdim=True)
    arc_at_start = cumulative[..., : length.shape[-1]].expand_as(along)
    arc = arc_at_start.gather(-1, segment) + along.gather(-1, segment) * length.expand_as(along).gather(-1, segment)
    return arc.squeeze(-1), offset.squeeze(-1)


def path_potential(positions: torch.Tensor, path: torch.Tensor, target_index: torch.Tensor) -> torch.Tensor:
    """The potential of rule ``"path"``: the distance to ``path[t]`` along the path,
    ``psi(x) = offset(x) + | C_t - arc(x) |`` (:func:`project_on_path`; ``C_t`` the arc length of
    the target). On a straight route it equals :func:`matching_potential` to the target; on a
    curved one, cutting across the curve does not shorten it (the straight line does).

    Args:
        positions (torch.Tensor): ``[B, P]`` position features.
        path (torch.Tensor): ``[L, P]`` the expert's positions.
        target_index (torch.Tensor): ``[B]`` each position's target ``t``.

    Examples:
        >>> import torch
        >>> corner = torch.tensor([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]])
        >>> # to the end of the L: 4 from its start (straight line: 2.83), 0.5 + 3 from (1, 0.5) (1.80)
        >>> path_potential(torch.tensor([[0.0, 0.0], [1.0, 0.5]]), corner, torch.tensor([2, 2])).tolist()
        [4.0, 3.5]
    """
    return _path_potential(positions, _path_geometry(path.to(positions.dtype)), target_index)


def _path_potential(positions: torch.Tensor, geometry: tuple[torch.Tensor, ...], target_index: torch.Tensor) -> torch.Tensor:
    """:func:`path_potential` on the segments of :func:`_path_geometry` (computed once per batch)."""
    arc, offset = _project(positions, *geometry)
    return offset + (geometry[-1][target_index] - arc).abs()


def matching_reward(
    observation: torch.Tensor,
    next_observation: torch.Tensor,
    expert_observations: torch.Tensor,
    subgoal: int,
    *,
    ego_feature_indices: Sequence[int] | torch.Tensor | None = None,
    position_feature_indices: Sequence[int] | torch.Tensor | None = None,
    scale: float = 1.0,
    target: str = "next",
    sign: float = 1.0,
) -> torch.Tensor:
    """The matching reward ``r_m = sign * scale * (psi(s) - psi(s'))`` for a batch of transitions.

    The target (and hence the potential) is determined by ``s`` and used for both ``s`` and ``s'``.

    Args:
        observation (torch.Tensor): ``[*B, D]`` states ``s``.
        next_observation (torch.Tensor): ``[*B, D]`` next states ``s'``.
        expert_observations (torch.Tensor): ``[L, D]`` curriculum trajectory.
        subgoal (int): the current subgoal ``g`` in ``[0, L-1]``.
        ego_feature_indices: features used for the nearest-state search (default: all).
        position_feature_indices: features of the potential (default: all).
        scale (float): reward scale. Defaults to ``1.0``.
        target (str): target rule, ``"next"``, ``"final"`` or ``"path"``.
        sign (float): ``+1`` (default, shaping toward the target) or ``-1``.

    Returns:
        torch.Tensor: ``[*B]`` rewards.

    Examples:
        >>> import torch
        >>> expert = torch.tensor([[0.0], [1.0], [2.0], [3.0]])
        >>> # behind subgoal 2: heads for s^e_2; moving from 0.0 to 0.5 gains 0.5
        >>> matching_reward(torch.tensor([[0.0]]), torch.tensor([[0.5]]), expert, 2, scale=10.0)
        tensor([5.])
    """
    batch_shape = observation.shape[:-1]
    obs = observation.reshape(-1, observation.shape[-1])
    next_obs = next_observation.reshape(-1, next_observation.shape[-1]).to(obs.dtype)
    expert = expert_observations.to(device=obs.device, dtype=obs.dtype)
    ego = _feature_index(ego_feature_indices, obs)
    pos = _feature_index(position_feature_indices, obs)
    rows, row_index = distinct_expert_states(expert.index_select(-1, ego))
    reward = _matching_reward_from_features(
        obs.index_select(-1, ego),
        obs.index_select(-1, pos),
        next_obs.index_select(-1, pos),
        rows,
        row_index,
        expert.index_select(-1, pos),
        int(subgoal),
        target,
        sign * scale,
    )
    return reward.reshape(batch_shape)


def _feature_index(indices: Sequence[int] | torch.Tensor | None, like: torch.Tensor) -> torch.Tensor:
    if indices is None:
        return torch.arange(like.shape[-1], device=like.device)
    return torch.as_tensor(indices, dtype=torch.int64, device=like.device)


def _matching_reward_from_features(
    ego: torch.Tensor,
    position: torch.Tensor,
    next_position: torch.Tensor,
    expert_rows: torch.Tensor,
    expert_row_index: torch.Tensor,
    expert_position: torch.Tensor,
    subgoal: int,
    target: str,
    factor: float,
    failed: torch.Tensor | None = None,
) -> torch.Tensor:
    """Steps 1-4 on pre-selected features (flat ``[B, F]``); ``factor = sign * scale``.

    ``expert_rows``/``expert_row_index`` come from :func:`distinct_expert_states`; ``failed``
    (``[B]`` bool) marks transitions into a failed termination (:func:`failed_termination_potential`).
    """
    nearest = _nearest_distinct(ego, expert_rows, expert_row_index)
    target_index = matching_target_index(nearest, subgoal, expert_position.shape[0], target)
    if target == "path":
        geometry = _path_geometry(expert_position.to(position.dtype))

        def potential(x: torch.Tensor) -> torch.Tensor:
            return _path_potential(x, geometry, target_index)
    else:
        target_position = expert_position[target_index]

        def potential(x: torch.Tensor) -> torch.Tensor:
            return matching_potential(x, target_position)
    next_potential = potential(next_position)
    if failed is not None:
        start_potential = potential(expert_position[:1].expand_as(next_position))
        next_potential = failed_termination_potential(next_potential, start_potential, failed)
    delta = potential(position) - next_potential
    return delta.mul_(factor)


def failed_termination_potential(
    next_potential: torch.Tensor,
    start_potential: torch.Tensor,
    failed: torch.Tensor,
) -> torch.Tensor:
    """The potential of ``s'`` when a transition ends the episode in failure (e.g. a crash).

    A failed termination leads to an absorbing state whose potential is the one of the curriculum
    trajectory's **start**, ``psi(s^e_0)``, or ``psi(s')`` if that is larger: the last transition
    then pays back the progress the episode had made (with the ``"final"`` target the undiscounted
    matching return of a failed episode started at ``s^e_0`` is at most 0), and a failure is never
    paid more than the same transition without it. Not in the paper (there a crash only stops the
    reward): an accomplish rate earned by driving fast and then crashing is not expert-like.

    Args:
        next_potential (torch.Tensor): ``[B]`` the ordinary ``psi(s')``.
        start_potential (torch.Tensor): ``[B]`` ``psi(s^e_0)`` toward each transition's target.
        failed (torch.Tensor): ``[B]`` bool, the transitions that end in failure.

    Returns:
        torch.Tensor: ``[B]`` the potential of ``s'`` to use.

    Examples:
        >>> import torch
        >>> failed_termination_potential(torch.tensor([2.0, 2.0]), torch.tensor([10.0, 10.0]),
        ...                               torch.tensor([False, True])).tolist()
        [2.0, 10.0]
    """
    return torch.where(failed, torch.maximum(next_potential, start_potential), next_potential)


def _check_indices(indices: Sequence[int] | None, dim: int, name: str) -> torch.Tensor | None:
    if indices is None:
        return None
    idx = torch.as_tensor(list(indices), dtype=torch.int64)
    if idx.ndim != 1 or idx.numel() == 0:
        raise ValueError(f"{name} must be a non-empty sequence of ints, got {indices!r}.")
    if (idx < 0).any() or (idx >= dim).any():
        raise ValueError(f"{name} {idx.tolist()} out of range for observations of size {dim}.")
    return idx


class SubgoalMatchingReward(TransitionRewardTransform):
    """Writes the CSIRL matching reward ``r_m(s, s'; g)`` under ``("next", out_key)``.

    Works as an environment transform (in a :class:`~torchrl.envs.TransformedEnv`, over a
    single, serial or parallel env: the transform and its subgoal live in the main process) and
    as a replay-buffer transform that recomputes the reward of sampled transitions
    (``observation``, ``("next", "observation")``) for the *current* subgoal.

    The subgoal has one owner. Given a *subgoal source* (any object with an int ``subgoal``
    attribute, e.g. the :class:`~torchrl_csirl.curriculum.SubgoalCurriculum` that selects it),
    the transform reads ``source.subgoal`` at every call and never stores it: moving the
    curriculum moves the reward, with nothing to keep in step. Given an int, the transform owns a
    fixed subgoal, changed with :meth:`set_subgoal` (standalone use).

    The reward is written under its own key (default ``"matching_reward"``, declared in the
    observation spec so that ``env.reward_key`` is unchanged). To train on it, sum it (with the
    intrinsic reward) into ``("next", "reward")`` with
    :class:`~torchrl_csirl.transforms.CombineRewards`, or point the loss's ``reward`` key at it
    (``loss.set_keys(reward="matching_reward")``).

    Args:
        expert_observations: the curriculum trajectory: a ``[L, D]`` tensor, a trajectory
            TensorDict (its ``"observation"``) or :class:`~torchrl_csirl.data.ExpertDemonstrations`
            (its first trajectory).

    Keyword Args:
        subgoal (int or SubgoalSource): a fixed subgoal ``g`` (owned here, see
            :meth:`set_subgoal`), or the object owning it (read at every call). Defaults to ``0``.
        ego_feature_indices (sequence of int, optional): features for the nearest-state search
            (e.g. ``ScenarioSpec.ego_feature_indices``). Defaults to all features.
        position_feature_indices (sequence of int, optional): features of the potential
            (e.g. ``ScenarioSpec.position_feature_indices``). Defaults to all features.
        scale (float): reward scale (published: 700 highway, 500 merge, 100 roundabout and
            intersection). Defaults to ``1.0``.
        target (str): ``"next"`` (default, published code), ``"final"`` (paper: the straight line
            to ``s^e_T`` past the subgoal) or ``"path"`` (the same targets, distances measured
            along the expert's path: :func:`path_potential`).
        sign (float): ``+1`` (default) or ``-1``.
        in_key (NestedKey): observation key. Defaults to ``"observation"``.
        out_key (NestedKey): output key inside ``"next"``. Defaults to ``"matching_reward"``.
        include_final (bool): with a trajectory input, append its last next-observation.
        failure_keys (sequence of NestedKey): boolean entries of ``"next"`` that mark a failed
            termination (e.g. ``("crashed", "offroad")``, the driving envs' flags); on such a
            transition ``s'`` takes the potential of the curriculum's start
            (:func:`failed_termination_potential`), so a crash pays back the progress made. A
            transition without these entries (e.g. an expert one) is not a failure. Defaults to
            ``()`` (the paper: a failure only ends the reward).

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> expert = torch.tensor([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0]])
        >>> t = SubgoalMatchingReward(expert, subgoal=2, scale=10.0, position_feature_indices=[0])
        >>> td = TensorDict({"observation": torch.zeros(1, 2),
        ...                  "next": {"observation": torch.tensor([[0.5, 0.0]])}}, [1])
        >>> t(td)["next", "matching_reward"]
        tensor([[5.]])
        >>> t.set_subgoal(0)  # now past the subgoal: head for s^e_1
        >>> t(td)["next", "matching_reward"]
        tensor([[5.]])
        >>> class Owner:  # e.g. a SubgoalCurriculum
        ...     subgoal = 3
        >>> owner = Owner()
        >>> follower = SubgoalMatchingReward(expert, subgoal=owner, position_feature_indices=[0])
        >>> owner.subgoal = 1
        >>> follower.subgoal
        1
    """

    def __init__(
        self,
        expert_observations: Any,
        *,
        subgoal: int | SubgoalSource = 0,
        ego_feature_indices: Sequence[int] | None = None,
        position_feature_indices: Sequence[int] | None = None,
        scale: float = 1.0,
        target: str = "next",
        sign: float = 1.0,
        in_key: NestedKey = "observation",
        out_key: NestedKey = "matching_reward",
        include_final: bool = False,
        failure_keys: Sequence[NestedKey] = (),
    ) -> None:
        super().__init__(in_keys=[in_key], out_key=out_key)
        if isinstance(failure_keys, str):
            failure_keys = (failure_keys,)
        self.failure_keys = tuple(failure_keys)
        expert = expert_observation_tensor(expert_observations, include_final)
        if expert.ndim != 2 or expert.shape[0] < 1:
            raise ValueError(f"expert observations must have shape [L, D] with L >= 1, got {tuple(expert.shape)}.")
        if not torch.is_floating_point(expert):
            expert = expert.float()
        if not torch.isfinite(expert).all():
            raise ValueError("expert observations contain NaN or infinite values.")
        if target not in _TARGET_RULES:
            raise ValueError(f"target must be one of {_TARGET_RULES}, got {target!r}.")
        if sign not in (1, -1, 1.0, -1.0):
            raise ValueError(f"sign must be +1 or -1, got {sign!r}.")
        dim = expert.shape[-1]
        ego = _check_indices(ego_feature_indices, dim, "ego_feature_indices")
        pos = _check_indices(position_feature_indices, dim, "position_feature_indices")
        expert = expert.detach().clone()
        self.register_buffer("expert_observations", expert)
        # the indices live with the expert states (a GPU learner keeps them there)
        ego = (ego if ego is not None else torch.arange(dim)).to(expert.device)
        pos = (pos if pos is not None else torch.arange(dim)).to(expert.device)
        # features selected once: a call costs one [B, L] distance matrix and a few [B] ops
        rows, row_index = distinct_expert_states(expert.index_select(-1, ego))
        self.register_buffer("_expert_rows", rows)
        self.register_buffer("_expert_row_index", row_index)
        self.register_buffer("_expert_pos", expert.index_select(-1, pos))
        self.register_buffer("_ego_idx", ego)
        self.register_buffer("_pos_idx", pos)
        self.scale = float(scale)
        self.target = target
        self.sign = float(sign)
        self._subgoal = 0
        # not a submodule (a curriculum may hold networks): the transform only reads it
        self.__dict__["_source"] = None
        if isinstance(subgoal, (int, torch.Tensor)):
            self.set_subgoal(subgoal)
        elif isinstance(getattr(subgoal, "subgoal", None), int):
            self.__dict__["_source"] = subgoal
            validate_subgoal(subgoal.subgoal, self.length)
        else:
            raise TypeError(
                f"subgoal must be an int or an object with an int 'subgoal' attribute (e.g. a SubgoalCurriculum), "
                f"got {type(subgoal).__name__}.")

    @property
    def length(self) -> int:
        """int: the curriculum trajectory length ``L``."""
        return int(self.expert_observations.shape[0])

    @property
    def position_feature_indices(self) -> torch.Tensor:
        """torch.Tensor: the observation entries of the matching features ``h(s)`` (the potential's)."""
        return self._pos_idx

    @property
    def subgoal_source(self) -> SubgoalSource | None:
        """The object owning the subgoal, or None when the transform holds a fixed one."""
        return self.__dict__.get("_source")

    @property
    def subgoal(self) -> int:
        """int: the current subgoal ``g`` (the source's, when there is one)."""
        source = self.subgoal_source
        return self._subgoal if source is None else validate_subgoal(source.subgoal, self.length)

    def set_subgoal(self, subgoal: int) -> None:
        """Sets the fixed subgoal ``g`` (an int in ``[0, L-1]``), used from the next step / sample on.

        Raises:
            RuntimeError: when the subgoal belongs to a source (move the source instead).
        """
        if self.subgoal_source is not None:
            raise RuntimeError(
                f"This transform reads its subgoal from {type(self.subgoal_source).__name__}; "
                "change it there (e.g. SubgoalCurriculum.step() or set_subgoal()).")
        self._subgoal = validate_subgoal(subgoal, self.length)

    def _transition_reward(
        self, tensordict: TensorDictBase, next_tensordict: TensorDictBase
    ) -> torch.Tensor:
        obs, next_obs, batch_shape = self._flat_observations(tensordict, next_tensordict)
        reward = _matching_reward_from_features(
            obs.index_select(-1, self._ego_idx),
            obs.index_select(-1, self._pos_idx),
            next_obs.index_select(-1, self._pos_idx),
            self._expert_rows,
            self._expert_row_index,
            self._expert_pos,
            self.subgoal,
            self.target,
            self.sign * self.scale,
            self._failed(next_tensordict, obs.shape[0]),
        )
        return reward.reshape(batch_shape).to(torch.float32)

    def _flat_observations(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase
                           ) -> tuple[torch.Tensor, torch.Tensor, torch.Size]:
        """``(s [B, D], s' [B, D], the batch shape)``, in the expert states' dtype."""
        key = self.in_keys[0]
        obs = tensordict.get(key)
        next_obs = next_tensordict.get(key)
        batch_shape = obs.shape[:-1]
        obs = obs.reshape(-1, obs.shape[-1])
        next_obs = next_obs.reshape(-1, next_obs.shape[-1])
        dtype = self.expert_observations.dtype
        if obs.dtype != dtype:
            obs, next_obs = obs.to(dtype), next_obs.to(dtype)
        return obs, next_obs, batch_shape

    def _failed(self, next_tensordict: TensorDictBase, numel: int) -> torch.Tensor | None:
        """``[B]`` bool: the transitions flagged by any of ``failure_keys`` (None without keys or flags)."""
        flags = [next_tensordict.get(key) for key in self.failure_keys if key in next_tensordict.keys(True)]
        if not flags:
            return None
        failed = torch.zeros(numel, dtype=torch.bool, device=flags[0].device)
        for flag in flags:
            failed |= flag.reshape(numel).bool()
        return failed

    def get_extra_state(self) -> dict[str, Any]:
        return {"subgoal": self.subgoal}

    def set_extra_state(self, state: dict[str, Any]) -> None:
        if self.subgoal_source is None:  # a source restores its own state
            self.set_subgoal(int(state["subgoal"]))

    def __repr__(self) -> str:
        return (
            f"{type(self).__name__}(length={self.length}, subgoal={self.subgoal}, scale={self.scale}, "
            f"target={self.target!r}, sign={self.sign}, in_key={self.in_keys[0]!r}, out_key={self.out_key!r}"
            + (f", failure_keys={self.failure_keys!r})" if self.failure_keys else ")")
        )
