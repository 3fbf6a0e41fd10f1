"""Any gymnasium environment with flat ``Box`` spaces as a CSIRL task, without code.

:func:`make_gymnasium_task` reads the environment's spaces and episode limit, writes a
:class:`~torchrl_csirl.envs.TaskSpec` and registers it (:func:`~torchrl_csirl.envs.register_task`)
under the gymnasium id, with :func:`make_gymnasium_env` as its factory
(:mod:`torchrl_csirl.envs.gymnasium_env`, also importable from here). The environment seen by
the learner:

* actions in ``[-1, 1]``, rescaled to the environment's bounds (gymnasium's ``RescaleAction``);
* float32 observations, as the environment gives them (a policy sees nothing more);
* ``"success"`` (evaluation's flag): a termination that is not a truncation
  (``success="termination"``), an info entry the configuration names (``success="<key>"``), or
  never (``success="none"``, e.g. a task without a goal: compare returns).

Such a task has no finish position: its accomplish rate is its success rate, and the return is
reported beside it (docs/own-task.md).
"""
from __future__ import annotations

from functools import partial

import gymnasium as gym

from torchrl_csirl.envs.gymnasium_env import SUCCESS_RULES, GymnasiumTaskWrapper, check_flat_box_spaces, make_gymnasium_env
from torchrl_csirl.envs.registry import register_task
from torchrl_csirl.envs.scenarios import TASKS
from torchrl_csirl.envs.spec import TaskSpec

__all__ = ["GymnasiumTaskWrapper", "make_gymnasium_env", "make_gymnasium_task", "parse_feature_indices"]


def parse_feature_indices(features: str | None, obs_dim: int, spec: TaskSpec | None = None,
                          key: str = "env.features") -> tuple[int, ...]:
    """Observation indices from ``"0,2"`` (indices) or names of the spec's layout (``None``: all).

    Raises:
        ValueError: one line naming the entry that is not an index in ``[0, obs_dim)`` or a name.

    Examples:
        >>> parse_feature_indices("0", 2), parse_feature_indices(None, 3)
        ((0,), (0, 1, 2))
        >>> parse_feature_indices("5", 2)
        Traceback (most recent call last):
        ...
        ValueError: env.features=5: index 5 is outside the observation (size 2: indices 0-1)
    """
    if features is None or str(features).strip() in ("", "all"):
        return tuple(range(obs_dim))
    names = {spec.feature_name(i): i for i in range(obs_dim)} if spec is not None else {}
    indices = []
    for item in (part.strip() for part in str(features).split(",")):
        if item.lstrip("-").isdigit():
            index = int(item)
            if not 0 <= index < obs_dim:
                raise ValueError(f"{key}={features}: index {index} is outside the observation "
                                 f"(size {obs_dim}: indices 0-{obs_dim - 1})")
        elif item in names:
            index = names[item]
        else:
            known = f"; names: {', '.join(names)}" if names else ""
            raise ValueError(f"{key}={features}: {item!r} is neither an observation index (0-{obs_dim - 1}) "
                             f"nor a feature name{known}")
        if index in indices:
            raise ValueError(f"{key}={features}: {item!r} is listed twice")
        indices.append(index)
    return tuple(indices)


def make_gymnasium_task(gym_id: str, features: str | None = None, success: str = "termination",
                        matching_scale: float = 100.0, max_steps: int | None = None) -> TaskSpec:
    """Registers the gymnasium id ``gym_id`` as a task (named ``gym_id``) and returns its spec.

    Registering the same id again with the same settings returns the spec registered before.

    Args:
        gym_id: a gymnasium id with flat ``Box`` spaces (``MountainCarContinuous-v0``, ``Pendulum-v1``,
            ``Hopper-v5``, ...).
        features: the matching features ``h(s)``: observation indices ``"0,1"`` (``None``: all).
        success: evaluation's success flag, as :class:`GymnasiumTaskWrapper`.
        matching_scale: the matching reward's scale (default: the robotics tasks' 100; pick it so that an expert
            episode earns some hundreds, docs/own-task.md).
        max_steps: the episode limit (``None``: the id's ``max_episode_steps``).

    Raises:
        ValueError: one line: an unknown id, spaces that are not flat ``Box``, no episode limit,
            bad feature indices.

    Examples:
        >>> spec = make_gymnasium_task("MountainCarContinuous-v0", features="0")
        >>> spec.name, spec.obs_dim, spec.action_dim, spec.max_steps, spec.position_feature_indices
        ('MountainCarContinuous-v0', 2, 1, 999, (0,))
    """
    if gym_id not in gym.registry:
        close = [name for name in gym.registry if gym_id.lower().split("-")[0] in name.lower()][:5]
        hint = f" (did you mean {', '.join(close)}?)" if close else ""
        raise ValueError(f"env.gym_id={gym_id}: not a registered gymnasium id{hint}")
    if success not in SUCCESS_RULES and not success:
        raise ValueError(f"env.success={success!r}: termination, none or the name of an info entry")
    probe = gym.make(gym_id)
    try:
        check_flat_box_spaces(probe, gym_id)
        obs_dim, action_dim = int(probe.observation_space.shape[0]), int(probe.action_space.shape[0])
        limit = max_steps or (probe.spec.max_episode_steps if probe.spec is not None else None)
    finally:
        probe.close()
    if not limit:
        raise ValueError(f"env.gym_id={gym_id}: the id has no episode limit; set env.max_steps")
    spec = TaskSpec(
        name=gym_id, obs_dim=obs_dim, action_dim=action_dim, max_steps=int(limit), finish_position=None,
        ego_feature_indices=tuple(range(obs_dim)),
        position_feature_indices=parse_feature_indices(features, obs_dim),
        matching_scale=float(matching_scale), family="gymnasium", dt=1.0, episode_ends_at_goal=success != "none",
        description=f"gymnasium {gym_id} (success: {success})",
    )
    previous = TASKS.get(gym_id)
    if previous is not None and previous == spec:
        return previous
    return register_task(spec, partial(make_gymnasium_env, gym_id, success), replace=previous is not None)
