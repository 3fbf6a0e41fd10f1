"""The expert driver's route following: the lane-level route to the destination, its geometry, and the
IDM + steering controllers that drive the ego vehicle along it under a candidate :class:`Behaviour`.
"""
from __future__ import annotations

import copy
import dataclasses
import math
from typing import Any, Sequence

import numpy as np

from torchrl_csirl.tasks.driving.expert_config import ExpertConfig

__all__ = ["Behaviour", "RouteFollower"]


@dataclasses.dataclass
class Behaviour:
    """A candidate behaviour: a lane on the route, a target speed, and an optional stop line."""

    lane_id: int | None
    speed: float
    stop: bool = False
    gap: tuple[float, float] | None = None  # (time headway, jam distance); None: the config's
    nudge: bool = False  # straddle the line towards ``lane_id`` until the gap behind is free

    def key(self) -> tuple:
        return (self.lane_id, self.speed, self.stop, self.gap, self.nudge)


class RouteFollower:
    """Lane-level route, path geometry and the IDM + steering controllers of the ego vehicle."""

    # highway-env ControlledVehicle gains
    TAU_HEADING = 0.2
    TAU_LATERAL = 0.6
    TAU_PURSUIT = 0.5 * TAU_HEADING
    MAX_STEERING = math.pi / 3
    # IDM parameters (IDMVehicle's exponent; gap parameters in ExpertConfig)
    DELTA = 4.0
    COMFORT_DECELERATION = 5.0

    def __init__(
        self, network: Any, roads: Sequence[tuple[str, str]], config: ExpertConfig, dt: float = 0.2
    ) -> None:
        self.network = network
        self.dt = dt
        self.roads = list(roads)
        self.config = config
        self.road_index = 0
        self._approach: dict[tuple, Any] = {}  # per-route lane caches, shared by copies (same route)

    def copy(self) -> RouteFollower:
        clone = copy.copy(self)
        return clone

    # --- route bookkeeping -------------------------------------------------------------------------
    def lanes_of(self, k: int) -> list[Any]:
        _from, _to = self.roads[k]
        return self.network.graph[_from][_to]

    def lane_id_on(self, k: int, position: np.ndarray, lane_id: int | None) -> int:
        lanes = self.lanes_of(k)
        if lane_id is not None and self.config.lane_choice:
            return int(min(max(lane_id, 0), len(lanes) - 1))
        distances = [abs(lane.local_coordinates(position)[1]) for lane in lanes]
        return int(np.argmin(distances))

    def update(self, vehicle: Any) -> None:
        """Advance along the route when the ego has passed the end of the current road."""
        while self.road_index < len(self.roads) - 1:
            lane = self.lanes_of(self.road_index)[0]
            long, _ = lane.local_coordinates(vehicle.position)
            if long < lane.length:
                # also accept the ego already being on a later road of the route
                if vehicle.lane_index[:2] in self.roads[self.road_index + 1 :]:
                    self.road_index = self.roads.index(vehicle.lane_index[:2])
                    continue
                break
            self.road_index += 1

    def crossing_lanes(self, k: int) -> list[Any]:
        """Lanes whose traffic crosses or joins road ``k`` of the route.

        Every lane of a road that is not on the route and does not start at road ``k``'s start node.
        """
        key = ("crossing", k)
        if key not in self._approach:
            start = self.roads[k][0]
            self._approach[key] = [
                lane
                for _from, to_dict in self.network.graph.items()
                if _from != start
                for _to, lanes in to_dict.items()
                if (_from, _to) not in self.roads
                for lane in lanes
            ]
        return self._approach[key]

    def approach_lane(self, k: int, window: int | None = None) -> int | None:
        """Lane of road ``k`` that leads to the next narrower road of the route (``None``: any).

        Only a road with fewer lanes within ``window`` roads ahead (default ``config.approach_roads``;
        the roads in between have as many lanes as road ``k``) counts, e.g. the roundabout's exit:
        only the ring lane whose end is closest to the start of the exit lane leads on.
        """
        window = self.config.approach_roads if window is None else window
        key = (k, window)
        if key not in self._approach:
            self._approach[key] = self._find_approach_lane(k, window)
        return self._approach[key]

    def _find_approach_lane(self, k: int, window: int) -> int | None:
        for j in range(k + 1, min(k + 1 + window, len(self.roads))):
            if len(self.lanes_of(j)) < len(self.lanes_of(j - 1)):
                lanes = self.lanes_of(j - 1)
                target = self.lanes_of(j)[0].position(0.0, 0.0)
                ends = [np.linalg.norm(lane.position(lane.length, 0.0) - target) for lane in lanes]
                return int(np.argmin(ends))
            if len(self.lanes_of(j)) != len(self.lanes_of(k)):
                return None
        return None

    def reference_lane(self, k: int) -> int:
        """Lane of road ``k`` along which route progress is measured (the exit's approach lane if any)."""
        if not self.config.approach_roads:
            return 0
        lane = self.approach_lane(k, window=len(self.roads))
        return 0 if lane is None else lane

    def path_lanes(self, position: np.ndarray, lane_id: int | None, count: int = 4) -> list[Any]:
        lanes = []
        current = None
        for k in range(self.road_index, min(self.road_index + count, len(self.roads))):
            forced = self.approach_lane(k) if lane_id is not None and self.config.approach_roads else None
            if forced is not None:
                current = forced
            elif current is None:
                current = self.lane_id_on(k, position, lane_id)
            else:
                n = len(self.lanes_of(k))
                if lane_id is not None and self.config.lane_choice:
                    current = int(min(max(lane_id, 0), n - 1))
                elif n != len(self.lanes_of(k - 1)):
                    end = lanes[-1].position(lanes[-1].length, 0)
                    current = self.lane_id_on(k, end, None)
            lanes.append(self.lanes_of(k)[current])
        return lanes

    def progress(self, vehicle: Any) -> float:
        """Distance travelled along the route (road lengths of passed roads + longitudinal position)."""
        passed = sum(self.lanes_of(k)[self.reference_lane(k)].length for k in range(self.road_index))
        lane = self.lanes_of(self.road_index)[self.reference_lane(self.road_index)]
        return passed + lane.local_coordinates(vehicle.position)[0]

    # --- controllers -------------------------------------------------------------------------------
    def steering(self, vehicle: Any, lane: Any, offset: float = 0.0) -> float:
        """Steering angle tracking the centre line of ``lane`` shifted laterally by ``offset`` [m]."""
        long, lat = lane.local_coordinates(vehicle.position)
        lat -= offset
        speed = max(abs(vehicle.speed), 1e-2)
        future_heading = lane.heading_at(long + speed * self.TAU_PURSUIT)
        lateral_speed_command = -lat / self.TAU_LATERAL
        heading_command = math.asin(float(np.clip(lateral_speed_command / speed, -1, 1)))
        heading_ref = future_heading + float(np.clip(heading_command, -math.pi / 4, math.pi / 4))
        heading_error = (heading_ref - vehicle.heading + math.pi) % (2 * math.pi) - math.pi
        heading_rate = heading_error / self.TAU_HEADING
        slip = math.asin(float(np.clip(vehicle.LENGTH / 2 / speed * heading_rate, -1, 1)))
        steering = math.atan(2 * math.tan(slip))
        return float(np.clip(steering, -self.MAX_STEERING, self.MAX_STEERING))

    def idm(
        self,
        speed: float,
        target_speed: float,
        gap: float | None,
        front_speed: float,
        gap_parameters: tuple[float, float] | None = None,
    ) -> float:
        accel_max = self.config.max_acceleration
        time_headway, jam_distance = gap_parameters or (self.config.time_headway, self.config.jam_distance)
        acceleration = accel_max * (1 - (max(speed, 0.0) / max(target_speed, 1e-2)) ** self.DELTA)
        if target_speed <= 0.0:
            acceleration = -accel_max * np.sign(speed)
        if gap is not None:
            dv = speed - front_speed
            d_star = (
                jam_distance
                + max(speed, 0.0) * time_headway
                + speed * dv / (2 * math.sqrt(accel_max * self.COMFORT_DECELERATION))
            )
            acceleration -= accel_max * (max(d_star, 0.0) / max(gap, 0.5)) ** 2
        return float(np.clip(acceleration, -self.config.max_braking, self.config.max_acceleration))

    def front_obstacle(
        self, vehicle: Any, others: Sequence[Any], lanes: Sequence[Any], stop_at: float | None
    ) -> tuple[float | None, float]:
        """Nearest obstacle ahead on the path: (bumper-to-bumper gap, its speed along the path)."""
        origin = lanes[0].local_coordinates(vehicle.position)[0]
        best_gap, best_speed = None, 0.0
        if stop_at is not None:
            best_gap, best_speed = stop_at - origin - vehicle.LENGTH / 2, 0.0
        offset = 0.0
        for lane in lanes:
            for other in others:
                if other is vehicle:
                    continue
                if np.abs(other.position - vehicle.position).max() > 80:
                    continue
                long, lat = lane.local_coordinates(other.position)
                if not (-2.5 <= long <= lane.length + 2.5) or abs(lat) > 2.6:
                    continue
                s = offset + long - origin
                if s <= 0.5:
                    continue
                gap = s - vehicle.LENGTH
                if best_gap is None or gap < best_gap:
                    heading = lane.heading_at(long)
                    direction = np.array([math.cos(heading), math.sin(heading)])
                    best_gap = gap
                    best_speed = float(np.dot(getattr(other, "velocity", np.zeros(2)), direction))
            offset += lane.length
        return best_gap, best_speed

    def control(self, vehicle: Any, others: Sequence[Any], behaviour: Behaviour) -> tuple[float, float]:
        """Physical (acceleration, steering) for the ego under a behaviour."""
        self.update(vehicle)
        if behaviour.nudge:
            nudged = self.nudge_control(vehicle, others, behaviour)
            if nudged is not None:
                return nudged
        lanes = self.path_lanes(vehicle.position, behaviour.lane_id)
        stop_at = None
        if behaviour.stop:
            stop_at = self.stop_line(vehicle, lanes)
        # steer towards the lane we are on or the next one when the current lane is ending
        lane = lanes[0]
        long, _ = lane.local_coordinates(vehicle.position)
        if long > lane.length and len(lanes) > 1:
            lane = lanes[1]
        steering = self.steering(vehicle, lane)
        gap, front_speed = self.front_obstacle(vehicle, others, lanes, stop_at)
        acceleration = self.idm(vehicle.speed, behaviour.speed, gap, front_speed, behaviour.gap)
        acceleration = max(acceleration, -max(vehicle.speed, 0.0) / self.dt)  # brake to a stop, never reverse
        return acceleration, steering

    def nudge_control(
        self, vehicle: Any, others: Sequence[Any], behaviour: Behaviour
    ) -> tuple[float, float] | None:
        """Controls of a "nudge" behaviour while the ego is not yet in its target lane (else ``None``).

        Longitudinal: the smaller IDM acceleration of the ego's own lane and of the target lane (as
        highway-env's IDM vehicles do while changing lanes). Lateral: move into the target lane once
        the gap behind in it is free (:meth:`gap_behind_is_free`); until then hold
        ``config.nudge_offset`` from the own lane's centre towards the target lane.
        """
        current = self.lane_id_on(self.road_index, vehicle.position, None)
        n = len(self.lanes_of(self.road_index))
        target = int(min(max(behaviour.lane_id, 0), n - 1))
        if current == target:
            return None
        own = self.path_lanes(vehicle.position, current)
        lanes = self.path_lanes(vehicle.position, target)
        accelerations = []
        for path in (own, lanes):
            gap, front_speed = self.front_obstacle(vehicle, others, path, None)
            accelerations.append(self.idm(vehicle.speed, behaviour.speed, gap, front_speed, behaviour.gap))
        acceleration = max(min(accelerations), -max(vehicle.speed, 0.0) / self.dt)
        if self.gap_behind_is_free(vehicle, others, lanes[0]):
            steering = self.steering(vehicle, lanes[0])
        else:
            # the target lane's centre beside the ego, in the own lane's frame: its sign is the side
            s_target, _ = lanes[0].local_coordinates(vehicle.position)
            _, side = own[0].local_coordinates(lanes[0].position(s_target, 0.0))
            steering = self.steering(vehicle, own[0], offset=math.copysign(self.config.nudge_offset, side))
        return acceleration, steering

    def gap_behind_is_free(self, vehicle: Any, others: Sequence[Any], lane: Any) -> bool:
        """Whether the ego can move into ``lane``: no vehicle in it alongside, none close behind.

        A vehicle behind needs ``safety_margin`` plus one second of its closing speed between its
        front and the ego's rear; one ahead needs ``safety_margin`` between the bumpers.
        """
        s_ego, _ = lane.local_coordinates(vehicle.position)
        margin = self.config.safety_margin
        for other in others:
            if other is vehicle or np.abs(other.position - vehicle.position).max() > 40:
                continue
            s, lat = lane.local_coordinates(other.position)
            if abs(lat) > lane.width_at(s) / 2:
                continue
            length = (vehicle.LENGTH + getattr(other, "LENGTH", vehicle.LENGTH)) / 2
            if s >= s_ego:
                if s - s_ego < length + margin:
                    return False
            elif s_ego - s < length + margin + max(0.0, other.speed - vehicle.speed) * 1.0:
                return False
        return True

    def stop_line(self, vehicle: Any, lanes: Sequence[Any]) -> float | None:
        """Path coordinate (from the start of ``lanes[0]``) of the next stop line, if any is ahead."""
        offset = 0.0
        for i, k in enumerate(range(self.road_index, min(self.road_index + len(lanes), len(self.roads)))):
            if self.roads[k] in self.config.yield_roads:
                return offset + lanes[i].length - 1.0
            offset += lanes[i].length
        return None

    def can_stop(self, vehicle: Any, lanes: Sequence[Any]) -> bool:
        stop = self.stop_line(vehicle, lanes)
        if stop is None:
            return False
        remaining = stop - lanes[0].local_coordinates(vehicle.position)[0] - vehicle.LENGTH / 2
        return remaining > vehicle.speed**2 / (2 * self.config.max_braking) - 0.5

