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
    """Imports the provider of ``gym_id`` when gymnasium does not know the id yet; returns the provider's name.

    Returns the provider (one of :data:`GYM_ID_PROVIDERS`) whose environment the id is, imported now or
    before; None for an id of gymnasium's own or of another package, and for an id no installed provider
    registers (gymnasium still does not know it then: the caller says so).

    Examples:
        >>> import_gym_provider("Pendulum-v1") is None  # gymnasium's own
        True
        >>> import_gym_provider("PointMaze_UMaze-v3"), "PointMaze_UMaze-v3" in gym.registry
        ('gymnasium_robotics', True)
        >>> import_gym_provider("NoSuchEnv-v0") is None
        True
    """
    for name in GYM_ID_PROVIDERS:
        if gym_id in gym.registry:
            break
        try:
            module = importlib.import_module(name)
        except ImportError:  # not installed
            continue
        gym.register_envs(module)
    if gym_id not in gym.registry:
        return None
    entry_point = gym.spec(gym_id).entry_point
    package = entry_point.split(".")[0].split(":")[0] if isinstance(entry_point, str) else entry_point.__module__.split(".")[0]
    return package if package in GYM_ID_PROVIDERS else None
