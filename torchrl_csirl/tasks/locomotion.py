"""gymnasium's MuJoCo locomotion as CSIRL tasks: ``hopper`` (``Hopper-v5``) and ``halfcheetah``
(``HalfCheetah-v5``), the standard home of online imitation (GAIL, DAC, ValueDICE, SQIL and
IQ-Learn report there).

The matching reward needs a progress coordinate: the torso's x position. gymnasium drops it from
the observation by default; here the observation keeps it as entry 0
(``exclude_current_positions_from_observation=False``), the matching reward and the nearest-state
search read it (``position_feature_indices = ego_feature_indices = (0,)``), and the task lists it in
:attr:`~torchrl_csirl.tasks.TaskSpec.hidden_feature_indices`, so every network (actor, critics,
learned reward, discriminators) reads the observation through
:class:`~torchrl_csirl.modules.DropFeatures` and sees exactly gymnasium's default observation
(11 entries for the hopper, 17 for the cheetah). The demonstrations keep x, as the matching reward
needs it.

There is no goal: ``"success"`` is never set (compare returns), the episode limit is gymnasium's
1 000 steps, a fall ends a hopper's episode (``"terminated"``), the cheetah never falls. The
matching scale makes an expert's 1 000-step episode earn a few hundred (the hopper covers about
20 m, the cheetah about 300 m).

Examples:
    >>> from torchrl_csirl.tasks import make_env, resolve_scenario
    >>> spec = resolve_scenario("hopper")
    >>> spec.obs_dim, spec.hidden_feature_indices, spec.matching_features
    (12, (0,), ('x',))
    >>> make_env("hopper", seed=0).rollout(3)["observation"].shape
    torch.Size([3, 12])
"""
from __future__ import annotations

import os
from functools import partial
from types import MappingProxyType
from typing import Any, Callable

import numpy as np
import torch

from torchrl_csirl._paths import EXPERTS_DIR
from torchrl_csirl.tasks.gymnasium_env import make_gymnasium_env
from torchrl_csirl.tasks.spec import TaskSpec

__all__ = ["LOCOMOTION_GYM_IDS", "LOCOMOTION_MAKE_KWARGS", "LOCOMOTION_TASKS", "LocomotionExpert", "expert_policy_path",
           "locomotion_factories", "make_locomotion_env"]

#: task name -> the gymnasium id it wraps
LOCOMOTION_GYM_IDS: dict[str, str] = {"hopper": "Hopper-v5", "halfcheetah": "HalfCheetah-v5"}
#: the ``gym.make`` keywords of every locomotion task: x kept in the observation
LOCOMOTION_MAKE_KWARGS: dict[str, bool] = {"exclude_current_positions_from_observation": False}


def _locomotion_spec(name: str, joints: int, action_dim: int, dt: float, scale: float, body: str) -> TaskSpec:
    """A locomotion task's spec: ``[x, z, angle, joint angles, vx, vz, angular velocity, joint velocities]``."""
    velocities = 3 + joints
    layout = {"x": (0, 1), "z": (1, 2), "angle": (2, 3), "joint_angles": (3, velocities),
              "vx": (velocities, velocities + 1), "vz": (velocities + 1, velocities + 2),
              "angular_velocity": (velocities + 2, velocities + 3),
              "joint_velocities": (velocities + 3, velocities + 3 + joints)}
    return TaskSpec(
        name=name, obs_dim=velocities + 3 + joints, action_dim=action_dim, max_steps=1000, finish_position=None,
        ego_feature_indices=(0,), position_feature_indices=(0,), hidden_feature_indices=(0,),
        matching_scale=scale, episode_ends_at_goal=False, dt=dt, family="locomotion",
        expert=f"{__name__}:LocomotionExpert",
        observation_layout=MappingProxyType(layout),
        description=f"gymnasium {LOCOMOTION_GYM_IDS[name]}: the {body} runs forward; the matching reward "
                    "reads the torso's x, the networks do not",
    )


#: the locomotion tasks by name
LOCOMOTION_TASKS: dict[str, TaskSpec] = {
    "hopper": _locomotion_spec("hopper", joints=3, action_dim=3, dt=0.008, scale=10.0, body="one-legged hopper"),
    "halfcheetah": _locomotion_spec("halfcheetah", joints=6, action_dim=6, dt=0.05, scale=1.0, body="half cheetah"),
}


def make_locomotion_env(name: str, device: torch.device | str = "cpu", **make_kwargs: Any):
    """The TorchRL environment of a locomotion task: the gymnasium id with x kept in the observation.

    Pictures (``render_mode="rgb_array"``) are taken by the model's ``track`` camera, which follows the
    body; gymnasium's default, a free camera, stays at the start while the body runs out of the picture.

    Args:
        name: ``"hopper"`` or ``"halfcheetah"``.
        device: device of the output TensorDicts.
        **make_kwargs: keywords of ``gym.make`` (e.g. ``render_mode="rgb_array"``, ``camera_name=...``).

    Examples:
        >>> env = make_locomotion_env("halfcheetah")
        >>> env.observation_spec["observation"].shape, env.action_spec.shape
        (torch.Size([18]), torch.Size([6]))
    """
    if name not in LOCOMOTION_GYM_IDS:
        raise ValueError(f"{name!r} is not a locomotion task; expected one of {sorted(LOCOMOTION_GYM_IDS)}.")
    if make_kwargs.get("render_mode") is not None and "camera_id" not in make_kwargs:
        make_kwargs.setdefault("camera_name", "track")
    return make_gymnasium_env(LOCOMOTION_GYM_IDS[name], "none", device, **LOCOMOTION_MAKE_KWARGS, **make_kwargs)


def locomotion_factories() -> dict[str, Callable[..., Any]]:
    """Each locomotion task's picklable environment factory (for the task registry)."""
    return {name: partial(make_locomotion_env, name) for name in LOCOMOTION_TASKS}


def expert_policy_path(name: str) -> str:
    """The shipped expert of a locomotion task: SAC on the task's own reward
    (``recipes/train_expert.py``, docs/experts.md), a :func:`~torchrl_csirl.modules.save_policy` file."""
    return os.path.join(EXPERTS_DIR, name, "sac_policy.pt")


class LocomotionExpert:
    """A locomotion task's expert: the shipped SAC policy (or another saved one), deterministic.

    It reads the observation the environment gives (x included, which the policy's input map drops),
    through the unwrapped MuJoCo environment, as every expert of :func:`~torchrl_csirl.tasks.experts.make_expert`
    reads its simulator.

    Args:
        name: ``"hopper"`` or ``"halfcheetah"``.
        policy: a :func:`~torchrl_csirl.modules.save_policy` file or run directory (default: the shipped one).

    Raises:
        FileNotFoundError: no policy file there.
        ValueError: a policy whose sizes are not the task's.
    """

    def __init__(self, name: str, policy: Any = None) -> None:
        from torchrl_csirl.modules import load_policy

        spec = LOCOMOTION_TASKS[name]
        policy = expert_policy_path(name) if policy is None else policy
        self.policy = load_policy(policy) if isinstance(policy, (str, os.PathLike)) else policy
        dims = getattr(self.policy, "metadata", {})
        if (dims.get("obs_dim", spec.obs_dim), dims.get("action_dim", spec.action_dim)) != (spec.obs_dim, spec.action_dim):
            raise ValueError(f"the {name} expert needs a policy with {spec.obs_dim} inputs and {spec.action_dim} "
                             f"actions, got {dims.get('obs_dim')} and {dims.get('action_dim')}.")

    def reset(self, env: Any) -> None:
        """Nothing to reset: the policy is memoryless."""

    @torch.no_grad()
    def act(self, env: Any) -> np.ndarray:
        from tensordict import TensorDict
        from torchrl.envs.utils import ExplorationType, set_exploration_type

        obs = torch.as_tensor(env.unwrapped._get_obs(), dtype=torch.float32)
        with set_exploration_type(ExplorationType.DETERMINISTIC):
            return self.policy(TensorDict({"observation": obs}, []))["action"].numpy().astype(np.float32)
