"""A user's own task, as a module a run imports with ``env.module=own_task_module``: Pendulum-v1
under another name, registered with :func:`torchrl_csirl.tasks.register_task` (its factory is a
top-level function, so spawned collector workers can import it)."""
from __future__ import annotations

from torchrl_csirl.tasks import TASKS, TaskSpec, make_gymnasium_env, register_task

NAME = "own-pendulum"


def make_own_pendulum(**overrides):
    """The task's TorchRL environment: Pendulum with actions in [-1, 1]; it never succeeds."""
    return make_gymnasium_env("Pendulum-v1", "none", **overrides)


SPEC = TaskSpec(name=NAME, obs_dim=3, action_dim=1, max_steps=200, finish_position=None,
                ego_feature_indices=(0, 1, 2), position_feature_indices=(0, 1), matching_scale=1.0,
                observation_layout={"cos": (0, 1), "sin": (1, 2), "speed": (2, 3)})

if NAME not in TASKS:
    register_task(SPEC, make_own_pendulum)
