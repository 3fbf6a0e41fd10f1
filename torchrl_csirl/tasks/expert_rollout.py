"""Driving one episode with a task's expert and recording it: :func:`rollout_expert`, and the empty-road
curriculum's :func:`clear_traffic`.
"""
from __future__ import annotations

from typing import Any, Callable

import numpy as np

from torchrl_csirl.tasks.catalog import TASKS, resolve_scenario
from torchrl_csirl.tasks.experts import expert_tasks, make_expert
from torchrl_csirl.tasks.metrics import accomplish_rate

__all__ = ["clear_traffic", "rollout_expert"]


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
            robotics task with an expert, see
            :func:`~torchrl_csirl.tasks.experts.expert_tasks`).
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
        >>> from torchrl_csirl.tasks import make_gym_env
        >>> episode = rollout_expert(make_gym_env("intersection"), seed=0)
        >>> episode["observation"].shape[1], episode["action"].shape[1]
        (35, 2)
    """
    scenario = scenario or _scenario_of(env)
    expert = expert or make_expert(scenario)
    if not action_noise >= 0:
        raise ValueError(f"action_noise must be >= 0, got {action_noise}.")
    perturb = _action_perturbation(env.action_space, action_noise, seed)
    if empty_road and resolve_scenario(scenario).family != "driving":
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
        if gym_id and gym_id == TASKS[name].gym_id:
            return name
    raise ValueError(f"Cannot infer the scenario of env {gym_id!r}; pass scenario=...")
