"""Any gymnasium environment with flat ``Box`` spaces as a CSIRL task, without code.

:func:`make_gymnasium_task` reads the environment's spaces and episode limit, writes a
:class:`~torchrl_csirl.envs.TaskSpec` and registers it (:func:`~torchrl_csirl.envs.register_task`)
under the gymnasium id, with :func:`make_gymnasium_env` as its factory. The environment seen by
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
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torchrl.envs import EnvBase
from torchrl.envs.libs.gym import GymWrapper

from torchrl_csirl.envs.headless import ensure_headless_gl
from torchrl_csirl.envs.registry import register_task
from torchrl_csirl.envs.scenarios import TASKS
from torchrl_csirl.envs.spec import TaskSpec

__all__ = ["GymnasiumTaskWrapper", "make_gymnasium_env", "make_gymnasium_task", "parse_feature_indices"]

#: evaluation's success flag for a gymnasium task: besides these, the name of an info entry
SUCCESS_RULES = ("termination", "none")


class GymnasiumTaskWrapper(gym.Wrapper):
    """Actions in ``[-1, 1]``, float32 observations and ``info["success"]`` for a flat-``Box`` env.

    Args:
        env: the gymnasium environment (flat ``Box`` observation and action spaces).
        success: ``"termination"``, ``"none"`` or the info entry holding the success flag.

    Examples:
        >>> env = GymnasiumTaskWrapper(gym.make("MountainCarContinuous-v0"))
        >>> env.action_space.low, env.observation_space.dtype
        (array([-1.], dtype=float32), dtype('float32'))
        >>> _ = env.reset(seed=0)
        >>> env.step(np.array([1.0], dtype=np.float32))[4]["success"]
        False
    """

    def __init__(self, env: gym.Env, success: str = "termination") -> None:
        check_flat_box_spaces(env, env.spec.id if env.spec is not None else type(env).__name__)
        low, high = env.action_space.low, env.action_space.high
        super().__init__(gym.wrappers.RescaleAction(env, -np.ones_like(low), np.ones_like(high)))
        self.success = success
        space = env.observation_space
        self.observation_space = gym.spaces.Box(space.low.astype(np.float32), space.high.astype(np.float32),
                                                space.shape, np.float32)

    def reset(self, **kwargs: Any):
        obs, info = self.env.reset(**kwargs)
        return np.asarray(obs, dtype=np.float32), {**info, "success": False}

    def step(self, action: np.ndarray):
        obs, reward, terminated, truncated, info = self.env.step(action)
        if self.success == "termination":
            success = bool(terminated) and not bool(truncated)
        elif self.success == "none":
            success = False
        else:
            success = bool(info.get(self.success, False))
        return np.asarray(obs, dtype=np.float32), reward, terminated, truncated, {**info, "success": success}


def check_flat_box_spaces(env: gym.Env, name: str) -> None:
    """One ``ValueError`` line when ``env`` is not a flat-``Box`` environment."""
    for what, space in (("observation", env.observation_space), ("action", env.action_space)):
        if not isinstance(space, gym.spaces.Box) or len(space.shape) != 1:
            raise ValueError(f"env.gym_id={name}: its {what} space is {space}; a CSIRL task needs flat Box "
                             "observation and action spaces (register your own task for others)")
    if not (np.isfinite(env.action_space.low).all() and np.isfinite(env.action_space.high).all()):
        raise ValueError(f"env.gym_id={name}: its action space is unbounded; actions are rescaled to [-1, 1]")


def make_gymnasium_env(gym_id: str, success: str = "termination", device: torch.device | str = "cpu",
                       **make_kwargs: Any) -> EnvBase:
    """The TorchRL environment of a gymnasium task (picklable through ``functools.partial``).

    Args:
        gym_id: the gymnasium id.
        success: as :class:`GymnasiumTaskWrapper`.
        device: device of the output TensorDicts.
        **make_kwargs: keywords of ``gym.make`` (e.g. ``render_mode="rgb_array"``).

    Examples:
        >>> env = make_gymnasium_env("MountainCarContinuous-v0")
        >>> td = env.rollout(3)
        >>> td["observation"].dtype, td["next", "success"].shape
        (torch.float32, torch.Size([3]))
    """
    from torchrl_csirl.envs.torchrl_env import ScenarioInfoReader, info_spec

    ensure_headless_gl(make_kwargs.get("render_mode"))  # a MuJoCo task's pictures on a machine without a display
    env = GymWrapper(GymnasiumTaskWrapper(gym.make(gym_id, **make_kwargs), success), device=device)
    env.set_info_dict_reader(ScenarioInfoReader(["success"], spec=info_spec(["success"])))
    return env


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
