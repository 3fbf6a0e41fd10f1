"""The four CSIRL driving scenes as highway-env subclasses.

Every scene shares :class:`CSIRLDrivingMixin`:

* continuous ``[acceleration, steering]`` actions in ``[-1, 1]`` (scaled by the action config),
* a flattened Kinematics observation (``fast=True`` uses the pandas-free
  :class:`~torchrl_csirl.tasks.driving._observation.FastKinematicObservation`, identical output),
* termination on crash, off-road and arrival at the finish (``arrival_terminal``, plus
  scene-specific conditions), truncation at ``max_steps`` policy steps,
* ``info`` entries ``distance_to_finish``, ``progress``, ``crashed``, ``offroad``, ``arrived``,
  ``success``.

The upstream bugs handled here (without touching the installed package): merge-v0 and
roundabout-v0 evaluate ``action in [0, 2]`` in their reward, which raises on continuous
(array) actions; merge never truncates; intersection counts any exit as arrival.
"""
from __future__ import annotations

import numpy as np
from gymnasium import spaces
from highway_env import utils
from highway_env.envs.common.action import ContinuousAction
from highway_env.envs.highway_env import HighwayEnvFast
from highway_env.envs.intersection_env import IntersectionEnv
from highway_env.envs.merge_env import MergeEnv
from highway_env.envs.roundabout_env import RoundaboutEnv
from highway_env.road.lane import AbstractLane, CircularLane, LineType, SineLane, StraightLane
from highway_env.road.regulation import RegulatedRoad
from highway_env.road.road import Road, RoadNetwork
from highway_env.utils import near_split
from highway_env.vehicle.controller import ControlledVehicle, MDPVehicle
from highway_env.vehicle.kinematics import Vehicle

from torchrl_csirl.tasks.driving._observation import FastKinematicObservation
from torchrl_csirl.tasks.driving._road import CachedRegulatedRoad, CachedRoad
from torchrl_csirl.tasks.driving._vehicles import FastVehicle, IntersectionIDMVehicle, ScenarioIDMVehicle

__all__ = [
    "CSIRLDrivingMixin",
    "CSIRLHighwayEnv",
    "CSIRLIntersectionEnv",
    "CSIRLMergeEnv",
    "CSIRLRoundaboutEnv",
]

_VEHICLE_PATH = "torchrl_csirl.tasks.driving._vehicles."
_UPSTREAM_IDM = "highway_env.vehicle.behavior.IDMVehicle"

POSITION_VELOCITY = ["presence", "x", "y", "vx", "vy"]
WITH_HEADING = POSITION_VELOCITY + ["cos_h", "sin_h"]


def kinematics_config(features: list[str], features_range: dict[str, list[float]]) -> dict:
    """Full Kinematics observation config (ego + 4 vehicles, absolute, normalised, clipped)."""
    return {
        "type": "Kinematics",
        "vehicles_count": 5,
        "features": list(features),
        "features_range": {k: list(v) for k, v in features_range.items()},
        "absolute": True,
        "normalize": True,
        "clip": True,
        "see_behind": False,
        "observe_intentions": False,
        "include_obstacles": False,
        "order": "sorted",
    }


class _EgoContinuousAction(ContinuousAction):
    """``ContinuousAction`` whose ego vehicle class is chosen by the scenario."""

    def __init__(self, env, ego_class: type = Vehicle, **kwargs) -> None:
        super().__init__(env, **kwargs)
        self._ego_class = ego_class

    @property
    def vehicle_class(self):
        return self._ego_class


class CSIRLDrivingMixin:
    """Behaviour shared by the CSIRL scenes (put first in the bases, before the upstream env)."""

    def _rewards(self, action) -> dict[str, float]:
        # upstream merge/roundabout score lane changes with ``action in [0, 2]`` (discrete
        # meta-actions), which raises for a continuous action: score it as IDLE (no lane change)
        return super()._rewards(_IDLE if _is_array(action) else action)

    #: class of the other vehicles (IDM with pinned constants, see ``_vehicles``)
    _OTHER_VEHICLES: type = ScenarioIDMVehicle

    @classmethod
    def default_config(cls) -> dict:
        config = super().default_config()
        config.update(
            {
                "action": {
                    "type": "ContinuousAction",
                    "acceleration_range": [-15.0, 15.0],
                    "steering_range": [-np.pi / 2, np.pi / 2],
                    "longitudinal": True,
                    "lateral": True,
                    "dynamical": False,
                    "clip": True,
                },
                "simulation_frequency": 5,
                "policy_frequency": 5,
                "max_steps": 100,
                "finish_position": [0.0, 0.0],
                "offroad_terminal": True,
                # the task ends at the finish in every scene (stock highway-fast and roundabout
                # drive on): docs/scenarios.md, "Episodes end at the finish"
                "arrival_terminal": True,
                "fast": True,
            }
        )
        return config

    # ------------------------------------------------------------------ spaces
    def define_spaces(self) -> None:
        fast = self.config.get("fast", True)
        if self.config["other_vehicles_type"] == _UPSTREAM_IDM:
            self.config["other_vehicles_type"] = _VEHICLE_PATH + self._OTHER_VEHICLES.__name__
        super().define_spaces()
        obs_config = dict(self.config["observation"])
        if obs_config.get("type") == "Kinematics" and fast:
            self.observation_type = FastKinematicObservation(self, **obs_config)
        act_config = dict(self.config["action"])
        if act_config.get("type") == "ContinuousAction" and not act_config.get("dynamical", False):
            act_config.pop("type")
            self.action_type = _EgoContinuousAction(
                self, ego_class=FastVehicle if fast else Vehicle, **act_config
            )
            self.action_space = self.action_type.space()
        shape = self.observation_type.space().shape
        bound = 1.0 if obs_config.get("clip", True) and obs_config.get("normalize", True) else np.inf
        self.observation_space = spaces.Box(
            -bound, bound, shape=(int(np.prod(shape)),), dtype=np.float32
        )

    # ------------------------------------------------------------------ episode
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        self._policy_steps = 0
        self._initial_distance = None
        obs, info = super().reset(seed=seed, options=options)
        return np.asarray(obs, dtype=np.float32).reshape(-1), info

    def step(self, action):
        self._policy_steps += 1
        obs, reward, terminated, truncated, info = super().step(action)
        return (
            np.asarray(obs, dtype=np.float32).reshape(-1),
            float(reward),
            bool(terminated),
            bool(truncated) and not bool(terminated),
            info,
        )

    # ------------------------------------------------------------------ route
    @property
    def finish_position(self) -> np.ndarray:
        return np.asarray(self.config["finish_position"], dtype=np.float64)

    def distance_to_finish(self) -> float:
        """Euclidean distance [m] of the ego vehicle to the finish position."""
        return float(np.linalg.norm(self.vehicle.position - self.finish_position))

    def has_arrived_at_finish(self) -> bool:
        """Whether the ego vehicle reached the finish area (scene specific)."""
        raise NotImplementedError

    def is_offroad(self) -> bool:
        return not self.vehicle.on_road

    def _configure_other_vehicle_collisions(self, vehicle: Vehicle) -> None:
        """Disable collision checks of a non-ego vehicle unless ``other_vehicles_collide``.

        As highway-fast-v0 does for its traffic: a vehicle that does not check collisions still
        collides with the ego (which does), but not with other non-ego vehicles.
        """
        if not self.config.get("other_vehicles_collide", True):
            vehicle.check_collisions = False

    def _scene_terminated(self) -> bool:
        """Scene-specific termination besides crash and off-road."""
        return False

    def _is_terminated(self) -> bool:
        return bool(
            self.vehicle.crashed
            or (self.config["offroad_terminal"] and self.is_offroad())
            or (self.config["arrival_terminal"] and self.has_arrived_at_finish())
            or self._scene_terminated()
        )

    def _is_truncated(self) -> bool:
        return getattr(self, "_policy_steps", 0) >= self.config["max_steps"]

    def _info(self, obs, action=None) -> dict:
        info = super()._info(obs, action)
        distance = self.distance_to_finish()
        if getattr(self, "_initial_distance", None) is None:
            self._initial_distance = distance
        d0 = self._initial_distance
        progress = float(np.clip((d0 - distance) / d0, 0.0, 1.0)) if d0 > 0 else 1.0
        arrived = bool(self.has_arrived_at_finish())
        crashed = bool(self.vehicle.crashed)
        info.update(
            {
                "distance_to_finish": distance,
                "progress": progress,
                "crashed": crashed,
                "offroad": bool(self.is_offroad()),
                "arrived": arrived,
                "success": arrived and not crashed,
            }
        )
        return info


# ---------------------------------------------------------------------- highway
class CSIRLHighwayEnv(CSIRLDrivingMixin, HighwayEnvFast):
    """highway-fast with a fast ego (35 m/s) among slower traffic (speed limit 25 m/s)."""

    @classmethod
    def default_config(cls) -> dict:
        config = super().default_config()
        config.update(
            {
                "observation": kinematics_config(
                    POSITION_VELOCITY,
                    {"x": [150, 700], "y": [-12, 12], "vx": [-80, 80], "vy": [-80, 80]},
                ),
                "max_steps": 150,
                "finish_position": [650.0, 8.0],
                "lanes_count": 3,
                "vehicles_count": 20,
                "vehicles_density": 1,
                "ego_speed": 35.0,
                "speed_limit": 25.0,
            }
        )
        return config

    def _create_road(self) -> None:
        road_class = CachedRoad if self.config.get("fast", True) else Road
        self.road = road_class(
            network=RoadNetwork.straight_road_network(
                self.config["lanes_count"], speed_limit=self.config["speed_limit"]
            ),
            np_random=self.np_random,
            record_history=self.config["show_trajectories"],
            neighbour_vehicles_connected_lanes=self.config["neighbour_vehicles_connected_lanes"],
        )

    def _create_vehicles(self) -> None:
        # upstream HighwayEnv._create_vehicles with a configurable ego speed
        other_vehicles_type = utils.class_from_path(self.config["other_vehicles_type"])
        other_per_controlled = near_split(
            self.config["vehicles_count"], num_bins=self.config["controlled_vehicles"]
        )
        self.controlled_vehicles = []
        for others in other_per_controlled:
            vehicle = Vehicle.create_random(
                self.road,
                speed=self.config["ego_speed"],
                lane_id=self.config["initial_lane_id"],
                spacing=self.config["ego_spacing"],
            )
            vehicle = self.action_type.vehicle_class(
                self.road, vehicle.position, vehicle.heading, vehicle.speed
            )
            self.controlled_vehicles.append(vehicle)
            self.road.vehicles.append(vehicle)
            for _ in range(others):
                vehicle = other_vehicles_type.create_random(
                    self.road, spacing=1 / self.config["vehicles_density"]
                )
                vehicle.randomize_behavior()
                self.road.vehicles.append(vehicle)
        # HighwayEnvFast: only the ego checks collisions
        for vehicle in self.road.vehicles:
            if vehicle not in self.controlled_vehicles:
                vehicle.check_collisions = False

    def has_arrived_at_finish(self) -> bool:
        return bool(self.vehicle.position[0] >= self.finish_position[0])


# ---------------------------------------------------------------------- merge
class CSIRLMergeEnv(CSIRLDrivingMixin, MergeEnv):
    """Stock merge scene; ends when the ego passes x = ``merge_end_x`` (370 m)."""

    @classmethod
    def default_config(cls) -> dict:
        config = super().default_config()
        config.update(
            {
                "observation": kinematics_config(
                    POSITION_VELOCITY,
                    {"x": [-500, 500], "y": [-8, 8], "vx": [-80, 80], "vy": [-80, 80]},
                ),
                "max_steps": 60,
                "finish_position": [400.0, 4.0],
                "merge_end_x": 370.0,
            }
        )
        return config

    def _make_road(self) -> None:
        super()._make_road()
        if self.config.get("fast", True):
            self.road.__class__ = CachedRoad  # same state, cached neighbour search

    def _scene_terminated(self) -> bool:  # the scene's own end, also with arrival_terminal=False
        return self.has_arrived_at_finish()

    def has_arrived_at_finish(self) -> bool:
        return bool(self.vehicle.position[0] > self.config["merge_end_x"])


# ---------------------------------------------------------------------- roundabout
class CSIRLRoundaboutEnv(CSIRLDrivingMixin, RoundaboutEnv):
    """Four-lane roundabout (radii 20/24/28/32 m); the ego goes straight to the north exit."""

    @classmethod
    def default_config(cls) -> dict:
        config = super().default_config()
        config.update(
            {
                "observation": kinematics_config(
                    WITH_HEADING,
                    {"x": [-100, 100], "y": [-100, 100], "vx": [-15, 15], "vy": [-15, 15]},
                ),
                "max_steps": 55,
                "finish_position": [2.0, -75.0],
                "ring_radius": 20.0,
                "ring_lanes": 4,
                "access_length": 110.0,
                "road_length": 170.0,
                "ego_position": [2.0, 70.0],
                "ego_speed": 8.0,
                "other_speed": 16.0,
                "finish_radius": 5.0,
                # stock: other vehicles collide with each other; False lets them pass through each
                # other as in highway-fast-v0 (measured: no gain for the expert, docs/scenarios.md)
                "other_vehicles_collide": True,
            }
        )
        return config

    def _make_road(self) -> None:
        center = [0, 0]
        alpha = 24  # [deg]
        n_lanes = int(self.config["ring_lanes"])
        radii = [self.config["ring_radius"] + 4 * i for i in range(n_lanes)]
        n, c, s = LineType.NONE, LineType.CONTINUOUS, LineType.STRIPED
        net = RoadNetwork()
        nodes = ["se", "ex", "ee", "nx", "ne", "wx", "we", "sx", "se"]
        angles = [
            (90 - alpha, alpha),
            (alpha, -alpha),
            (-alpha, -90 + alpha),
            (-90 + alpha, -90 - alpha),
            (-90 - alpha, -180 + alpha),
            (-180 + alpha, -180 - alpha),
            (180 - alpha, 90 + alpha),
            (90 + alpha, 90 - alpha),
        ]
        for lane in range(n_lanes):
            if n_lanes == 1:
                line = [c, c]
            elif lane == 0:
                line = [c, s]
            elif lane == n_lanes - 1:
                line = [n, c]
            else:
                line = [n, s]
            for i in range(8):
                net.add_lane(
                    nodes[i],
                    nodes[i + 1],
                    CircularLane(
                        center,
                        radii[lane],
                        np.deg2rad(angles[i][0]),
                        np.deg2rad(angles[i][1]),
                        clockwise=False,
                        line_types=line,
                    ),
                )
        # Access lanes: straight (r)oad then (s)ine junction, as upstream with a longer junction
        access = self.config["road_length"]
        dev = self.config["access_length"]
        a = 5.0
        delta_st = 0.2 * dev
        delta_en = dev - delta_st
        w = 2 * np.pi / dev
        for rot in range(4):  # south, east, north, west entries/exits
            names = ["s", "e", "n", "w"][rot]
            R = _rotation(rot)
            net.add_lane(
                names + "er",
                names + "es",
                StraightLane(R @ [2, access], R @ [2, dev / 2], line_types=(s, c)),
            )
            net.add_lane(
                names + "es",
                names + "e",
                SineLane(
                    R @ [2 + a, dev / 2],
                    R @ [2 + a, dev / 2 - delta_st],
                    a,
                    w,
                    -np.pi / 2,
                    line_types=(c, c),
                ),
            )
            net.add_lane(
                names + "x",
                names + "xs",
                SineLane(
                    R @ [-2 - a, -dev / 2 + delta_en],
                    R @ [-2 - a, dev / 2],
                    a,
                    w,
                    -np.pi / 2 + w * delta_en,
                    line_types=(c, c),
                ),
            )
            net.add_lane(
                names + "xs",
                names + "xr",
                StraightLane(R @ [-2, dev / 2], R @ [-2, access], line_types=(n, c)),
            )
        road_class = CachedRoad if self.config.get("fast", True) else Road
        self.road = road_class(
            network=net,
            np_random=self.np_random,
            record_history=self.config["show_trajectories"],
            neighbour_vehicles_connected_lanes=self.config["neighbour_vehicles_connected_lanes"],
        )

    def _make_vehicles(self) -> None:
        position_deviation = 2.0
        speed_deviation = 2.0
        n_lanes = int(self.config["ring_lanes"])
        ego_lane = self.road.network.get_lane(("ser", "ses", 0))
        longitudinal, _ = ego_lane.local_coordinates(np.asarray(self.config["ego_position"], float))
        ego = self.action_type.vehicle_class(
            self.road,
            ego_lane.position(longitudinal, 0.0),
            speed=self.config["ego_speed"],
            heading=ego_lane.heading_at(longitudinal),
        )
        self.road.vehicles.append(ego)
        self.vehicle = ego

        destinations = ["exr", "sxr", "nxr"]
        other_type = utils.class_from_path(self.config["other_vehicles_type"])
        speed = self.config["other_speed"]

        def add(lane_index, longitudinal_mean):
            vehicle = other_type.make_on_lane(
                self.road,
                lane_index,
                longitudinal=longitudinal_mean + self.np_random.normal() * position_deviation,
                speed=speed + self.np_random.normal() * speed_deviation,
            )
            return vehicle

        # incoming vehicle on the outer ring lane
        vehicle = add(("we", "sx", n_lanes - 1), 5.0)
        if self.config["incoming_vehicle_destination"] is not None:
            destination = destinations[self.config["incoming_vehicle_destination"]]
        else:
            destination = self.np_random.choice(destinations)
        vehicle.plan_route_to(destination)
        vehicle.randomize_behavior()
        self.road.vehicles.append(vehicle)
        # one vehicle per ring lane, alternately behind / ahead
        for lane in range(n_lanes):
            vehicle = add(("we", "sx", lane), 20.0 * (-1 if lane % 2 == 0 else 1))
            vehicle.plan_route_to(self.np_random.choice(destinations))
            vehicle.randomize_behavior()
            self.road.vehicles.append(vehicle)
        # entering vehicle from the east
        vehicle = add(("eer", "ees", 0), 50.0)
        vehicle.plan_route_to(self.np_random.choice(destinations))
        vehicle.randomize_behavior()
        self.road.vehicles.append(vehicle)
        for vehicle in self.road.vehicles:
            if vehicle is not ego:
                self._configure_other_vehicle_collisions(vehicle)

    def has_arrived_at_finish(self) -> bool:
        # reached (or passed) the finish on the north exit road
        lane_from, lane_to, _ = self.vehicle.lane_index
        on_exit = (lane_from, lane_to) in (("nx", "nxs"), ("nxs", "nxr"))
        close = self.distance_to_finish() <= self.config["finish_radius"]
        passed = on_exit and self.vehicle.position[1] <= self.finish_position[1]
        return bool(close or passed)


# ---------------------------------------------------------------------- intersection
class _FastRegulatedRoad(CachedRegulatedRoad):
    """``RegulatedRoad`` computing each vehicle's predicted trajectory once per regulation pass.

    Upstream predicts both vehicles of every pair (O(n^2) predictions, the ego's deep-copying the
    road each time). Predictions depend only on the vehicles' state, which a pass changes only
    when it makes a vehicle yield (target speed); the cache is emptied then, so the decisions
    are exactly upstream's. With :class:`~torchrl_csirl.tasks.driving._vehicles.FastVehicle` as ego the
    remaining predictions are copy-free.
    """

    def enforce_road_rules(self) -> None:
        for v in self.vehicles:
            if getattr(v, "is_yielding", False):
                if v.yield_timer >= self.YIELD_DURATION * self.REGULATION_FREQUENCY:
                    v.target_speed = v.lane.speed_limit
                    delattr(v, "color")
                    v.is_yielding = False
                else:
                    v.yield_timer += 1
        cache: dict[int, tuple] = {}
        vehicles = self.vehicles
        for i in range(len(vehicles) - 1):
            for j in range(i + 1, len(vehicles)):
                if self._conflict_possible(vehicles[i], vehicles[j], cache):
                    yielding = self.respect_priorities(vehicles[i], vehicles[j])
                    if (
                        yielding is not None
                        and isinstance(yielding, ControlledVehicle)
                        and not isinstance(yielding, MDPVehicle)
                    ):
                        yielding.color = self.YIELDING_COLOR
                        yielding.target_speed = 0
                        yielding.is_yielding = True
                        yielding.yield_timer = 0
                        cache.clear()

    _TIMES = np.arange(0.25, 3, 0.25)

    def _conflict_possible(self, v1, v2, cache: dict) -> bool:
        for v in (v1, v2):
            if id(v) not in cache:
                cache[id(v)] = v.predict_trajectory_constant_speed(self._TIMES)
        positions_1, headings_1 = cache[id(v1)]
        positions_2, headings_2 = cache[id(v2)]
        for position_1, heading_1, position_2, heading_2 in zip(
            positions_1, headings_1, positions_2, headings_2, strict=False
        ):
            if np.linalg.norm(position_2 - position_1) > v1.LENGTH:
                continue
            if utils.rotated_rectangles_intersect(
                (position_1, 1.5 * v1.LENGTH, 0.9 * v1.WIDTH, heading_1),
                (position_2, 1.5 * v2.LENGTH, 0.9 * v2.WIDTH, heading_2),
            ):
                return True
        return False


class CSIRLIntersectionEnv(CSIRLDrivingMixin, IntersectionEnv):
    """Four-way intersection with two lanes per approach; the ego turns left.

    Node names: ``o{k}{c}`` (outer end), ``ir{k}{c}`` (inner, incoming), ``il{k}{c}`` (inner,
    outgoing), with ``k`` = 1 for the lane next to the centre line (straight and left turns) and
    2 for the kerb lane (right turns), ``c`` the corner (0 south, 1 west, 2 north, 3 east).
    """

    _OTHER_VEHICLES = IntersectionIDMVehicle

    @classmethod
    def default_config(cls) -> dict:
        config = super().default_config()
        config.update(
            {
                "observation": kinematics_config(
                    WITH_HEADING,
                    {"x": [-100, 100], "y": [-100, 100], "vx": [-20, 20], "vy": [-20, 20]},
                ),
                "max_steps": 65,
                "finish_position": [-45.0, -2.0],
                "destination": "o11",
                "arrival_distance": 30.0,
                "initial_vehicle_count": 10,
                "spawn_probability": 0.6,
                "normalize_reward": True,
                # scene deviation (docs/scenarios.md): the other vehicles do not collide with each
                # other (as in highway-fast-v0); True restores stock highway-env behaviour
                "other_vehicles_collide": False,
            }
        )
        return config

    def _make_road(self) -> None:
        lane_width = AbstractLane.DEFAULT_WIDTH
        right_turn_radius = lane_width + 5
        left_turn_radius = right_turn_radius + 2 * lane_width
        outer_distance = right_turn_radius + lane_width / 2 + lane_width
        access_length = 100.0
        net = RoadNetwork()
        n, c, s = LineType.NONE, LineType.CONTINUOUS, LineType.STRIPED
        offsets = {1: lane_width / 2, 2: lane_width / 2 + lane_width}
        for corner in range(4):
            angle = np.radians(90 * corner)
            priority = 3 if corner % 2 else 1
            rotation = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
            left, right = (corner + 1) % 4, (corner - 1) % 4
            for k, lines_in, lines_out in ((1, [s, s], [n, s]), (2, [n, c], [n, c])):
                off = offsets[k]
                # incoming
                net.add_lane(
                    f"o{k}{corner}",
                    f"ir{k}{corner}",
                    StraightLane(
                        rotation @ np.array([off, access_length + outer_distance]),
                        rotation @ np.array([off, outer_distance]),
                        line_types=lines_in,
                        priority=priority,
                        speed_limit=10.0,
                    ),
                )
                # exit (towards the corner's right neighbour)
                net.add_lane(
                    f"il{k}{right}",
                    f"o{k}{right}",
                    StraightLane(
                        rotation @ np.flip([off, outer_distance], axis=0),
                        rotation @ np.flip([off, access_length + outer_distance], axis=0),
                        line_types=lines_out,
                        priority=priority,
                        speed_limit=10.0,
                    ),
                )
            # right turn from the kerb lane
            net.add_lane(
                f"ir2{corner}",
                f"il2{right}",
                CircularLane(
                    rotation @ np.array([outer_distance, outer_distance]),
                    right_turn_radius,
                    angle + np.radians(180),
                    angle + np.radians(270),
                    line_types=[n, c],
                    priority=priority,
                    speed_limit=10.0,
                ),
            )
            # left turn from the centre lane
            net.add_lane(
                f"ir1{corner}",
                f"il1{left}",
                CircularLane(
                    rotation
                    @ np.array(
                        [-left_turn_radius + lane_width / 2, left_turn_radius - lane_width / 2]
                    ),
                    left_turn_radius,
                    angle + np.radians(0),
                    angle + np.radians(-90),
                    clockwise=False,
                    line_types=[n, n],
                    priority=priority - 1,
                    speed_limit=10.0,
                ),
            )
            # straight from the centre lane
            net.add_lane(
                f"ir1{corner}",
                f"il1{(corner + 2) % 4}",
                StraightLane(
                    rotation @ np.array([lane_width / 2, outer_distance]),
                    rotation @ np.array([lane_width / 2, -outer_distance]),
                    line_types=[n, n],
                    priority=priority,
                    speed_limit=10.0,
                ),
            )
        road_class = _FastRegulatedRoad if self.config.get("fast", True) else RegulatedRoad
        self.road = road_class(
            network=net,
            np_random=self.np_random,
            record_history=self.config["show_trajectories"],
            neighbour_vehicles_connected_lanes=self.config["neighbour_vehicles_connected_lanes"],
        )

    def _make_vehicles(self, n_vehicles: int = 10) -> None:
        # upstream's version, minus its writes of IDM constants onto the vehicle class (our
        # IntersectionIDMVehicle carries them) and with the ego on the centre lane
        simulation_steps = 3
        for t in range(n_vehicles - 1):
            self._spawn_vehicle(np.linspace(0, 80, n_vehicles)[t])
        for _ in range(simulation_steps):
            for _ in range(self.config["simulation_frequency"]):
                self.road.act()
                self.road.step(1 / self.config["simulation_frequency"])
        # challenger going straight
        self._spawn_vehicle(
            60, spawn_probability=1.0, go_straight=True, position_deviation=0.1, speed_deviation=0.0
        )
        ego_lane = self.road.network.get_lane(("o10", "ir10", 0))
        ego = self.action_type.vehicle_class(
            self.road,
            ego_lane.position(60.0 + 5.0 * self.np_random.normal(1.0), 0.0),
            speed=ego_lane.speed_limit,
            heading=ego_lane.heading_at(60.0),
        )
        self.road.vehicles.append(ego)
        self.controlled_vehicles = [ego]
        for v in self.road.vehicles.copy():  # prevent early collisions
            if v is not ego and np.linalg.norm(v.position - ego.position) < 20:
                self.road.vehicles.remove(v)

    def _spawn_vehicle(
        self,
        longitudinal: float = 0,
        position_deviation: float = 1.0,
        speed_deviation: float = 1.0,
        spawn_probability: float = 0.6,
        go_straight: bool = False,
    ):
        if self.np_random.uniform() > spawn_probability:
            return None
        route = self.np_random.choice(range(4), size=2, replace=False)
        route[1] = (route[0] + 2) % 4 if go_straight else route[1]
        # right turns use the kerb lane, straight and left turns the centre lane
        k = 2 if route[1] == (route[0] - 1) % 4 else 1
        vehicle_type = utils.class_from_path(self.config["other_vehicles_type"])
        vehicle = vehicle_type.make_on_lane(
            self.road,
            (f"o{k}{route[0]}", f"ir{k}{route[0]}", 0),
            longitudinal=longitudinal + 5.0 + self.np_random.normal() * position_deviation,
            speed=8.0 + self.np_random.normal() * speed_deviation,
        )
        for v in self.road.vehicles:
            if np.linalg.norm(v.position - vehicle.position) < 15:
                return None
        vehicle.plan_route_to(f"o{k}{route[1]}")
        vehicle.randomize_behavior()
        self._configure_other_vehicle_collisions(vehicle)
        self.road.vehicles.append(vehicle)
        return vehicle

    def has_arrived(self, vehicle: Vehicle, exit_distance: float | None = None) -> bool:
        """Arrival on the *intended* destination lane (upstream accepts any exit)."""
        if exit_distance is None:
            exit_distance = self.config["arrival_distance"]
        lane_from, lane_to, _ = vehicle.lane_index
        destination = self.config["destination"]
        return (
            lane_to == destination
            and lane_from == "il" + destination[1:]
            and vehicle.lane.local_coordinates(vehicle.position)[0] >= exit_distance
        )

    def has_arrived_at_finish(self) -> bool:
        return self.has_arrived(self.vehicle)

    def _scene_terminated(self) -> bool:
        return self.has_arrived(self.vehicle)


#: highway-env's discrete meta-action index of IDLE (neither LANE_LEFT=0 nor LANE_RIGHT=2)
_IDLE = 1


def _is_array(action) -> bool:
    return isinstance(action, np.ndarray) or (
        isinstance(action, (list, tuple)) and len(action) > 1
    )


def _rotation(quarter_turns: int) -> np.ndarray:
    """Rotation taking the south access road to the east/north/west ones (screen y points down)."""
    # south (0, +y) -> east (+x, 0) -> north (0, -y) -> west (-x, 0)
    angle = -np.pi / 2 * quarter_turns
    c, s = np.round(np.cos(angle)), np.round(np.sin(angle))
    return np.array([[c, -s], [s, c]])
