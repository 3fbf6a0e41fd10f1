"""TorchRL environments for the CSIRL tasks, by name: the built-in ones and those of :func:`~torchrl_csirl.tasks.register_task`.

The info entries (:data:`INFO_KEYS`, :func:`info_spec`, :class:`ScenarioInfoReader`) live in
:mod:`torchrl_csirl.tasks.info` and are importable from here too.
"""
from __future__ import annotations

from collections.abc import Callable
from functools import partial

import torch
from torchrl.envs import EnvBase, SerialEnv

from torchrl_csirl.tasks.catalog import resolve_scenario
from torchrl_csirl.tasks.info import FAILURE_KEYS, INFO_KEYS, ScenarioInfoReader, info_spec
from torchrl_csirl.tasks.registry import build_env, env_factory, registered_factory

__all__ = ["FAILURE_KEYS", "INFO_KEYS", "ScenarioInfoReader", "info_spec", "make_env", "make_serial_env"]


def make_env(
    name: str,
    seed: int | None = None,
    device: torch.device | str = "cpu",
    info_keys=INFO_KEYS,
    **overrides,
) -> EnvBase:
    """Create a task (driving scenario, robotics, locomotion or a registered one) as a TorchRL environment.

    Every task is built the same way, by its factory (:func:`~torchrl_csirl.tasks.registry.build_env`):
    the driving and robotics tasks' is :func:`~torchrl_csirl.tasks.catalog.make_scenario_env`, a
    :class:`~torchrl.envs.libs.gym.GymEnv` on the registered ``csirl/<name>-v0`` id with the
    task's info entries (``"distance_to_finish"``, ``"progress"``, ``"crashed"``,
    ``"offroad"``, ``"arrived"``, ``"success"``) read into the TensorDict with fixed specs.
    The episode limit appears as ``"truncated"``; crashes, off-road and the scene's own end
    conditions as ``"terminated"``.

    The function is defined at module level, so ``functools.partial(make_env, name, ...)`` is a
    picklable factory for :class:`~torchrl.envs.ParallelEnv` and collectors.

    Args:
        name: task name ("highway-fast", "merge", "roundabout", "intersection",
            "antmaze-umaze", "relocate") or gym id. The robotics tasks report no
            ``"offroad"`` (always False); AntMaze's ``"crashed"`` is a flipped ant (the episode
            goes on), Relocate's is always False.
        seed: seed applied with ``env.set_seed`` (None: unseeded).
        device: device of the output TensorDicts, for every task: given to a factory that takes
            ``device``, else the environment is moved there (None: where its factory puts it).
        info_keys: which info entries to read (for a factory that takes ``info_keys``).
        **overrides: highway-env config entries (see :func:`~torchrl_csirl.tasks.make_gym_env`),
            e.g. ``fast=False`` for the stock observation code; for a robotics task its
            constructor keywords (e.g. ``render_mode="rgb_array"``).

    Returns:
        the TorchRL environment.

    Examples:
        >>> from torchrl_csirl.tasks import make_env
        >>> env = make_env("merge", seed=0)
        >>> td = env.rollout(3, break_when_any_done=False)
        >>> td["observation"].shape, td["next", "distance_to_finish"].shape
        (torch.Size([3, 25]), torch.Size([3]))
    """
    spec = resolve_scenario(name)
    factory = registered_factory(spec.name)
    if factory is None:
        raise ValueError(f"{spec.name!r} is not a registered task (register_task registers it with its factory).")
    return build_env(factory, seed, device, info_keys, **overrides)


def make_serial_env(name: str | Callable[[], EnvBase], num_envs: int, seed: int | None = None, **kwargs) -> EnvBase:
    """``num_envs`` copies of a scenario stepped one after the other in this process.

    A :class:`~torchrl.envs.SerialEnv` of :func:`make_env` (batch size ``[num_envs]``); for
    ``num_envs=1`` the plain environment. ``partial(make_serial_env, name, k)`` pickles: as the
    environment factory of a multi-process collector's workers (the recipe) or of a
    :class:`~torchrl.envs.ParallelEnv` it gives ``k`` environments per worker process, and the
    policy forward and the per-step bookkeeping run once per ``k`` frames
    (``benchmarks/bench_collection.py --envs-per-worker``, docs/performance.md).

    Args:
        name: task name or gym id, or a zero-argument factory of one environment
            (:func:`~torchrl_csirl.tasks.registry.env_factory`: what a spawned worker receives).
        num_envs: environments in the batch (positive).
        seed: seed applied with ``env.set_seed`` (each copy gets its own seed derived from it).
        **kwargs: as :func:`make_env`.

    Examples:
        >>> from torchrl_csirl.tasks import make_serial_env
        >>> env = make_serial_env("merge", 2, seed=0)
        >>> env.rollout(3, break_when_any_done=False)["observation"].shape
        torch.Size([2, 3, 25])
        >>> env.close()
    """
    if not isinstance(num_envs, int) or num_envs < 1:
        raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}.")
    if callable(name):
        factory = partial(name, **kwargs) if kwargs else name
    else:
        resolve_scenario(name)  # fail here, not in the sub-environments
        factory = env_factory(name, **kwargs)
    if num_envs == 1:
        env = factory()
    else:
        env = SerialEnv(num_envs, factory)
    if seed is not None:
        env.set_seed(seed)
    return env
