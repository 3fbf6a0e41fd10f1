"""Demonstrations of your own controller on any task: :func:`record_demonstrations`."""
from __future__ import annotations

from collections.abc import Callable

import torch
from tensordict import TensorDictBase

from torchrl_csirl.data.expert import ExpertDemonstrations

__all__ = ["record_demonstrations"]


@torch.no_grad()
def record_demonstrations(task: str, policy: Callable[[TensorDictBase], TensorDictBase], episodes: int,
                          seed: int = 0, only_successful: bool = False) -> ExpertDemonstrations:
    """Rolls ``policy`` for ``episodes`` seeded episodes of ``task`` and keeps them as demonstrations.

    Episode ``i`` is seeded with ``seed + i`` and runs to its end (termination or the episode limit).

    Args:
        task: a task name (built-in, registered, or a gymnasium id registered by
            :func:`~torchrl_csirl.envs.make_gymnasium_task`).
        policy: ``policy(tensordict) -> tensordict`` writing ``"action"`` in ``[-1, 1]`` (a TorchRL
            actor, or a function of ``tensordict["observation"]``).
        episodes: how many to record (positive).
        seed: seed of the first episode.
        only_successful: keep only the episodes whose last step has ``"success"`` (or terminated);
            ``episodes`` counts the kept ones (at most ``10 x episodes`` tries).

    Returns:
        the demonstrations, with ``metadata["episodes"]`` holding each episode's seed, length and return.

    Raises:
        ValueError: ``episodes`` not positive, or too few successful episodes.

    Examples:
        >>> from torchrl_csirl.envs import make_gymnasium_task
        >>> _ = make_gymnasium_task("MountainCarContinuous-v0", features="0")
        >>> def pump(td):  # push the way the car moves: swings up to the flag
        ...     td["action"] = torch.where(td["observation"][..., 1:] >= 0, 1.0, -1.0)
        ...     return td
        >>> demos = record_demonstrations("MountainCarContinuous-v0", pump, episodes=2)
        >>> demos.num_trajectories, demos.observation_dim, demos.metadata["episodes"][0]["success"]
        (2, 2, True)
    """
    from torchrl_csirl.envs import episode_success, make_env, resolve_scenario

    if episodes < 1:
        raise ValueError(f"episodes must be positive, got {episodes}.")
    spec = resolve_scenario(task)
    env = make_env(spec.name)
    kept, info = [], []
    try:
        for i in range(episodes * 10 if only_successful else episodes):
            env.set_seed(seed + i)
            rollout = env.rollout(spec.max_steps, policy, break_when_any_done=True)
            success = bool(episode_success(rollout))
            if only_successful and not success:
                continue
            kept.append(rollout)
            info.append({"seed": seed + i, "length": int(rollout.shape[-1]), "success": success,
                         "return": float(rollout["next", "reward"].sum())})
            if len(kept) == episodes:
                break
    finally:
        env.close()
    if len(kept) < episodes:
        raise ValueError(f"{spec.name}: only {len(kept)} of {episodes} episodes succeeded in {episodes * 10} tries.")
    return ExpertDemonstrations.from_episodes(kept, metadata={"task": spec.name, "episodes": info})
