"""The experts: the privileged expert driver of the CSIRL driving scenarios, and every task's expert by name.

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


Where the pieces live (this module gathers their public names):

* :mod:`~torchrl_csirl.tasks.driving.expert_config`: :class:`ExpertConfig`, the per-scene :data:`EXPERT_CONFIGS`,
  the action units (:func:`normalize_action`);
* :mod:`~torchrl_csirl.tasks.driving.road_clone`: the light road copies of the look-ahead;
* :mod:`~torchrl_csirl.tasks.driving.route_follower`: the route, its geometry and the IDM + steering controllers;
* :mod:`~torchrl_csirl.tasks.driving.expert_driver`: :class:`ExpertDriver`, the decision;
* :mod:`~torchrl_csirl.tasks.experts`: every task's expert by name (:func:`make_expert`,
  :func:`expert_tasks`), read from its spec's ``expert``;
* :mod:`~torchrl_csirl.tasks.expert_rollout`: :func:`rollout_expert`, :func:`clear_traffic`.

Examples:
    >>> from torchrl_csirl.tasks.driving.expert import make_expert, rollout_expert
    >>> from torchrl_csirl.tasks import make_gym_env
    >>> env = make_gym_env("merge")
    >>> episode = rollout_expert(env, seed=0, empty_road=True)
    >>> bool(episode["success"]), episode["action"].shape[1]
    (True, 2)
"""
from __future__ import annotations

from torchrl_csirl.tasks.driving.expert_config import (
    ACCELERATION_SCALE,
    EXPERT_CONFIGS,
    STEERING_SCALE,
    ExpertConfig,
    normalize_action,
)
from torchrl_csirl.tasks.driving.expert_driver import ExpertDriver, make_expert_driver
from torchrl_csirl.tasks.driving.road_clone import clone_road, fast_network, perceived_vehicles
from torchrl_csirl.tasks.expert_rollout import clear_traffic, rollout_expert
from torchrl_csirl.tasks.experts import expert_tasks, make_expert

__all__ = [
    "ACCELERATION_SCALE",
    "STEERING_SCALE",
    "ExpertConfig",
    "ExpertDriver",
    "EXPERT_CONFIGS",
    "clear_traffic",
    "clone_road",
    "expert_tasks",
    "fast_network",
    "make_expert",
    "make_expert_driver",
    "normalize_action",
    "perceived_vehicles",
    "rollout_expert",
]
