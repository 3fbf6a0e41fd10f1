"""Gymnasium ids that installed packages register when imported: :func:`import_gym_provider`.

``gymnasium.make("PointMaze_UMaze-v3")`` knows the id only once ``gymnasium_robotics`` has been imported
(``gymnasium.register_envs(gymnasium_robotics)``). :func:`import_gym_provider` imports the known providers
(:data:`GYM_ID_PROVIDERS`, those installed) until one registers the id, so that ``env.gym_id=`` takes such
an id without ``env.module=``; a task's environment factory calls it too, in a worker process as here.
"""
from __future__ import annotations

import importlib

import gymnasium as gym

__all__ = ["GYM_ID_PROVIDERS", "import_gym_provider"]

#: the packages whose import registers gymnasium ids, tried in this order for an id gymnasium does not know
GYM_ID_PROVIDERS: tuple[str, ...] = ("gymnasium_robotics",)


def import_gym_provider(gym_id: str) -> str | None:
    """Imports the provider of ``gym_id`` when gymnasium does not know the id yet; returns its module name.

    Returns None when the id was known already, or when no installed provider registers it (gymnasium
    still does not know it then: the caller says so).

    Examples:
        >>> import_gym_provider("Pendulum-v1") is None  # gymnasium's own
        True
        >>> _ = import_gym_provider("PointMaze_UMaze-v3")  # "gymnasium_robotics", unless imported before
        >>> "PointMaze_UMaze-v3" in gym.registry
        True
        >>> import_gym_provider("NoSuchEnv-v0") is None
        True
    """
    if gym_id in gym.registry:
        return None
    for name in GYM_ID_PROVIDERS:
        try:
            module = importlib.import_module(name)
        except ImportError:  # not installed
            continue
        gym.register_envs(module)
        if gym_id in gym.registry:
            return name
    return None
