"""Ego-relative input features: a fixed, parameter-free first layer for the CSIRL networks.

The driving observations are *absolute* Kinematics rows normalised by wide per-scenario ranges
(merge maps x in [-500, 500] m to [-1, 1]), so a vehicle 5 m ahead of the ego and one 25 m ahead
differ by 0.04 in the input. A network can learn the difference ``x_i - x_ego`` but, at that scale,
only slowly; that difference is what decides a crash. :class:`EgoRelativeFeatures` appends, for
every other observed vehicle, its offsets from the ego (positions and velocities) rescaled to a
few metres / metres per second per unit, to the unchanged observation. It has no parameters, so
the networks stay MLPs over a fixed feature map (the learner still sees only the observation).
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import torch
from torch import nn

from torchrl_csirl.modules.input_memo import mapped_once
from torchrl_csirl.modules.lane_features import LaneFeatures

__all__ = ["DropFeatures", "EgoRelativeFeatures", "FeatureChain", "RELATIVE_REFERENCE", "StandardizeFeatures", "feature_map_from_config",
           "find_standardization", "input_map", "make_input_features", "with_standardization"]

#: metres (positions) and metres per second (velocities) that one unit of a relative feature
#: represents, before clipping to ``[-clip, clip]``.
RELATIVE_REFERENCE: Mapping[str, float] = {"x": 20.0, "y": 20.0, "vx": 10.0, "vy": 10.0}


class EgoRelativeFeatures(nn.Module):
    """Appends the other vehicles' offsets from the ego to a flattened Kinematics observation.

    The observation is ``vehicles_count`` rows of ``num_features`` features, ego first. For each
    of the other rows and each feature index ``f`` in ``relative_indices`` the module computes
    ``clip(gain_f * (obs[i, f] - obs[0, f]), -clip, clip)``, zero where the row's presence flag is
    not positive (absent vehicles are all-zero rows), and concatenates these ``(vehicles_count - 1) *
    len(relative_indices)`` values after the unchanged observation.

    Args:
        vehicles_count (int): observed vehicles per observation (ego included).
        num_features (int): features per vehicle.
        relative_indices (sequence of int): feature indices to take relative to the ego.
        gains (sequence of float): one multiplier per relative index.
        presence_index (int, optional): index of the presence flag; ``None`` if there is none.
        clip (float): bound of the relative features. Defaults to ``5.0``.

    Examples:
        >>> import torch
        >>> feats = EgoRelativeFeatures(3, 3, relative_indices=[1, 2], gains=[10.0, 1.0], presence_index=0)
        >>> obs = torch.tensor([[1.0, 0.10, 0.5,  1.0, 0.15, 0.0,  0.0, 0.0, 0.0]])
        >>> feats(obs)[..., 9:]
        tensor([[ 0.5000, -0.5000,  0.0000,  0.0000]])
        >>> feats.out_features
        13
    """

    def __init__(
        self,
        vehicles_count: int,
        num_features: int,
        relative_indices: Sequence[int],
        gains: Sequence[float],
        presence_index: int | None = None,
        clip: float = 5.0,
    ) -> None:
        super().__init__()
        relative_indices = [int(i) for i in relative_indices]
        if vehicles_count < 2:
            raise ValueError(f"vehicles_count must be >= 2 (ego and others), got {vehicles_count}.")
        if not relative_indices or any(not 0 <= i < num_features for i in relative_indices):
            raise ValueError(
                f"relative_indices must be a non-empty list of indices in [0, {num_features}), got {relative_indices}."
            )
        if len(gains) != len(relative_indices):
            raise ValueError(f"one gain per relative index expected, got {len(gains)} for {len(relative_indices)}.")
        if presence_index is not None and not 0 <= presence_index < num_features:
            raise ValueError(f"presence_index must be in [0, {num_features}), got {presence_index}.")
        if clip <= 0:
            raise ValueError(f"clip must be positive, got {clip}.")
        self.vehicles_count = int(vehicles_count)
        self.num_features = int(num_features)
        self.relative_indices = relative_indices
        # contiguous indices (x, y, vx, vy in the driving scenes) are a slice: a view, no gather
        first = relative_indices[0]
        contiguous = relative_indices == list(range(first, first + len(relative_indices)))
        self._relative_slice = slice(first, first + len(relative_indices)) if contiguous else None
        self.presence_index = presence_index
        self.clip = float(clip)
        # a plain tuple, not a buffer: the ensemble critics stack their members' tensors
        self.gains = tuple(float(g) for g in gains)

    @classmethod
    def from_scenario(cls, spec: Any, reference: Mapping[str, float] = RELATIVE_REFERENCE,
                      clip: float = 5.0) -> EgoRelativeFeatures:
        """The module for a scenario's observation layout (a :class:`~torchrl_csirl.tasks.ScenarioSpec`).

        The gain of feature ``f`` turns its normalised unit (half its range) into units of
        ``reference[f]``, and is never below 1.

        Examples:
            >>> from torchrl_csirl.tasks import SCENARIOS
            >>> feats = EgoRelativeFeatures.from_scenario(SCENARIOS["merge"])
            >>> feats.gains, feats.out_features
            ((25.0, 1.0, 8.0, 8.0), 41)
        """
        features = list(spec.features)
        indices, gains = [], []
        for name in ("x", "y", "vx", "vy"):
            if name in features and name in reference:
                low, high = spec.features_range[name]
                indices.append(features.index(name))
                gains.append(max(1.0, 0.5 * (high - low) / float(reference[name])))
        presence = features.index("presence") if "presence" in features else None
        return cls(int(spec.vehicles_count), len(features), indices, gains, presence, clip)

    @property
    def in_features(self) -> int:
        return self.vehicles_count * self.num_features

    @property
    def out_features(self) -> int:
        return self.in_features + (self.vehicles_count - 1) * len(self.relative_indices)

    def config(self) -> dict[str, Any]:
        """The constructor arguments (to rebuild the module, e.g. with a saved policy)."""
        return {
            "vehicles_count": self.vehicles_count,
            "num_features": self.num_features,
            "relative_indices": list(self.relative_indices),
            "gains": list(self.gains),
            "presence_index": self.presence_index,
            "clip": self.clip,
        }

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        return mapped_once(self, self._relative_features, observation)

    def _relative_features(self, observation: torch.Tensor) -> torch.Tensor:
        if observation.shape[-1] != self.in_features:
            raise ValueError(
                f"EgoRelativeFeatures expects observations of size {self.in_features} "
                f"({self.vehicles_count} vehicles x {self.num_features} features), got {observation.shape[-1]}."
            )
        rows = observation.unflatten(-1, (self.vehicles_count, self.num_features))
        selected = rows[..., self._relative_slice if self._relative_slice is not None else self.relative_indices]
        relative = (selected[..., 1:, :] - selected[..., :1, :]).mul_(self._gains_like(observation))
        relative = relative.clamp_(-self.clip, self.clip)
        if self.presence_index is not None:
            present = rows[..., 1:, self.presence_index : self.presence_index + 1] > 0
            relative = torch.where(present, relative, 0.0)
        return torch.cat([observation, relative.flatten(-2)], dim=-1)

    def _gains_like(self, observation: torch.Tensor) -> torch.Tensor:
        """The gains as a tensor of the observation's dtype and device (made once per kind)."""
        kind = (self.gains, observation.dtype, observation.device)
        cached = self.__dict__.get("_gains_tensor")
        if cached is None or cached[0] != kind:
            cached = self.__dict__["_gains_tensor"] = (kind, torch.tensor(self.gains, dtype=kind[1], device=kind[2]))
        return cached[1]

    def extra_repr(self) -> str:
        return f"vehicles={self.vehicles_count}, relative={self.relative_indices}, gains={list(self.gains)}"


class DropFeatures(nn.Module):
    """Drops observation entries the networks must not read: a task's ``hidden_feature_indices``.

    The locomotion tasks keep the torso's absolute x in the observation for the matching reward;
    every network reads the observation through this map, so a policy sees what gymnasium's default
    observation holds. Parameter-free, like the other input maps.

    Args:
        in_features (int): input size.
        hidden (sequence of int): indices to drop, in ``[0, in_features)``.

    Examples:
        >>> import torch
        >>> drop = DropFeatures(4, hidden=[0])
        >>> drop(torch.tensor([[9.0, 1.0, 2.0, 3.0]])), drop.out_features
        (tensor([[1., 2., 3.]]), 3)
    """

    def __init__(self, in_features: int, hidden: Sequence[int]) -> None:
        super().__init__()
        hidden = sorted({int(i) for i in hidden})
        if not hidden or any(not 0 <= i < in_features for i in hidden) or len(hidden) >= in_features:
            raise ValueError(f"hidden must be indices in [0, {in_features}) that keep at least one entry, got {hidden}.")
        self._in_features = int(in_features)
        self.hidden = tuple(hidden)
        # a plain tuple, not a buffer (as EgoRelativeFeatures.gains); a contiguous run is a slice
        self.keep = tuple(i for i in range(in_features) if i not in self.hidden)
        contiguous = self.keep == tuple(range(self.keep[0], self.keep[-1] + 1))
        self._slice = slice(self.keep[0], self.keep[-1] + 1) if contiguous else None

    @property
    def in_features(self) -> int:
        return self._in_features

    @property
    def out_features(self) -> int:
        return len(self.keep)

    def config(self) -> dict[str, Any]:
        return {"kind": "drop", "in_features": self._in_features, "hidden": list(self.hidden)}

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        if observation.shape[-1] != self._in_features:
            raise ValueError(f"DropFeatures expects observations of size {self._in_features}, got {observation.shape[-1]}.")
        if self._slice is not None:
            return observation[..., self._slice]
        return observation.index_select(-1, torch.as_tensor(self.keep, device=observation.device))

    def extra_repr(self) -> str:
        return f"in_features={self._in_features}, hidden={list(self.hidden)}"


class StandardizeFeatures(nn.Module):
    """Standardises each input entry with fixed statistics: ``(x - loc) / scale``.

    ValueDICE's networks read states standardised with the demonstrations' mean and standard deviation
    (the authors' code, ``google-research/value_dice``: ``scale = std + 1e-3``); :meth:`from_data`
    computes them so. The statistics are buffers (saved with the network), not parameters.

    Args:
        loc (tensor): per-entry offset, shape ``[in_features]``.
        scale (tensor): per-entry divisor (positive), the same shape.

    Examples:
        >>> import torch
        >>> norm = StandardizeFeatures.from_data(torch.tensor([[0.0, 10.0], [2.0, 30.0]]))
        >>> norm.loc.tolist(), norm(torch.tensor([[1.0, 20.0], [2.0, 30.0]])).double().round(decimals=3).tolist()
        ([1.0, 20.0], [[0.0, 0.0], [0.999, 1.0]])
    """

    def __init__(self, loc: torch.Tensor, scale: torch.Tensor) -> None:
        super().__init__()
        loc, scale = torch.as_tensor(loc, dtype=torch.float32), torch.as_tensor(scale, dtype=torch.float32)
        if loc.ndim != 1 or loc.shape != scale.shape or not bool((scale > 0).all()) or not bool(torch.isfinite(loc).all()):
            raise ValueError(f"loc and scale must be finite vectors of one size with scale > 0, got shapes "
                             f"{tuple(loc.shape)} and {tuple(scale.shape)}.")
        self.register_buffer("loc", loc)
        self.register_buffer("scale", scale)

    @classmethod
    def from_data(cls, features: torch.Tensor, eps: float = 1e-3) -> StandardizeFeatures:
        """The standardisation of ``features`` (``[N, in_features]``): their mean, and their standard
        deviation plus ``eps`` (the authors' ValueDICE code)."""
        features = features.reshape(-1, features.shape[-1]).to(torch.float64)
        return cls(features.mean(0), features.std(0, correction=0) + eps)

    @property
    def in_features(self) -> int:
        return int(self.loc.numel())

    @property
    def out_features(self) -> int:
        return self.in_features

    def config(self) -> dict[str, Any]:
        return {"kind": "standardize", "loc": self.loc.tolist(), "scale": self.scale.tolist()}

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        if observation.shape[-1] != self.in_features:
            raise ValueError(f"StandardizeFeatures expects inputs of size {self.in_features}, got {observation.shape[-1]}.")
        return (observation - self.loc.to(observation.dtype)) / self.scale.to(observation.dtype)

    def extra_repr(self) -> str:
        return f"in_features={self.in_features}"


class FeatureChain(nn.Sequential):
    """Parameter-free input maps applied one after the other.

    Examples:
        >>> from torchrl_csirl.tasks import SCENARIOS
        >>> chain = make_input_features(SCENARIOS["roundabout"], ego_relative=True, lane=True)
        >>> type(chain).__name__, chain.in_features, chain.out_features
        ('FeatureChain', 35, 54)
    """

    @property
    def in_features(self) -> int:
        return int(self[0].in_features)

    @property
    def out_features(self) -> int:
        return int(self[-1].out_features)

    def config(self) -> dict[str, Any]:
        return {"kind": "chain", "maps": [m.config() for m in self]}


def make_input_features(spec: Any, ego_relative: bool = True, lane: bool = False) -> nn.Module | None:
    """The networks' input map for a task: :class:`EgoRelativeFeatures` (``ego_relative``, driving),
    then :class:`~torchrl_csirl.modules.LaneFeatures` (``lane``, driving), then :class:`DropFeatures`
    where the task hides entries (``spec.hidden_feature_indices``); ``None`` for none of them.

    Examples:
        >>> from torchrl_csirl.tasks import SCENARIOS
        >>> make_input_features(SCENARIOS["merge"], ego_relative=False) is None
        True
        >>> make_input_features(SCENARIOS["merge"], ego_relative=False, lane=True).out_features  # + lateral offset
        26
        >>> from torchrl_csirl.tasks import resolve_scenario
        >>> make_input_features(resolve_scenario("hopper"), ego_relative=False)  # x hidden
        DropFeatures(in_features=12, hidden=[0])
    """
    maps: list[nn.Module] = []
    if ego_relative:
        maps.append(EgoRelativeFeatures.from_scenario(spec))
    if lane:
        maps.append(LaneFeatures.from_scenario(spec, in_features=maps[-1].out_features if maps else None))
    hidden = tuple(getattr(spec, "hidden_feature_indices", ()))
    if hidden:  # last: the maps above append, so the observation's own indices stay where they were
        maps.append(DropFeatures(maps[-1].out_features if maps else int(spec.obs_dim), hidden))
    if not maps:
        return None
    return maps[0] if len(maps) == 1 else FeatureChain(*maps)


def with_standardization(features: nn.Module | None, observations: torch.Tensor) -> nn.Module:
    """A :class:`StandardizeFeatures` fitted to the raw ``observations``, then ``features``: the networks read
    standardised states (ValueDICE's authors' code). ``features`` must read the observation entry by entry
    (:class:`DropFeatures`, or none): the driving maps compute on the raw rows.

    Examples:
        >>> import torch
        >>> chain = with_standardization(DropFeatures(3, hidden=[0]), torch.tensor([[5.0, 0.0, 1.0], [7.0, 2.0, 1.0]]))
        >>> [type(m).__name__ for m in chain], chain[0].loc.tolist(), chain.out_features
        (['StandardizeFeatures', 'DropFeatures'], [6.0, 1.0, 1.0], 2)
    """
    if features is not None and not isinstance(features, DropFeatures):
        raise ValueError(f"standardised states need an input map that reads the observation entry by entry (none or "
                         f"DropFeatures), got {type(features).__name__}: it computes on the raw observation.")
    norm = StandardizeFeatures.from_data(observations)
    return norm if features is None else FeatureChain(norm, features)


def input_map(module: nn.Module) -> nn.Module | None:
    """The input map a network reads its observation through (the outermost one: a chain comes before its
    members), or None.

    Examples:
        >>> from torchrl_csirl.modules import make_actor
        >>> input_map(make_actor(3, 1, hidden=(8,), input_features=DropFeatures(3, hidden=[0])))
        DropFeatures(in_features=3, hidden=[0])
    """
    maps = (FeatureChain, EgoRelativeFeatures, LaneFeatures, DropFeatures, StandardizeFeatures)
    return next((m for m in module.modules() if isinstance(m, maps)), None)


def find_standardization(module: nn.Module) -> StandardizeFeatures | None:
    """The :class:`StandardizeFeatures` a network reads its raw observation through: its input map's first
    map (as :func:`with_standardization` builds it), or None.

    Examples:
        >>> import torch
        >>> from torchrl_csirl.modules import make_actor
        >>> norm = StandardizeFeatures(torch.zeros(3), torch.ones(3))
        >>> find_standardization(make_actor(3, 1, hidden=(8,), input_features=norm)) is norm
        True
    """
    outer = input_map(module)
    first = outer[0] if isinstance(outer, FeatureChain) else outer
    return first if isinstance(first, StandardizeFeatures) else None


def feature_map_from_config(config: dict[str, Any],
                            lane_centres: Callable[[str], Any] | None = None) -> nn.Module:
    """Rebuilds an input map from its ``config()`` (a saved policy's; a config without ``kind`` is an
    :class:`EgoRelativeFeatures`', as saved before lane features existed). ``lane_centres``: see
    :meth:`LaneFeatures.from_config`."""
    kind = config.get("kind", "ego")
    if kind == "chain":
        return FeatureChain(*(feature_map_from_config(c, lane_centres) for c in config["maps"]))
    if kind == "lane":
        return LaneFeatures.from_config(config, lane_centres)
    if kind == "drop":
        return DropFeatures(config["in_features"], config["hidden"])
    if kind == "standardize":
        return StandardizeFeatures(torch.tensor(config["loc"]), torch.tensor(config["scale"]))
    if kind != "ego":
        raise ValueError(f"unknown input map kind {kind!r} (saved by a newer torchrl-csirl?)")
    return EgoRelativeFeatures(**{k: v for k, v in config.items() if k != "kind"})
