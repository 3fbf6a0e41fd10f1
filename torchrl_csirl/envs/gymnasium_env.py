"""A gymnasium environment with flat ``Box`` spaces as the TorchRL environment of a CSIRL task.

The environment side of :func:`~torchrl_csirl.envs.make_gymnasium_task` (which registers the task):
:class:`GymnasiumTaskWrapper` (actions in ``[-1, 1]``, float32 observations, ``info["success"]``)
and :func:`make_gymnasium_env`, the task's picklable factory, also that of the locomotion tasks
(:mod:`torchrl_csirl.envs.locomotion`). It depends on no registry.
"""
from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torchrl.envs import EnvBase
from torchrl.envs.libs.gym import GymWrapper

from torchrl_csirl.envs.headless import ensure_headless_gl
from torchrl_csirl.envs.info import ScenarioInfoReader, info_spec

__all__ = ["SUCCESS_RULES", "GymnasiumTaskWrapper", "check_flat_box_spaces", "make_gymnasium_env"]

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
    ensure_headless_gl(make_kwargs.get("render_mode"))  # a MuJoCo task's pictures on a machine without a display
    env = GymWrapper(GymnasiumTaskWrapper(gym.make(gym_id, **make_kwargs), success), device=device)
    env.set_info_dict_reader(ScenarioInfoReader(["success"], spec=info_spec(["success"])))
    return env
