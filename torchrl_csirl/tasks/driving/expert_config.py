"""The expert driver's per-scene settings (:class:`ExpertConfig`, :data:`EXPERT_CONFIGS`) and its action units.

The driver (:class:`~torchrl_csirl.tasks.driving.expert_driver.ExpertDriver`) commands physical acceleration
[m/s^2] and steering [rad]; :func:`normalize_action` turns them into the learner's normalised action
``[acceleration / 15, steering / (pi / 2)]`` clipped to ``[-1, 1]``.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

__all__ = ["ACCELERATION_SCALE", "EXPERT_CONFIGS", "STEERING_SCALE", "ExpertConfig", "normalize_action"]

ACCELERATION_SCALE = 15.0
"""Physical acceleration [m/s^2] of a normalised action of 1."""
STEERING_SCALE = math.pi / 2
"""Physical steering angle [rad] of a normalised action of 1."""

@dataclasses.dataclass(frozen=True)
class ExpertConfig:
    """Per-scenario settings of :class:`~torchrl_csirl.tasks.driving.expert_driver.ExpertDriver`.

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
            :meth:`~torchrl_csirl.tasks.driving.route_follower.RouteFollower.nudge_control`), so that two slow
            vehicles side by side do not block both lanes. The nudge candidates follow with the
            ``close_following`` gap (at the highest target speed), which must be short enough for the
            ego to get ahead of the centre of the vehicle beside it.
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

