"""Demonstrations of your own controller on any task: :func:`record_demonstrations`."""
from __future__ import annotations

from collections.abc import Callable

import torch
from tensordict import TensorDictBase

from torchrl_csirl.data.expert import ExpertDemonstrations

__all__ = ["record_demonstrations"]


@torch.no_grad()
def record_demonstrations(task: str, policy: Callable[[TensorDictBase], TensorDictBase], episodes: int,
                          seed: int = 0, only_successful: bool = False,
                          min_return: float | None = None) -> ExpertDemonstrations:
    """Rolls ``policy`` for ``episodes`` seeded episodes of ``task`` and keeps them as demonstrations.

    Episode ``i`` is seeded with ``seed + i`` and runs to its end (termination or the episode limit).

    Args:
        task: a task name (built-in, registered, or a gymnasium id registered by
            :func:`~torchrl_csirl.tasks.make_gymnasium_task`).
        policy: ``policy(tensordict) -> tensordict`` writing ``"action"`` in ``[-1, 1]`` (a TorchRL
            actor, or a function of ``tensordict["observation"]``).
        episodes: how many to record (positive).
        seed: seed of the first episode.
        only_successful: keep only the episodes whose last step has ``"success"`` (or terminated);
            ``episodes`` counts the kept ones (at most ``10 x episodes`` tries).
        min_return: keep only the episodes that earn at least this return (as IQ-Learn's authors generate
            their MuJoCo demonstrations, above a threshold); ``episodes`` counts the kept ones (at most
            ``10 x episodes`` tries). None: every episode.

    Returns:
        the demonstrations, with ``metadata["episodes"]`` holding each episode's seed, length and return.

    Raises:
        ValueError: ``episodes`` not positive, or too few episodes kept.

    Examples:
        >>> from torchrl_csirl.tasks import make_gymnasium_task
        >>> _ = make_gymnasium_task("MountainCarContinuous-v0", features="0")
        >>> def pump(td):  # push the way the car moves: swings up to the flag
        ...     td["action"] = torch.where(td["observation"][..., 1:] >= 0, 1.0, -1.0)
        ...     return td
        >>> demos = record_demonstrations("MountainCarContinuous-v0", pump, episodes=2)
        >>> demos.num_trajectories, demos.observation_dim, demos.metadata["episodes"][0]["success"]
        (2, 2, True)
        >>> record_demonstrations("MountainCarContinuous-v0", pump, episodes=1, min_return=1000.0)
        Traceback (most recent call last):
        ...
        ValueError: MountainCarContinuous-v0: only 0 of 1 episodes earned at least 1000.0 in 10 tries.
    """
    from torchrl_csirl.tasks import episode_success, make_env, resolve_scenario

    if episodes < 1:
        raise ValueError(f"episodes must be positive, got {episodes}.")
    spec = resolve_scenario(task)
    env = make_env(spec.name)
    kept, info = [], []
    try:
        tries = episodes * 10 if only_successful or min_return is not None else episodes
        for i in range(tries):
            env.set_seed(seed + i)
            rollout = env.rollout(spec.max_steps, policy, break_when_any_done=True)
            success, episode_return = bool(episode_success(rollout)), float(rollout["next", "reward"].sum())
            if (only_successful and not success) or (min_return is not None and episode_return < min_return):
                continue
            kept.append(rollout)
            info.append({"seed": seed + i, "length": int(rollout.shape[-1]), "success": success, "return": episode_return})
            if len(kept) == episodes:
                break
    finally:
        env.close()
    if len(kept) < episodes:
        wanted = " and ".join(([] if not only_successful else ["succeeded"])
                              + ([] if min_return is None else [f"earned at least {min_return}"]))
        raise ValueError(f"{spec.name}: only {len(kept)} of {episodes} episodes {wanted} in {tries} tries.")
    return ExpertDemonstrations.from_episodes(kept, metadata={"task": spec.name, "episodes": info})
