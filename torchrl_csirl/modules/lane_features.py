"""Lane-relative input features: the ego's offset from the road's centre lines, computed from its position.

The driving observations give the ego's absolute position normalised over wide ranges (the
roundabout and the intersection map +-100 m to [-1, 1]), so a lane's 2 m half-width is 0.02 of an
input's range: the difference between driving on the exit lane and leaving the road is a few
thousandths in the input (docs/studies/index.md, "Where the roundabout and intersection policies leave
the road"). :class:`LaneFeatures` appends what a driver sees directly: the signed offset of the ego
from the nearest lane centre line of the scene, in half lane widths, and, where the observation
has the ego's heading, the heading relative to that lane. The road of each scenario is fixed, so
the centre lines are sampled once from highway-env's road network
(:func:`torchrl_csirl.tasks.sample_lane_centres`, through the scenario's spec) and saved with the
module; the module has no parameters and reads only the observation (demonstrations need nothing new).
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import torch
from torch import nn

from torchrl_csirl.modules.input_memo import mapped_once

__all__ = ["LaneFeatures"]

class LaneFeatures(nn.Module):
    """Appends the ego's lane-relative position (and heading) to an observation's features.

    For the ego position ``p`` (de-normalised from ``obs[x_index]``, ``obs[y_index]``) the module
    finds the nearest sampled centre-line point ``c`` (heading ``h``, half width ``w``) and appends
    ``clip(((p - c) x (cos h, sin h)) / w, -clip, clip)``, the signed lateral offset in half lane
    widths (beyond +-1: off that lane), then, when ``cos_index``/``sin_index`` are given,
    ``cos(theta - h)`` and ``sin(theta - h)`` of the ego heading ``theta``. It reads the first
    ``obs_dim`` entries of its input and passes its whole input through, so it can follow another
    feature map that appends after the observation.

    Args:
        centres: ``(P, 4)`` centre-line points: x, y, heading, half width
            (:func:`torchrl_csirl.tasks.sample_lane_centres`).
        obs_dim (int): size of the observation (the input's first entries).
        x_index (int): the ego's normalised x in the observation.
        y_index (int): the ego's normalised y in the observation.
        x_range (pair of float): the x range mapped to [-1, 1] by the observation.
        y_range (pair of float): the y range mapped to [-1, 1] by the observation.
        cos_index (int, optional): the ego's heading cosine, if observed.
        sin_index (int, optional): the ego's heading sine, if observed.
        in_features (int, optional): width of the input (``obs_dim`` unless a map precedes this one).
        clip (float): bound of the lateral offset. Defaults to ``3.0``.
        scenario (str, optional): the scenario the points come from (a label: :meth:`config` stores
            the points themselves).

    Examples:
        >>> import numpy as np, torch
        >>> centres = np.array([[0.0, 0.0, 0.0, 2.0], [1.0, 0.0, 0.0, 2.0]], dtype=np.float32)  # a lane along x
        >>> feats = LaneFeatures(centres, obs_dim=2, x_index=0, y_index=1, x_range=(-100, 100), y_range=(-100, 100))
        >>> feats(torch.tensor([[0.005, 0.01]]))  # x 0.5 m, y 1 m: half a half-width left of the line
        tensor([[0.0050, 0.0100, 0.5000]])
    """

    def __init__(
        self,
        centres: np.ndarray | Sequence[Sequence[float]],
        obs_dim: int,
        x_index: int,
        y_index: int,
        x_range: Sequence[float],
        y_range: Sequence[float],
        cos_index: int | None = None,
        sin_index: int | None = None,
        in_features: int | None = None,
        clip: float = 3.0,
        scenario: str | None = None,
    ) -> None:
        super().__init__()
        centres = np.asarray(centres, dtype=np.float32)
        if centres.ndim != 2 or centres.shape[1] != 4 or not len(centres):
            raise ValueError(f"centres must be a non-empty (P, 4) array (x, y, heading, half width), got {centres.shape}.")
        if not all(0 <= i < obs_dim for i in (x_index, y_index)):
            raise ValueError(f"x_index and y_index must be in [0, {obs_dim}), got {x_index}, {y_index}.")
        if (cos_index is None) != (sin_index is None):
            raise ValueError("cos_index and sin_index go together: give both or neither.")
        if clip <= 0:
            raise ValueError(f"clip must be positive, got {clip}.")
        self.obs_dim, self.x_index, self.y_index = int(obs_dim), int(x_index), int(y_index)
        self.x_range = (float(x_range[0]), float(x_range[1]))
        self.y_range = (float(y_range[0]), float(y_range[1]))
        self.cos_index, self.sin_index = cos_index, sin_index
        self._in_features = int(in_features if in_features is not None else obs_dim)
        self.clip, self.scenario = float(clip), scenario
        # not a buffer: the ensemble critics stack their members' tensors, and the points are constants
        self._centres = torch.as_tensor(centres)

    @classmethod
    def from_scenario(cls, spec: Any, in_features: int | None = None, clip: float = 3.0) -> LaneFeatures:
        """The module for a driving scenario (a :class:`~torchrl_csirl.tasks.ScenarioSpec`): its road's centre lines
        (``spec.lane_centres()``) and its observation layout (the heading where the scenario observes
        ``cos_h``, ``sin_h``).

        Examples:
            >>> from torchrl_csirl.tasks import SCENARIOS
            >>> feats = LaneFeatures.from_scenario(SCENARIOS["roundabout"])
            >>> feats.in_features, feats.out_features
            (35, 38)
        """
        features = list(spec.features)
        heading = ("cos_h" in features and "sin_h" in features)
        return cls(spec.lane_centres(), int(spec.obs_dim), features.index("x"), features.index("y"),
                   spec.features_range["x"], spec.features_range["y"],
                   features.index("cos_h") if heading else None, features.index("sin_h") if heading else None,
                   in_features, clip, scenario=spec.name)

    @property
    def in_features(self) -> int:
        return self._in_features

    @property
    def out_features(self) -> int:
        return self._in_features + (1 if self.cos_index is None else 3)

    def config(self) -> dict[str, Any]:
        """The constructor arguments (to rebuild the module, e.g. with a saved policy)."""
        return {
            "kind": "lane", "scenario": self.scenario,
            "centres": self._centres.tolist(),
            "obs_dim": self.obs_dim, "x_index": self.x_index, "y_index": self.y_index,
            "x_range": list(self.x_range), "y_range": list(self.y_range),
            "cos_index": self.cos_index, "sin_index": self.sin_index,
            "in_features": self._in_features, "clip": self.clip,
        }

    @classmethod
    def from_config(cls, config: dict[str, Any],
                    lane_centres: Callable[[str], np.ndarray] | None = None) -> LaneFeatures:
        """The inverse of :meth:`config`.

        A config saved with the scenario's name and no points (policies saved before the points
        were stored) takes them from ``lane_centres(scenario)``, e.g.
        :func:`torchrl_csirl.tasks.sample_lane_centres`.

        Raises:
            ValueError: no points in ``config`` and no ``lane_centres``.
        """
        config = {k: v for k, v in config.items() if k != "kind"}
        if config.get("centres") is None:
            if lane_centres is None:
                raise ValueError(
                    f"these lane features were saved with the name of their scenario ({config.get('scenario')}) "
                    "and not their points; pass lane_centres=torchrl_csirl.tasks.sample_lane_centres to rebuild them.")
            config["centres"] = lane_centres(config["scenario"])
        return cls(**config)

    @staticmethod
    def _denormalise(value: torch.Tensor, bounds: tuple[float, float]) -> torch.Tensor:
        low, high = bounds
        return low + (value + 1.0) * (high - low) / 2.0

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        return mapped_once(self, self._lane_features, features)

    def _lane_features(self, features: torch.Tensor) -> torch.Tensor:
        if features.shape[-1] != self._in_features:
            raise ValueError(f"LaneFeatures expects inputs of size {self._in_features}, got {features.shape[-1]}.")
        centres = self._centres.to(device=features.device, dtype=features.dtype)
        position = torch.stack([self._denormalise(features[..., self.x_index], self.x_range),
                                self._denormalise(features[..., self.y_index], self.y_range)], -1)
        flat = position.reshape(-1, 2)
        nearest = torch.cdist(flat, centres[:, :2]).argmin(-1)
        point = centres[nearest]
        offset = flat - point[:, :2]
        cos_h, sin_h = point[:, 2].cos(), point[:, 2].sin()
        lateral = (cos_h * offset[:, 1] - sin_h * offset[:, 0]) / point[:, 3]
        extra = [lateral.clamp(-self.clip, self.clip)]
        if self.cos_index is not None:
            heading = torch.atan2(features[..., self.sin_index], features[..., self.cos_index]).reshape(-1)
            relative = heading - point[:, 2]
            extra += [relative.cos(), relative.sin()]
        extra = torch.stack(extra, -1).reshape(*features.shape[:-1], len(extra))
        return torch.cat([features, extra], dim=-1)

    def extra_repr(self) -> str:
        heading = "" if self.cos_index is None else ", heading"
        return f"scenario={self.scenario}, points={len(self._centres)}, lateral{heading}"
