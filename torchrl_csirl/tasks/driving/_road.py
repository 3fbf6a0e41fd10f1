"""Roads whose neighbour search reuses lane projections within one ``Road.act`` pass.

During ``Road.act`` every IDM vehicle looks for its leader/follower on its lane (and, for
MOBIL, on the side lanes) with ``Road.neighbour_vehicles``, which projects *every* vehicle onto
that lane: O(n^2) ``lane.local_coordinates`` calls per frame, the largest cost of a highway step
once the observation is fast. Positions do not change while vehicles decide their actions, so
the projection of a vehicle onto a lane is computed once per pass and reused. The same
function is called on the same inputs, so results are bit-for-bit upstream's.
"""
from __future__ import annotations

from highway_env.road.regulation import RegulatedRoad
from highway_env.road.road import Road
from highway_env.vehicle.objects import Landmark

__all__ = ["CachedRoad", "CachedRegulatedRoad", "NeighbourCacheMixin"]


class NeighbourCacheMixin:
    """Caches ``lane.local_coordinates(v.position)`` and ``on_lane`` within ``act``."""

    _projection_cache: dict | None = None

    def act(self) -> None:
        self._projection_cache = {}
        try:
            super().act()
        finally:
            self._projection_cache = None

    def _projection(self, lane, obj):
        key = (id(lane), id(obj))
        hit = self._projection_cache.get(key)
        if hit is None:
            s_v, lat_v = lane.local_coordinates(obj.position)
            hit = (s_v, lat_v, lane.on_lane(obj.position, s_v, lat_v, margin=1))
            self._projection_cache[key] = hit
        return hit

    def neighbour_vehicles(self, vehicle, lane_index=None):
        if self._projection_cache is None or self.neighbour_vehicles_connected_lanes:
            return super().neighbour_vehicles(vehicle, lane_index)
        lane_index = lane_index or vehicle.lane_index
        if not lane_index:
            return None, None
        lane = self.network.get_lane(lane_index)
        s = self._projection(lane, vehicle)[0]
        s_front = s_rear = None
        v_front = v_rear = None
        for v in self.vehicles + self.objects:
            if v is vehicle or isinstance(v, Landmark):
                continue
            s_v, _, on_lane = self._projection(lane, v)
            if not on_lane:
                continue
            if s <= s_v and (s_front is None or s_v <= s_front):
                s_front = s_v
                v_front = v
            if s_v < s and (s_rear is None or s_v > s_rear):
                s_rear = s_v
                v_rear = v
        return v_front, v_rear


class CachedRoad(NeighbourCacheMixin, Road):
    """:class:`~highway_env.road.road.Road` with the per-pass projection cache."""


class CachedRegulatedRoad(NeighbourCacheMixin, RegulatedRoad):
    """:class:`~highway_env.road.regulation.RegulatedRoad` with the per-pass projection cache."""
