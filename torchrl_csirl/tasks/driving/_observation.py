"""A pandas-free Kinematics observation, bit-for-bit identical to highway-env's.

highway-env's :class:`~highway_env.envs.common.observation.KinematicObservation` builds a
``pandas.DataFrame`` from per-vehicle dictionaries on every step, which costs more than the
whole physics step in our scenes. :class:`FastKinematicObservation` produces the same array
with plain numpy:

* the same neighbour selection as ``Road.close_objects_to`` (Euclidean range check, the
  ``see_behind`` test and the stable sort on ``|lane_distance_to|``), but each lane
  projection is computed once instead of two or three times and obstacles are only looked at
  when they are observed;
* the same feature values (``Vehicle.to_dict`` semantics, including relative coordinates),
* the same normalisation ``lmap`` arithmetic in float64, clipping, zero rows for absent
  vehicles, shuffling and final cast to float32.
"""
from __future__ import annotations

import numpy as np
from highway_env.envs.common.observation import KinematicObservation

__all__ = ["FastKinematicObservation"]

_CHEAP_FEATURES = frozenset({"presence", "x", "y", "vx", "vy", "cos_h", "sin_h", "heading"})


class FastKinematicObservation(KinematicObservation):
    """Drop-in replacement of highway-env's ``KinematicObservation`` without pandas.

    Takes exactly the constructor arguments of the upstream class (it is one) and returns
    identical arrays from :meth:`observe`.

    Examples:
        >>> import gymnasium as gym
        >>> import numpy as np
        >>> import highway_env  # noqa: F401
        >>> env = gym.make("highway-fast-v0").unwrapped
        >>> _ = env.reset(seed=0)
        >>> fast = FastKinematicObservation(env, **env.config["observation"])
        >>> bool(np.array_equal(fast.observe(), env.observation_type.observe()))
        True
    """

    def _feature_row(self, vehicle, origin, observe_intentions: bool) -> list[float]:
        features = self.features
        if not _CHEAP_FEATURES.issuperset(features):
            d = vehicle.to_dict(origin, observe_intentions=observe_intentions)
            return [d[f] for f in features]
        position = vehicle.position
        direction = vehicle.direction
        velocity = vehicle.speed * direction
        values = {
            "presence": 1,
            "x": position[0],
            "y": position[1],
            "vx": velocity[0],
            "vy": velocity[1],
            "heading": vehicle.heading,
            "cos_h": direction[0],
            "sin_h": direction[1],
        }
        if origin is not None:
            origin_velocity = origin.speed * origin.direction
            values["x"] -= origin.position[0]
            values["y"] -= origin.position[1]
            values["vx"] -= origin_velocity[0]
            values["vy"] -= origin_velocity[1]
        return [values[f] for f in features]

    def _close_objects(self, ego) -> list:
        """``Road.close_objects_to`` with each lane projection computed once."""
        road = self.env.road
        distance = self.env.PERCEPTION_DISTANCE
        count = self.vehicles_count - 1
        lane = ego.lane
        ego_position = ego.position
        ego_long = lane.local_coordinates(ego_position)[0]
        min_gap = -2 * ego.LENGTH
        candidates = []
        for v in road.vehicles:
            if not (np.linalg.norm(v.position - ego_position) < distance and v is not ego):
                continue
            gap = lane.local_coordinates(v.position)[0] - ego_long
            if self.see_behind or min_gap < gap:
                candidates.append((v, gap))
        if self.include_obstacles:
            for o in road.objects:
                if np.linalg.norm(o.position - ego_position) < distance:
                    gap = lane.local_coordinates(o.position)[0] - ego_long
                    if min_gap < gap:
                        candidates.append((o, gap))
        if self.order == "sorted":
            candidates = sorted(candidates, key=lambda item: abs(item[1]))
        if count:
            candidates = candidates[:count]
        return [c[0] for c in candidates]

    def observe(self) -> np.ndarray:
        if not self.env.road:
            return np.zeros(self.space().shape)
        ego = self.observer_vehicle
        # upstream calls ego.to_dict() with its default observe_intentions=True
        rows = [self._feature_row(ego, None, True)]
        close = self._close_objects(ego)
        if close:
            origin = ego if not self.absolute else None
            rows.extend(
                self._feature_row(v, origin, self.observe_intentions)
                for v in close[-self.vehicles_count + 1 :]
            )
        n_features = len(self.features)
        values = np.array(rows, dtype=np.float64).reshape(len(rows), n_features)
        if self.normalize:
            if not self.features_range:
                self._default_features_range()
            for j, feature in enumerate(self.features):
                f_range = self.features_range.get(feature)
                if f_range is None:
                    continue
                column = values[:, j]
                column = f_range_map(column, f_range)
                if self.clip:
                    column = np.clip(column, -1, 1)
                values[:, j] = column
        if values.shape[0] < self.vehicles_count:
            obs = np.zeros((self.vehicles_count, n_features), dtype=np.float64)
            obs[: values.shape[0]] = values
        else:
            obs = values
        if self.order == "shuffled":
            self.env.np_random.shuffle(obs[1:])
        return obs.astype(self.space().dtype)

    def _default_features_range(self) -> None:
        # Same defaults as upstream's normalize_obs (only used without explicit ranges).
        import pandas as pd

        self.normalize_obs(pd.DataFrame(columns=self.features))


def f_range_map(column: np.ndarray, f_range) -> np.ndarray:
    """highway-env's ``utils.lmap(v, [lo, hi], [-1, 1])`` with the same operation order."""
    return -1 + (column - f_range[0]) * (1 - -1) / (f_range[1] - f_range[0])
