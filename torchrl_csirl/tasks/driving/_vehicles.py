"""Vehicle classes used by the CSIRL driving scenarios.

Two concerns live here:

* **Isolation.** highway-env's intersection scene writes IDM constants onto the class
  named by ``config["other_vehicles_type"]`` (``vehicle_type.DISTANCE_WANTED = 7``). With
  the stock :class:`~highway_env.vehicle.behavior.IDMVehicle` that silently changes every
  other scene created later in the same process. Our scenarios therefore use subclasses with
  the upstream constants pinned, one per scene family, so no scenario leaks into another.
* **Speed.** ``Vehicle.predict_trajectory_constant_speed`` (called for the ego in every pair
  check of the intersection's traffic regulation) deep-copies the vehicle, and with it the
  whole road (network, every vehicle, the random generator). :class:`FastVehicle` integrates
  the same equations on plain floats instead: the predicted positions and headings are
  bit-for-bit identical to upstream's (same numpy operations in the same order), without the
  copy. (IDM vehicles already predict along their route without copying.)
"""
from __future__ import annotations

import numpy as np
from highway_env.vehicle.behavior import IDMVehicle
from highway_env.vehicle.kinematics import Vehicle

__all__ = [
    "FastVehicle",
    "IntersectionIDMVehicle",
    "ScenarioIDMVehicle",
    "predict_constant_speed",
]


def predict_constant_speed(
    vehicle: Vehicle, times: np.ndarray
) -> tuple[list[np.ndarray], list[float]]:
    """Constant-action trajectory prediction without copying the vehicle (and its road).

    Reproduces ``Vehicle.predict_trajectory_constant_speed`` (deep copy, ``act`` with zero
    acceleration and the current or zero steering, repeated ``step``) operation by operation
    on local variables: crash handling, action clipping, speed bounds, the pending collision
    impulse and the kinematic bicycle update. (Controlled/IDM vehicles have their own,
    route-based and copy-free, prediction upstream; this is for plain :class:`Vehicle`.)

    Args:
        vehicle: a plain kinematic vehicle (left untouched).
        times: increasing prediction times [s].

    Returns:
        the predicted positions (arrays of shape (2,)) and headings.

    Examples:
        >>> import numpy as np
        >>> from highway_env.vehicle.kinematics import Vehicle
        >>> v = Vehicle(None, [0.0, 0.0], heading=0.0, speed=10.0)
        >>> positions, headings = predict_constant_speed(v, np.array([0.5, 1.0]))
        >>> positions[-1].tolist(), float(headings[-1])
        ([10.0, 0.0], 0.0)
    """
    if vehicle.prediction_type == "zero_steering":
        steering = 0.0
    elif vehicle.prediction_type == "constant_steering":
        steering = vehicle.action["steering"]
    else:
        raise ValueError("Unknown predition type")
    acceleration = 0.0
    dt = np.diff(np.concatenate(([0.0], times)))
    position = vehicle.position.copy()
    heading = vehicle.heading
    speed = vehicle.speed
    crashed = vehicle.crashed
    impact = vehicle.impact
    if impact is not None:
        impact = impact.copy()
    max_speed, min_speed, length = vehicle.MAX_SPEED, vehicle.MIN_SPEED, vehicle.LENGTH
    positions: list[np.ndarray] = []
    headings: list[float] = []
    for t in dt:
        # clip_actions
        if crashed:
            steering = 0
            acceleration = -1.0 * speed
        steering = float(steering)
        acceleration = float(acceleration)
        if speed > max_speed:
            acceleration = min(acceleration, 1.0 * (max_speed - speed))
        elif speed < min_speed:
            acceleration = max(acceleration, 1.0 * (min_speed - speed))
        # step
        beta = np.arctan(1 / 2 * np.tan(steering))
        v = speed * np.array([np.cos(heading + beta), np.sin(heading + beta)])
        position += v * t
        if impact is not None:
            position += impact
            crashed = True
            impact = None
        heading += speed * np.sin(beta) / (length / 2) * t
        speed += acceleration * t
        positions.append(position.copy())
        headings.append(heading)
    return positions, headings


class FastVehicle(Vehicle):
    """Ego vehicle (kinematic bicycle model) whose trajectory prediction does not copy the road."""

    def predict_trajectory_constant_speed(
        self, times: np.ndarray
    ) -> tuple[list[np.ndarray], list[float]]:
        return predict_constant_speed(self, times)


class ScenarioIDMVehicle(IDMVehicle):
    """Upstream IDM vehicle with its IDM constants pinned (immune to other scenes' class edits)."""

    COMFORT_ACC_MAX = 3.0
    COMFORT_ACC_MIN = -5.0
    DISTANCE_WANTED = 5.0 + IDMVehicle.LENGTH


class IntersectionIDMVehicle(ScenarioIDMVehicle):
    """IDM vehicle for the intersection (upstream sets these constants on the class at reset)."""

    COMFORT_ACC_MAX = 6
    COMFORT_ACC_MIN = -3
    DISTANCE_WANTED = 7
