"""The privileged expert driver of the CSIRL driving scenarios: :class:`ExpertDriver`.

The expert reads the simulator state (road network, ego vehicle, other vehicles) from ``env.unwrapped``
and returns continuous actions in the learner's normalised units
(:func:`~torchrl_csirl.tasks.driving.expert_config.normalize_action`). Every few steps it simulates a handful of
candidate behaviours (:class:`~torchrl_csirl.tasks.driving.route_follower.Behaviour`) on a light copy of the road
(:func:`~torchrl_csirl.tasks.driving.road_clone.clone_road`) and applies the one with the most route progress
that stays safe (see :mod:`torchrl_csirl.tasks.driving.expert`).
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from torchrl_csirl.tasks.catalog import SCENARIOS
from torchrl_csirl.tasks.driving.expert_config import EXPERT_CONFIGS, ExpertConfig, normalize_action
from torchrl_csirl.tasks.driving.road_clone import clone_road, perceived_vehicles
from torchrl_csirl.tasks.driving.route_follower import Behaviour, RouteFollower

__all__ = ["ExpertDriver", "make_expert_driver"]


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


class ExpertDriver:
    """Privileged expert driver for a CSIRL driving scenario.

    Args:
        scenario: a driving scenario (a key of :data:`~torchrl_csirl.tasks.driving.expert_config.EXPERT_CONFIGS`).
        config: optional :class:`ExpertConfig` overriding the scenario's defaults.
        dt: simulation step [s] (0.2 s in all CSIRL scenarios).

    Examples:
        >>> from torchrl_csirl.tasks import make_gym_env
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
        self.scenario = scenario
        self.config = config or EXPERT_CONFIGS[scenario]
        # one place for the finish: the scenario spec (used to rank behaviours near the end)
        self.finish_position = SCENARIOS[scenario].finish_position if scenario in SCENARIOS else None
        self.dt = dt
        self._route: RouteFollower | None = None
        self._previous: Behaviour | None = None
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
        self._route = RouteFollower(network, roads, self.config, self.dt)
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
    def candidates(self, vehicle: Any) -> list[Behaviour]:
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
        behaviours = [Behaviour(lane, speed) for lane in lane_ids for speed in self.config.speeds]
        if self.config.close_following is not None:
            top = max(self.config.speeds)
            behaviours += [Behaviour(lane, top, gap=tuple(self.config.close_following)) for lane in lane_ids]
        if self.config.nudge_offset is not None and self.config.lane_choice:
            current = route.lane_id_on(route.road_index, vehicle.position, None)
            top = max(self.config.speeds)
            gap = None if self.config.close_following is None else tuple(self.config.close_following)
            behaviours += [Behaviour(lane, top, gap=gap, nudge=True) for lane in lane_ids if lane != current]
        lanes = route.path_lanes(vehicle.position, None)
        if route.can_stop(vehicle, lanes):
            behaviours.append(Behaviour(lane_ids[0] if len(lane_ids) == 1 else None, max(self.config.speeds), stop=True))
        behaviours.append(Behaviour(None, 0.0))  # emergency braking
        return behaviours

    def decide(self, road: Any, vehicle: Any) -> Behaviour:
        """Choose the behaviour with the best simulated outcome over the look-ahead horizon."""
        best, best_score = None, -math.inf
        for behaviour in self.candidates(vehicle):
            score = self.evaluate(road, vehicle, behaviour)
            if self._previous is not None and behaviour.key() == self._previous.key():
                score += 2.0  # hysteresis: avoid dithering between near-equivalent behaviours
            if score > best_score:
                best, best_score = behaviour, score
        return best

    def evaluate(self, road: Any, vehicle: Any, behaviour: Behaviour) -> float:
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

    def _stuck_in_junction(self, ego: Any, route: RouteFollower) -> bool:
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

    def _approach_penalty(self, ego: Any, route: RouteFollower) -> float:
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

    def _lane_penalty(self, ego: Any, route: RouteFollower, behaviour: Behaviour) -> float:
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


def make_expert_driver(name: str, **overrides: Any) -> ExpertDriver:
    """The expert of a driving scenario (its :attr:`~torchrl_csirl.tasks.TaskSpec.expert`): an
    :class:`ExpertDriver` with fields of its :class:`~torchrl_csirl.tasks.driving.expert_config.ExpertConfig` overridden.

    Raises:
        ValueError: an unknown scenario, or an override that is no field of the config.

    Examples:
        >>> make_expert_driver("merge", horizon=7).config.horizon
        7
    """
    if name not in EXPERT_CONFIGS:
        raise ValueError(f"Unknown scenario {name!r}; expected one of {sorted(EXPERT_CONFIGS)}.")
    fields = {f.name for f in dataclasses.fields(ExpertConfig)}
    unknown = sorted(set(overrides) - fields)
    if unknown:
        raise ValueError(f"The {name!r} expert takes fields of ExpertConfig ({', '.join(sorted(fields))}), got {unknown}.")
    return ExpertDriver(name, config=dataclasses.replace(EXPERT_CONFIGS[name], **overrides) if overrides else None)
