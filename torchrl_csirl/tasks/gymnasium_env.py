"""A gymnasium environment with flat ``Box`` spaces as the TorchRL environment of a CSIRL task.

The environment side of :func:`~torchrl_csirl.tasks.make_gymnasium_task` (which registers the task):
:class:`GymnasiumTaskWrapper` (actions in ``[-1, 1]``, float32 observations, ``info["success"]``)
and :func:`make_gymnasium_env`, the task's picklable factory, also that of the locomotion tasks
(:mod:`torchrl_csirl.tasks.locomotion`). It depends on no registry.

A ``Dict`` observation of flat ``Box`` entries (a goal-conditioned gymnasium-robotics task:
``observation``, ``achieved_goal``, ``desired_goal``) becomes one flat observation, its entries in the
order of :func:`observation_layout` (the goal keys first, in :data:`GOAL_KEYS`' order, then the others
by name).
"""
from __future__ import annotations

import contextlib
import os
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torchrl.envs import EnvBase
from torchrl.envs.libs.gym import GymWrapper

from torchrl_csirl.tasks.gym_ids import import_gym_provider
from torchrl_csirl.tasks.headless import ensure_headless_gl
from torchrl_csirl.tasks.info import ScenarioInfoReader, info_spec

__all__ = ["GOAL_KEYS", "SUCCESS_RULES", "GymnasiumTaskWrapper", "check_flat_box_spaces", "is_goal_space",
           "make_gymnasium_env", "observation_layout", "remove_maze_xml"]

#: evaluation's success flag for a gymnasium task: besides these, the name of an info entry
SUCCESS_RULES = ("termination", "none")

#: a goal-conditioned environment's observation entries (gymnasium-robotics' ``GoalEnv``), first in this order
GOAL_KEYS = ("observation", "achieved_goal", "desired_goal")


def is_goal_space(space: gym.Space) -> bool:
    """Whether an observation space is a goal-conditioned ``Dict`` (``achieved_goal`` and ``desired_goal``).

    Examples:
        >>> box = gym.spaces.Box(-1.0, 1.0, (2,))
        >>> is_goal_space(gym.spaces.Dict(achieved_goal=box, desired_goal=box)), is_goal_space(box)
        (True, False)
    """
    return isinstance(space, gym.spaces.Dict) and {"achieved_goal", "desired_goal"} <= set(space.spaces)


def observation_layout(space: gym.Space) -> dict[str, tuple[int, int]]:
    """Name -> ``(start, stop)`` of each ``Dict`` entry in the flat observation (empty for a ``Box``).

    The keys of :data:`GOAL_KEYS` come first, in that order, then the others sorted by name.

    Examples:
        >>> box = lambda n: gym.spaces.Box(-1.0, 1.0, (n,))
        >>> observation_layout(gym.spaces.Dict(desired_goal=box(2), achieved_goal=box(2), observation=box(4)))
        {'observation': (0, 4), 'achieved_goal': (4, 6), 'desired_goal': (6, 8)}
    """
    if not isinstance(space, gym.spaces.Dict):
        return {}
    keys = [k for k in GOAL_KEYS if k in space.spaces] + sorted(k for k in space.spaces if k not in GOAL_KEYS)
    layout, start = {}, 0
    for key in keys:
        size = int(np.prod(space.spaces[key].shape))
        layout[key] = (start, start + size)
        start += size
    return layout


class GymnasiumTaskWrapper(gym.Wrapper):
    """Actions in ``[-1, 1]``, flat float32 observations and ``info["success"]`` for a flat-``Box`` env.

    A ``Dict`` observation of flat ``Box`` entries is flattened in the order of :func:`observation_layout`
    (kept in :attr:`layout`).

    Args:
        env: the gymnasium environment (a flat ``Box`` action space; a flat ``Box`` observation space or
            a ``Dict`` of them).
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
        remove_maze_xml(env)
        low, high = env.action_space.low, env.action_space.high
        super().__init__(gym.wrappers.RescaleAction(env, -np.ones_like(low), np.ones_like(high)))
        self.success = success
        space = env.observation_space
        self.layout = observation_layout(space)
        boxes = [space.spaces[key] for key in self.layout] if self.layout else [space]
        self.observation_space = gym.spaces.Box(np.concatenate([b.low.ravel() for b in boxes]).astype(np.float32),
                                                np.concatenate([b.high.ravel() for b in boxes]).astype(np.float32),
                                                dtype=np.float32)

    def _flat(self, obs: Any) -> np.ndarray:
        """The flat float32 observation (a ``Dict``'s entries in the order of :attr:`layout`)."""
        if not self.layout:
            return np.asarray(obs, dtype=np.float32)
        return np.concatenate([np.asarray(obs[key], dtype=np.float32).ravel() for key in self.layout])

    def reset(self, **kwargs: Any):
        obs, info = self.env.reset(**kwargs)
        return self._flat(obs), {**info, "success": False}

    def step(self, action: np.ndarray):
        obs, reward, terminated, truncated, info = self.env.step(action)
        if self.success == "termination":
            success = bool(terminated) and not bool(truncated)
        elif self.success == "none":
            success = False
        else:
            success = bool(info.get(self.success, False))
        return self._flat(obs), reward, terminated, truncated, {**info, "success": success}


def _is_flat_box(space: gym.Space) -> bool:
    return isinstance(space, gym.spaces.Box) and len(space.shape) == 1


def check_flat_box_spaces(env: gym.Env, name: str) -> None:
    """One ``ValueError`` line when ``env`` is not a flat-``Box`` environment (a ``Dict`` of flat ``Box``
    observations is one)."""
    observation = env.observation_space
    if isinstance(observation, gym.spaces.Dict) and observation.spaces and all(map(_is_flat_box, observation.spaces.values())):
        observation = gym.spaces.Box(-np.inf, np.inf, (1,))  # flattened by GymnasiumTaskWrapper
    for what, space in (("observation", observation), ("action", env.action_space)):
        if not _is_flat_box(space):
            shown = env.observation_space if what == "observation" else space
            raise ValueError(f"env.gym_id={name}: its {what} space is {shown}; a CSIRL task needs flat Box "
                             "observation (or a Dict of them) and action spaces (register your own task for others)")
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
    ensure_headless_gl(make_kwargs.get("render_mode"))  # a MuJoCo task's pictures on a machine without a display
    import_gym_provider(gym_id)  # gymnasium-robotics' ids, in a worker process too
    env = GymWrapper(GymnasiumTaskWrapper(gym.make(gym_id, **make_kwargs), success), device=device)
    env.set_info_dict_reader(ScenarioInfoReader(["success"], spec=info_spec(["success"])))
    return env


def remove_maze_xml(env: gym.Env) -> None:
    """Deletes the model file a gymnasium-robotics maze leaves in the temp folder (MuJoCo read it already):
    one per environment built otherwise (a no-op for other environments)."""
    path = getattr(env.unwrapped, "tmp_xml_file_path", None)
    if isinstance(path, str):
        with contextlib.suppress(OSError):
            os.remove(path)
