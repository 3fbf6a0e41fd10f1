"""Evaluation of a policy with the paper's test accomplish rate, on any task.

The accomplish rate needs the task's ``"distance_to_finish"`` (the driving scenes, AntMaze); a task
without it (Relocate's own measure aside: any task of your own, a gymnasium id) reports its
success rate there. Success is the task's ``"success"`` flag, or for a task without one a
termination that is not a truncation. The return is always reported (``env_return``).
"""
from __future__ import annotations

import torch
from tensordict.nn import TensorDictModuleBase
from torchrl.envs import EnvBase, ExplorationType, set_exploration_type

from torchrl_csirl.envs.metrics import accomplish_rate_from_rollout, episode_success

__all__ = ["evaluate_policy"]


@torch.no_grad()
def evaluate_policy(
    env: EnvBase,
    policy: TensorDictModuleBase,
    *,
    episodes: int,
    max_steps: int,
    seed: int,
    deterministic: bool = True,
) -> dict[str, float]:
    """Rolls out ``episodes`` seeded episodes and averages the paper's metrics.

    Episode ``i`` is seeded with ``seed + i``, so two calls with the same policy give the same
    numbers whatever happened in between.

    Args:
        env: a task's environment (:func:`~torchrl_csirl.envs.make_env`).
        policy: the actor.
        episodes: number of episodes.
        max_steps: episode limit (the scenario's ``max_steps``).
        seed: seed of the first episode.
        deterministic: evaluate the deterministic (mode) policy, as the paper does.

    Returns:
        ``accomplish_rate`` (mean), ``accomplish_rate_std``, ``success_rate``, ``crash_rate``,
        ``episode_length`` and ``env_return`` (the environment's own reward; driving: for
        reference only). Without ``"distance_to_finish"`` the accomplish rate is the success rate.

    Examples:
        >>> from torchrl_csirl.envs import SCENARIOS, make_env
        >>> from torchrl_csirl.modules import make_actor
        >>> spec = SCENARIOS["merge"]
        >>> env = make_env("merge")
        >>> out = evaluate_policy(env, make_actor(spec.obs_dim, spec.action_dim), episodes=1,
        ...                       max_steps=5, seed=0)
        >>> 0.0 <= out["accomplish_rate"] <= 1.0
        True
    """
    if episodes <= 0:
        raise ValueError(f"episodes must be positive, got {episodes}.")
    rates, successes, crashes, lengths, returns = [], [], [], [], []
    exploration = ExplorationType.DETERMINISTIC if deterministic else ExplorationType.RANDOM
    with set_exploration_type(exploration):
        for i in range(episodes):
            env.set_seed(seed + i)
            rollout = env.rollout(max_steps, policy, break_when_any_done=True)
            success = float(episode_success(rollout))
            has_distance = ("next", "distance_to_finish") in rollout.keys(True)
            rates.append(float(accomplish_rate_from_rollout(rollout)) if has_distance else success)
            successes.append(success)
            crashes.append(float(rollout["next", "crashed"].any()) if ("next", "crashed") in rollout.keys(True) else 0.0)
            lengths.append(rollout.shape[-1])
            returns.append(float(rollout["next", "reward"].sum()))
    rate = torch.tensor(rates)
    return {
        "accomplish_rate": float(rate.mean()),
        "accomplish_rate_std": float(rate.std(unbiased=False)),
        "success_rate": sum(successes) / episodes,
        "crash_rate": sum(crashes) / episodes,
        "episode_length": sum(lengths) / episodes,
        "env_return": sum(returns) / episodes,
    }
