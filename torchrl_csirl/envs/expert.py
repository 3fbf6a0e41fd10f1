"""A privileged expert driver for the four CSIRL driving scenarios.

The expert reads the simulator state (road network, ego vehicle, other vehicles) from ``env.unwrapped``
and returns continuous actions in the learner's normalised units: ``[acceleration / 15, steering / (pi / 2)]``
clipped to ``[-1, 1]``.

It is a *route-following controller with a short-horizon look-ahead*:

* **lateral**: highway-env's own cascaded lateral-position / heading controller
  (:meth:`highway_env.vehicle.controller.ControlledVehicle.steering_control`) tracking the centre line
  of the target lane along the route to the scenario's destination;
* **longitudinal**: the Intelligent Driver Model (IDM, as in
  :class:`highway_env.vehicle.behavior.IDMVehicle`) towards a target speed, following the nearest
  vehicle on the ego's *path* (which also covers vehicles crossing it) and, for "yield" behaviours,
  a virtual stopped vehicle at the stop line of the roundabout entry / intersection;
* **decision** (lane choice, MOBIL-like, and gap acceptance at junctions): every step a handful of
  candidate behaviours (target lane x target speed x go/yield) are simulated for a few seconds on a
  light copy of the road in which the other vehicles run their own (deterministic) IDM/MOBIL models
  and react to the ego. The behaviour with the most route progress that neither collides, leaves the
  road nor comes closer than a safety margin to another vehicle is applied for one step. Since the
  others' behaviour models are deterministic, the look-ahead is an exact prediction of the traffic
  within the horizon (vehicles spawned later by the environment are the only unknown).

Examples:
    >>> from torchrl_csirl.envs.expert import make_expert, rollout_expert
    >>> from torchrl_csirl.envs import make_gym_env
    >>> env = make_gym_env("merge")
    >>> episode = rollout_expert(env, seed=0, empty_road=True)
    >>> bool(episode["success"]), episode["action"].shape[1]
    (True, 2)
"""
from __future__ import annotations

import copy
import dataclasses
import math
import os
from functools import partial
from typing import Any, Callable, Sequence

import numpy as np

from torchrl_csirl.envs.locomotion import LOCOMOTION_TASKS

ACCELERATION_SCALE = 15.0
"""Physical acceleration [m/s^2] of a normalised action of 1."""
STEERING_SCALE = math.pi / 2
"""Physical steering angle [rad] of a normalised action of 1."""

__all__ = [
    "ACCELERATION_SCALE",
    "STEERING_SCALE",
    "ExpertConfig",
    "ExpertDriver",
    "EXPERT_CONFIGS",
    "clear_traffic",
    "expert_tasks",
    "make_expert",
    "rollout_expert",
    "normalize_action",
]


@dataclasses.dataclass(frozen=True)
class ExpertConfig:
    """Per-scenario settings of :class:`ExpertDriver`.

    Args:
        destination: road-network node the route leads to (``None``: keep driving along the road).
        speeds: candidate target speeds [m/s] for the "go" behaviours.
        lane_choice: whether the expert may choose among the parallel lanes of the current road.
        preferred_lane: lane id the expert prefers near the end of the route (``None``: no preference).
        yield_roads: road segments ``(from, to)`` whose end is a stop line at which the expert may
            wait (roundabout entry, intersection approach).
        horizon: look-ahead horizon in steps.
        safety_margin: minimal gap [m] (between vehicle outlines, approximately) kept to others.
        max_acceleration: largest acceleration the expert commands [m/s^2].
        max_braking: largest deceleration the expert commands [m/s^2].
        replan_every: steps between two decisions (the chosen behaviour's controllers run every step).
        perception_radius: the expert perceives only the vehicles within this distance [m] (per
            axis): they are the ones simulated in the look-ahead and the ones the executing
            controllers react to (the same set, so that the plan and its execution agree).
        time_headway: IDM desired time gap to the vehicle ahead [s].
        jam_distance: IDM desired bumper-to-bumper distance at standstill [m].
        close_following: optional ``(time_headway, jam_distance)`` of extra "close following"
            candidates (at the highest target speed, on every candidate lane): closing up on the
            vehicle ahead opens room to cut in front of a vehicle in the next lane (merge); also
            used in the roundabout, where a tighter gap measured more successes (docs/experts.md).
        approach_roads: on the last ``approach_roads`` roads before a road with fewer lanes (the
            roundabout's exit), every lane-choosing behaviour drives on the one lane that leads
            onto it; with ``approach_roads > 0`` route progress is also measured along that lane
            (not along lane 0, the inner ring lane, which would favour the inner lanes).
        approach_lane_cost: score penalty [m of progress] per lane still to cross, at the end of the
            look-ahead, to reach the lane that leads onto the next narrower road.
        nudge_offset: optional lateral offset [m] of extra "nudge" candidates (merge): the ego waits
            straddling the line towards the next lane, this far from its lane centre, close behind the
            vehicle ahead in its own lane; other vehicles' IDM counts a vehicle within 1 m of their lane
            as in it, so the vehicle beside it in the next lane, which the ego now seems to be ahead
            of, brakes and opens a gap; the ego moves over once the gap behind it is free (see
            :meth:`_RouteFollower.nudge_control`). Two slow vehicles side by side no longer block both
            lanes. The nudge candidates follow with the ``close_following`` gap (at the highest target
            speed), which must be short enough for the ego to get ahead of the centre of the vehicle
            beside it.
        episode_end_x: the scenario ends the episode once the ego passes this x [m] (merge: 370 m);
            the look-ahead stops there, so that a long horizon at high speed does not count driving
            off the end of the road, which the episode never reaches, as a failure.
        junction_min_speed: optional junction-clearance rule [m/s]: a behaviour whose look-ahead has
            the ego inside the junction (the route's road right after a stop line of
            ``yield_roads``) slower than this is rejected (scored below every behaviour that keeps
            moving through it, above every collision), so the expert enters the junction only when
            it can cross it without stopping in the crossing traffic's path, and waits at the stop
            line otherwise (intersection: 3 m/s).
    """

    destination: str | None
    speeds: tuple[float, ...]
    lane_choice: bool = False
    preferred_lane: int | None = None
    yield_roads: tuple[tuple[str, str], ...] = ()
    horizon: int = 15
    safety_margin: float = 1.5
    max_acceleration: float = 6.0
    max_braking: float = 12.0
    replan_every: int = 2
    perception_radius: float = 120.0
    time_headway: float = 1.0
    jam_distance: float = 10.0
    close_following: tuple[float, float] | None = None
    approach_roads: int = 0
    approach_lane_cost: float = 0.0
    nudge_offset: float | None = None
    episode_end_x: float | None = None
    junction_min_speed: float | None = None


EXPERT_CONFIGS: dict[str, ExpertConfig] = {
    "highway-fast": ExpertConfig(
        destination=None,
        speeds=(30.0, 22.0),
        lane_choice=True,
        preferred_lane=2,
        horizon=12,
        perception_radius=60.0,
    ),
    "merge": ExpertConfig(
        destination="d",
        speeds=(45.0, 35.0, 22.0),
        lane_choice=True,
        horizon=20,
        time_headway=0.6,
        jam_distance=8.0,
        close_following=(0.0, 1.6),
        nudge_offset=1.3,
        episode_end_x=370.0,
        perception_radius=80.0,
        max_acceleration=15.0,
    ),
    "roundabout": ExpertConfig(
        destination="nxr",
        speeds=(30.0, 24.0, 18.0, 12.0),
        lane_choice=True,
        max_acceleration=12.0,
        time_headway=0.5,
        jam_distance=4.0,
        close_following=(0.15, 1.5),
        approach_roads=1,
        approach_lane_cost=4.0,
        yield_roads=(("ses", "se"),),
        horizon=20,
        perception_radius=60.0,
    ),
    "intersection": ExpertConfig(
        destination="o11",
        speeds=(15.0, 12.0, 9.0, 7.0),
        max_acceleration=12.0,
        lane_choice=False,
        yield_roads=(("o10", "ir10"),),
        perception_radius=60.0,
        horizon=20,
        junction_min_speed=3.0,
    ),
}


def normalize_action(acceleration: float, steering: float) -> np.ndarray:
    """Convert a physical command into the learner's normalised action.

    Args:
        acceleration: longitudinal acceleration [m/s^2].
        steering: front-wheel steering angle [rad].

    Returns:
        ``float32`` array ``[acceleration / 15, steering / (pi / 2)]`` clipped to ``[-1, 1]``.

    Examples:
        >>> normalize_action(7.5, math.pi / 4).tolist()
        [0.5, 0.5]
    """
    action = np.array([acceleration / ACCELERATION_SCALE, steering / STEERING_SCALE], dtype=np.float64)
    return np.clip(action, -1.0, 1.0).astype(np.float32)


# ----------------------------------------------------------------------------------------------------
# Light copies of the simulator state for look-ahead
# ----------------------------------------------------------------------------------------------------
class _LaneLocator:
    """Exact, faster ``RoadNetwork.get_closest_lane_index`` for the look-ahead copies.

    highway-env scans every lane of the network for every vehicle at every step. A lane's
    ``distance_with_heading`` is never smaller than the Euclidean distance from the position to the
    lane's centre curve, so lanes whose (inflated) bounding box does not contain the position cannot
    beat a candidate closer than the inflation ``margin``: only nearby lanes are scanned, in the
    network's order (same tie-breaking), with a full scan as fallback.
    """

    def __init__(self, network: Any, margin: float = 15.0) -> None:
        self.network = network
        self.margin = margin
        self.indexes: list[tuple] = []
        self.lanes: list[Any] = []
        boxes = []
        for _from, to_dict in network.graph.items():
            for _to, lanes in to_dict.items():
                for _id, lane in enumerate(lanes):
                    samples = np.linspace(0.0, float(lane.length), max(2, int(lane.length // 2) + 2))
                    points = np.array([lane.position(s, 0.0) for s in samples])
                    boxes.append(np.concatenate([points.min(0) - margin, points.max(0) + margin]))
                    self.indexes.append((_from, _to, _id))
                    self.lanes.append(lane)
        self.boxes = np.array(boxes)

    def __call__(self, position: np.ndarray, heading: float | None = None) -> tuple:
        x, y = float(position[0]), float(position[1])
        b = self.boxes
        near = np.flatnonzero((b[:, 0] <= x) & (x <= b[:, 2]) & (b[:, 1] <= y) & (y <= b[:, 3]))
        if len(near):
            distances = [self.lanes[i].distance_with_heading(position, heading) for i in near]
            best = int(np.argmin(distances))
            if distances[best] <= self.margin:
                return self.indexes[near[best]]
        distances = [lane.distance_with_heading(position, heading) for lane in self.lanes]
        return self.indexes[int(np.argmin(distances))]


_FAST_NETWORKS: dict[int, tuple[Any, Any]] = {}


def fast_network(network: Any) -> Any:
    """A shallow copy of a road network with a faster (same result) closest-lane search."""
    cached = _FAST_NETWORKS.get(id(network))
    if cached is not None and cached[0] is network:
        return cached[1]
    fast = copy.copy(network)
    fast.get_closest_lane_index = _LaneLocator(network)
    if len(_FAST_NETWORKS) > 64:
        _FAST_NETWORKS.clear()
    _FAST_NETWORKS[id(network)] = (network, fast)
    return fast


def perceived_vehicles(vehicles: Sequence[Any], center: np.ndarray, radius: float) -> list[Any]:
    """The vehicles within ``radius`` metres of ``center`` (per axis): what the expert perceives.

    Examples:
        >>> from types import SimpleNamespace
        >>> cars = [SimpleNamespace(position=np.array([x, 0.0])) for x in (10.0, 70.0)]
        >>> len(perceived_vehicles(cars, np.zeros(2), 60.0))
        1
    """
    if not math.isfinite(radius):
        return list(vehicles)
    return [v for v in vehicles if np.abs(v.position - center).max() <= radius]


def clone_road(road: Any, center: np.ndarray | None = None, radius: float = math.inf) -> tuple[Any, dict[int, Any]]:
    """Copy a highway-env road so that stepping the copy leaves the original untouched.

    The (immutable) road network is shared; vehicles, objects and the random generator are copied.
    With ``center``/``radius``, only vehicles within ``radius`` metres of ``center`` are kept.

    Returns:
        the copy and a map ``id(original vehicle) -> copied vehicle``.
    """
    new_road = copy.copy(road)
    new_road.network = fast_network(road.network)
    new_road.np_random = copy.deepcopy(road.np_random)
    mapping: dict[int, Any] = {}

    def _copy_object(obj: Any) -> Any:
        clone = copy.copy(obj)
        clone.position = np.array(obj.position, dtype=float)
        if isinstance(getattr(obj, "action", None), dict):
            clone.action = dict(obj.action)
        if getattr(obj, "route", None) is not None:
            clone.route = list(obj.route)
        if hasattr(obj, "log"):
            clone.log = []
        clone.road = new_road
        mapping[id(obj)] = clone
        return clone

    vehicles = road.vehicles if center is None else perceived_vehicles(road.vehicles, center, radius)
    new_road.vehicles = [_copy_object(v) for v in vehicles]
    new_road.objects = [_copy_object(o) for o in road.objects]
    return new_road, mapping


def _overlaps_lane(vehicle: Any, lane: Any) -> bool:
    """Whether a vehicle's outline is on a lane: its centre within half a lane + half its width, or a corner on it.

    The corners matter for a vehicle turned across a lane: its centre can be clear of the lane while
    its front is in it (docs/experts.md, the intersection's test episode 49).
    """
    long, lat = lane.local_coordinates(vehicle.position)
    within = -vehicle.LENGTH / 2 <= long <= lane.length + vehicle.LENGTH / 2
    if within and abs(lat) <= lane.width_at(long) / 2 + vehicle.WIDTH / 2:
        return True
    for corner in vehicle.polygon()[:4]:
        long, lat = lane.local_coordinates(corner)
        if 0.0 <= long <= lane.length and abs(lat) <= lane.width_at(long) / 2:
            return True
    return False


# ----------------------------------------------------------------------------------------------------
# Low-level control
# ----------------------------------------------------------------------------------------------------
@dataclasses.dataclass
class _Behaviour:
    """A candidate behaviour: a lane on the route, a target speed, and an optional stop line."""

    lane_id: int | None
    speed: float
    stop: bool = False
    gap: tuple[float, float] | None = None  # (time headway, jam distance); None: the config's
    nudge: bool = False  # straddle the line towards ``lane_id`` until the gap behind is free

    def key(self) -> tuple:
        return (self.lane_id, self.speed, self.stop, self.gap, self.nudge)


class _RouteFollower:
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

    def copy(self) -> _RouteFollower:
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

    def control(self, vehicle: Any, others: Sequence[Any], behaviour: _Behaviour) -> tuple[float, float]:
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
        self, vehicle: Any, others: Sequence[Any], behaviour: _Behaviour
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


# ----------------------------------------------------------------------------------------------------
# The expert
# ----------------------------------------------------------------------------------------------------
class ExpertDriver:
    """Privileged expert driver for a CSIRL driving scenario.

    Args:
        scenario: one of ``"highway-fast"``, ``"merge"``, ``"roundabout"``, ``"intersection"``.
        config: optional :class:`ExpertConfig` overriding the scenario's defaults.
        dt: simulation step [s] (0.2 s in all CSIRL scenarios).

    Examples:
        >>> from torchrl_csirl.envs import make_gym_env
        >>> env = make_gym_env("highway-fast")
        >>> _ = env.reset(seed=0)
        >>> expert = ExpertDriver("highway-fast")
        >>> expert.reset(env)
        >>> action = expert.act(env)
        >>> action.shape, bool(abs(action).max() <= 1)
        ((2,), True)
    """

    def __init__(self, scenario: str, config: ExpertConfig | None = None, dt: float = 0.2) -> None:
        if scenario not in EXPERT_CONFIGS and config is None:
            raise ValueError(f"Unknown scenario {scenario!r}; expected one of {sorted(EXPERT_CONFIGS)}.")
        from torchrl_csirl.envs.scenarios import SCENARIOS

        self.scenario = scenario
        self.config = config or EXPERT_CONFIGS[scenario]
        # one place for the finish: the scenario spec (used to rank behaviours near the end)
        self.finish_position = SCENARIOS[scenario].finish_position if scenario in SCENARIOS else None
        self.dt = dt
        self._route: _RouteFollower | None = None
        self._previous: _Behaviour | None = None
        self._steps = 0

    # --- public API --------------------------------------------------------------------------------
    def reset(self, env: Any) -> None:
        """Plan the route of the ego vehicle of a freshly reset environment."""
        base = env.unwrapped
        vehicle = base.vehicle
        network = base.road.network
        start = vehicle.lane_index[:2]
        roads = [start]
        if self.config.destination is not None and start[1] != self.config.destination:
            path = network.shortest_path(start[1], self.config.destination)
            if not path:
                raise ValueError(
                    f"No route from {start} to {self.config.destination!r} in scenario {self.scenario!r}."
                )
            nodes = [start[1], *path] if path[0] != start[1] else list(path)
            roads += [(a, b) for a, b in zip(nodes[:-1], nodes[1:])]
        self._route = _RouteFollower(network, roads, self.config, self.dt)
        self._previous = None
        self._steps = 0

    def act(self, env: Any) -> np.ndarray:
        """Normalised action ``[acceleration / 15, steering / (pi / 2)]`` for the current state."""
        if self._route is None:
            self.reset(env)
        base = env.unwrapped
        if self._previous is None or self._steps % self.config.replan_every == 0:
            behaviour = self.decide(base.road, base.vehicle)
        else:
            behaviour = self._previous
        self._steps += 1
        self._previous = behaviour
        others = perceived_vehicles(base.road.vehicles, base.vehicle.position, self.config.perception_radius)
        acceleration, steering = self._route.control(base.vehicle, others, behaviour)
        return normalize_action(acceleration, steering)

    __call__ = act

    # --- decision ----------------------------------------------------------------------------------
    def candidates(self, vehicle: Any) -> list[_Behaviour]:
        route = self._route
        route.update(vehicle)
        lane_ids: list[int | None] = [None]
        if self.config.lane_choice:
            current = route.lane_id_on(route.road_index, vehicle.position, None)
            n = len(route.lanes_of(route.road_index))
            options = {int(np.clip(current + d, 0, n - 1)) for d in (-1, 0, 1)}
            if self._previous is not None and self._previous.lane_id is not None:
                options.add(int(np.clip(self._previous.lane_id, 0, n - 1)))  # keep the committed lane
            lane_ids = sorted(options)
        behaviours = [_Behaviour(lane, speed) for lane in lane_ids for speed in self.config.speeds]
        if self.config.close_following is not None:
            top = max(self.config.speeds)
            behaviours += [_Behaviour(lane, top, gap=tuple(self.config.close_following)) for lane in lane_ids]
        if self.config.nudge_offset is not None and self.config.lane_choice:
            current = route.lane_id_on(route.road_index, vehicle.position, None)
            top = max(self.config.speeds)
            gap = None if self.config.close_following is None else tuple(self.config.close_following)
            behaviours += [_Behaviour(lane, top, gap=gap, nudge=True) for lane in lane_ids if lane != current]
        lanes = route.path_lanes(vehicle.position, None)
        if route.can_stop(vehicle, lanes):
            behaviours.append(_Behaviour(lane_ids[0] if len(lane_ids) == 1 else None, max(self.config.speeds), stop=True))
        behaviours.append(_Behaviour(None, 0.0))  # emergency braking
        return behaviours

    def decide(self, road: Any, vehicle: Any) -> _Behaviour:
        """Choose the behaviour with the best simulated outcome over the look-ahead horizon."""
        best, best_score = None, -math.inf
        for behaviour in self.candidates(vehicle):
            score = self.evaluate(road, vehicle, behaviour)
            if self._previous is not None and behaviour.key() == self._previous.key():
                score += 2.0  # hysteresis: avoid dithering between near-equivalent behaviours
            if score > best_score:
                best, best_score = behaviour, score
        return best

    def evaluate(self, road: Any, vehicle: Any, behaviour: _Behaviour) -> float:
        """Simulate a behaviour and score it: route progress, minus penalties for risk and lane changes."""
        sim_road, mapping = clone_road(road, vehicle.position, self.config.perception_radius)
        ego = mapping[id(vehicle)]
        route = self._route.copy()
        start = route.progress(ego)
        min_gap = math.inf
        failed_at = stuck_at = None
        for t in range(self.config.horizon):
            acceleration, steering = route.control(ego, sim_road.vehicles, behaviour)
            ego.act({"acceleration": acceleration, "steering": steering})
            sim_road.act()
            sim_road.step(self.dt)
            if not ego.crashed and self._episode_over(ego):
                break  # the scenario would end the episode here: nothing to lose beyond it
            if ego.crashed or not ego.on_road:
                failed_at = t
                break
            min_gap = min(min_gap, self._clearance(ego, sim_road))
            route.update(ego)
            if stuck_at is None and self._stuck_in_junction(ego, route):
                stuck_at = t
        if failed_at is not None:
            return -1e6 + 1e3 * failed_at + route.progress(ego) - start
        if stuck_at is not None:
            return -1e5 + 1e3 * stuck_at + route.progress(ego) - start
        score = route.progress(ego) - start
        if min_gap < self.config.safety_margin:
            score -= 200.0 * (self.config.safety_margin - min_gap) + 100.0
        score -= self._lane_penalty(ego, route, behaviour)
        score -= self._approach_penalty(ego, route)
        return score

    def _stuck_in_junction(self, ego: Any, route: _RouteFollower) -> bool:
        """Junction-clearance rule: the ego is slower than ``junction_min_speed`` in the crossing traffic's path.

        The junction is the route's road right after a stop line (a road of ``yield_roads``); the
        crossing traffic's path is any lane of a road off the route that does not start where the
        ego's junction road starts (those diverge from the same stop line: traffic on them follows
        the ego) and that the ego's outline overlaps.
        """
        min_speed = self.config.junction_min_speed
        k = route.road_index
        if min_speed is None or k == 0 or route.roads[k - 1] not in self.config.yield_roads:
            return False
        if float(ego.speed) >= min_speed:
            return False
        return any(
            _overlaps_lane(ego, lane) for lane in route.crossing_lanes(k)
        )

    def _episode_over(self, ego: Any) -> bool:
        """Whether the scenario ends the episode at the ego's (simulated) position (``episode_end_x``)."""
        end = self.config.episode_end_x
        return end is not None and float(ego.position[0]) > end

    def _approach_penalty(self, ego: Any, route: _RouteFollower) -> float:
        """Cost of the lane changes still needed to reach the approach lane of a narrower road ahead."""
        if not self.config.approach_lane_cost or ego.lane_index[:2] != route.roads[route.road_index]:
            return 0.0
        target = route.approach_lane(route.road_index, window=len(route.roads))
        if target is None:
            return 0.0
        return self.config.approach_lane_cost * abs(ego.lane_index[2] - target)

    def _clearance(self, ego: Any, road: Any) -> float:
        """Approximate free distance between the ego and the nearest vehicle (outline to outline)."""
        best = math.inf
        direction = ego.direction
        normal = np.array([-direction[1], direction[0]])
        for other in road.vehicles:
            if other is ego:
                continue
            delta = other.position - ego.position
            if np.abs(delta).max() > 20:
                continue
            longitudinal = abs(float(delta @ direction)) - ego.LENGTH
            lateral = abs(float(delta @ normal)) - ego.WIDTH
            if lateral < 0.3:  # overlapping laterally: longitudinal clearance matters
                best = min(best, longitudinal)
            elif longitudinal < 0:  # side by side
                best = min(best, lateral + self.config.safety_margin - 0.3)
        return best

    def _lane_penalty(self, ego: Any, route: _RouteFollower, behaviour: _Behaviour) -> float:
        penalty = 0.0
        if behaviour.lane_id is not None:
            current = route.lane_id_on(route.road_index, ego.position, None)
            penalty += 1.0 * abs(behaviour.lane_id - current)
        preferred = self.config.preferred_lane
        finish = self.finish_position
        if preferred is not None and finish is not None and behaviour.lane_id is not None:
            remaining = finish[0] - ego.position[0]
            if remaining < 250:
                penalty += 5.0 * abs(behaviour.lane_id - preferred)
        return penalty


def _robotics_experts() -> dict[str, Any]:
    from torchrl_csirl.envs.locomotion import LocomotionExpert, expert_policy_path
    from torchrl_csirl.envs.robotics.ant_goal import WaypointAntExpert
    from torchrl_csirl.envs.robotics.expert import DAPGRelocateExpert

    experts: dict[str, Any] = {"antmaze-umaze": WaypointAntExpert, "relocate": DAPGRelocateExpert}
    for name in LOCOMOTION_TASKS:  # once their SAC expert is shipped
        if os.path.isfile(expert_policy_path(name)):
            experts[name] = partial(LocomotionExpert, name)
    return experts


def expert_tasks() -> tuple[str, ...]:
    """The tasks with an expert: the four driving scenarios, AntMaze (the waypoint-driven ant),
    Relocate (the DAPG policy) and the locomotion tasks whose SAC expert is shipped.

    Examples:
        >>> expert_tasks()[4:6], "halfcheetah" in expert_tasks()
        (('antmaze-umaze', 'relocate'), True)
    """
    return (*EXPERT_CONFIGS, *_robotics_experts())


def make_expert(name: str, **overrides: Any) -> Any:
    """Build the expert of a task: the driver of a driving scenario (optionally overriding
    fields of its :class:`ExpertConfig`) or a robotics task's policy (``"relocate"``: the DAPG
    expert, :class:`~torchrl_csirl.envs.robotics.expert.DAPGRelocateExpert`; ``"antmaze-umaze"``:
    :class:`~torchrl_csirl.envs.robotics.WaypointAntExpert` driving the shipped goal-reaching ant, or
    ``policy=<policy.pt or run directory of recipes/train_ant_expert.py>``, and its ``lookahead=``
    and ``action_gain=``; ``"hopper"``, ``"halfcheetah"``: the shipped SAC policy,
    :class:`~torchrl_csirl.envs.locomotion.LocomotionExpert`, or ``policy=``).

    Every expert has ``reset(env)`` and ``act(env) -> action``.

    Examples:
        >>> expert = make_expert("roundabout", horizon=10)
        >>> expert.config.horizon
        10
        >>> type(make_expert("relocate")).__name__
        'DAPGRelocateExpert'
    """
    robotics = _robotics_experts()
    if name == "antmaze-umaze":
        unknown = sorted(set(overrides) - {"policy", "lookahead", "action_gain"})
        if unknown:
            raise ValueError(
                "The 'antmaze-umaze' expert takes only policy=<policy.pt or run directory>, lookahead= and "
                f"action_gain=, got {unknown}."
            )
        policy = overrides.pop("policy", None)
        return robotics[name](policy, **overrides)
    if name in LOCOMOTION_TASKS and (name in robotics or "policy" in overrides):
        from torchrl_csirl.envs.locomotion import LocomotionExpert

        unknown = sorted(set(overrides) - {"policy"})
        if unknown:
            raise ValueError(f"The {name!r} expert takes only policy=<policy.pt or run directory>, got {unknown}.")
        return LocomotionExpert(name, overrides.get("policy"))
    if name in robotics:
        if overrides:
            raise ValueError(f"The {name!r} expert takes no options, got {sorted(overrides)}.")
        return robotics[name]()
    if name not in EXPERT_CONFIGS:
        raise ValueError(f"Unknown scenario {name!r}; expected one of {sorted(expert_tasks())}.")
    config = dataclasses.replace(EXPERT_CONFIGS[name], **overrides) if overrides else None
    return ExpertDriver(name, config=config)


def clear_traffic(env: Any) -> np.ndarray:
    """Remove every vehicle but the ego from a freshly reset scenario (the empty-road curriculum).

    Also stops the intersection from spawning new vehicles. Returns the recomputed observation.
    """
    base = env.unwrapped
    base.road.vehicles = [v for v in base.road.vehicles if v is base.vehicle]
    if "spawn_probability" in base.config:
        base.config["spawn_probability"] = 0.0
    return np.asarray(base.observation_type.observe(), dtype=np.float32).reshape(-1)


def rollout_expert(
    env: Any,
    seed: int | None = None,
    expert: Any | None = None,
    scenario: str | None = None,
    empty_road: bool = False,
    max_steps: int | None = None,
    end_at_arrival: bool = False,
    action_noise: float = 0.0,
    record_expert_action: bool = False,
) -> dict[str, Any]:
    """Drive one episode with the expert and record it.

    Args:
        env: a gymnasium env of a CSIRL task (``make_gym_env(name)``, a driving scenario or a
            robotics task with an expert, see :func:`expert_tasks`).
        seed: reset seed.
        expert: the expert (default: ``make_expert`` of the env's task).
        scenario: task name, when it cannot be read from the env.
        empty_road: remove all other vehicles after the reset (see :func:`clear_traffic`;
            driving scenarios only).
        max_steps: optional cap on the number of steps (default: until terminated/truncated).
        end_at_arrival: end the episode at the first step where the ego has arrived
            (``info["arrived"]``), marking that transition ``truncated`` (unless the env itself
            terminates there). Used when recording demonstrations: highway-fast and roundabout do
            not terminate on arrival, and the states recorded after it (driving on past the
            finish, x clipped at the edge of the observation range) carry no information.
        action_noise: standard deviation of Gaussian noise added to each expert action before it
            is executed, clipped to the action space; the noisy (executed) action is recorded, as
            in D4RL's AntMaze datasets (0.2 there). Drawn from a generator seeded by ``seed``, so an
            episode is reproducible. Defaults to ``0.0`` (the clean expert).
        record_expert_action: with ``action_noise``, record the expert's own (noise-free) action
            instead of the executed one: the states of a perturbed expert labelled with what the
            expert would do there (DART, Laskey et al. 2017). Defaults to ``False``.

    Returns:
        a dict with the episode in the layout of
        :meth:`torchrl_csirl.data.ExpertDemonstrations.from_episodes` (``observation`` and
        ``next_observation`` ``[T, D]``, ``action`` ``[T, A]``, ``reward``, ``terminated``,
        ``truncated`` ``[T]``) and its statistics: ``success`` (the env's ``info["success"]``: finish
        area reached without crash; Relocate: the ball at the target at some step),
        ``success_steps`` (steps with ``info["success"]``), ``crashed``, ``offroad``,
        ``accomplish_rate`` (``clip((d0 - d_min) / d0, 0, 1)``), ``distances`` (``d_0..d_T``),
        ``return`` (sum of rewards), ``length``, ``seed``.

    Examples:
        >>> from torchrl_csirl.envs import make_gym_env
        >>> episode = rollout_expert(make_gym_env("intersection"), seed=0)
        >>> episode["observation"].shape[1], episode["action"].shape[1]
        (35, 2)
    """
    from torchrl_csirl.envs.metrics import accomplish_rate

    scenario = scenario or _scenario_of(env)
    expert = expert or make_expert(scenario)
    if not action_noise >= 0:
        raise ValueError(f"action_noise must be >= 0, got {action_noise}.")
    perturb = _action_perturbation(env.action_space, action_noise, seed)
    if empty_road and scenario not in EXPERT_CONFIGS:
        raise ValueError(f"empty_road applies to the driving scenarios only, not {scenario!r}.")
    obs, info = env.reset(seed=seed)
    if empty_road:
        obs = clear_traffic(env)
    expert.reset(env)
    distances = [float(info["distance_to_finish"])]
    observations, actions, rewards, terminated, truncated = [np.asarray(obs, dtype=np.float32).ravel()], [], [], [], []
    crashed = offroad = success = False
    step = success_steps = 0
    while True:
        expert_action = expert.act(env)
        action = perturb(expert_action)
        obs, reward, term, trunc, info = env.step(action)
        step += 1
        observations.append(np.asarray(obs, dtype=np.float32).ravel())
        actions.append(expert_action if record_expert_action else action)
        rewards.append(float(reward))
        distances.append(float(info["distance_to_finish"]))
        crashed = crashed or bool(info.get("crashed", False))
        offroad = offroad or bool(info.get("offroad", False))
        success = success or bool(info.get("success", False))
        success_steps += int(bool(info.get("success", False)))
        if max_steps is not None and step >= max_steps:
            trunc = True
        if end_at_arrival and info.get("arrived", False):
            trunc = True
        terminated.append(bool(term))
        truncated.append(bool(trunc) and not bool(term))
        if term or trunc:
            break
    observations = np.stack(observations)
    return {
        "observation": observations[:-1],
        "next_observation": observations[1:],
        "action": np.stack(actions).astype(np.float32),
        "reward": np.asarray(rewards, dtype=np.float32),
        "terminated": np.asarray(terminated, dtype=bool),
        "truncated": np.asarray(truncated, dtype=bool),
        "distances": np.asarray(distances, dtype=np.float64),
        "length": step,
        "seed": seed,
        "scenario": scenario,
        "empty_road": bool(empty_road),
        "end_at_arrival": bool(end_at_arrival),
        "action_noise": float(action_noise),
        "recorded_action": "expert" if record_expert_action else "executed",
        "success": bool(success and not crashed and not offroad),
        "success_steps": success_steps,
        "return": float(np.sum(rewards)),
        "crashed": crashed,
        "offroad": offroad,
        "accomplish_rate": float(accomplish_rate(distances)),
    }


def _action_perturbation(action_space: Any, std: float, seed: int | None) -> Callable[[np.ndarray], np.ndarray]:
    """``a -> clip(a + N(0, std^2), low, high)`` with its own generator seeded by ``seed`` (identity for ``std == 0``)."""
    if std == 0:
        return lambda action: action
    generator = np.random.default_rng(None if seed is None else [seed, 0x5EED])

    def perturb(action: np.ndarray) -> np.ndarray:
        noisy = np.asarray(action) + generator.normal(0.0, std, np.shape(action))
        return np.clip(noisy, action_space.low, action_space.high).astype(np.asarray(action).dtype)

    return perturb


def _scenario_of(env: Any) -> str:
    spec = getattr(env, "spec", None)
    gym_id = getattr(spec, "id", "") or ""
    for name in expert_tasks():
        if gym_id == f"csirl/{name}-v0":
            return name
    raise ValueError(f"Cannot infer the scenario of env {gym_id!r}; pass scenario=...")
