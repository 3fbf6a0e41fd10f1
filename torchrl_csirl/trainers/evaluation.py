"""Evaluation of a policy with the paper's test accomplish rate, on any task.

The accomplish rate needs the task's ``"distance_to_finish"`` (the driving scenes, AntMaze); a task
without it (Relocate's own measure aside: any task of your own, a gymnasium id) reports its
success rate there. Success is the task's ``"success"`` flag, or for a task without one a
termination that is not a truncation. The return is always reported (``env_return``).

A batched environment (a :class:`~torchrl.envs.SerialEnv` or :class:`~torchrl.envs.ParallelEnv`
of ``N`` copies, batch size ``[N]``) plays ``N`` episodes at once: it rolls with
``break_when_any_done=False`` (TorchRL's default would cut the other copies' episodes short at the
first ``done``) and keeps each copy's first episode, up to its first ``done``. Episode ``i`` is
seeded with ``seed + i`` either way, so the per-episode numbers match the single environment's.
"""
from __future__ import annotations

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torchrl.envs import EnvBase, ExplorationType, set_exploration_type

from torchrl_csirl.tasks.metrics import _first_episode_mask, accomplish_rate_from_rollout, episode_success

__all__ = ["episode_metrics", "evaluate_episodes", "evaluate_policy"]

#: the per-episode entries of :func:`evaluate_episodes`
EPISODE_KEYS = ("accomplish_rate", "success", "crashed", "episode_length", "env_return")


def _flag(rollout: TensorDictBase, key: tuple[str, str]) -> torch.Tensor:
    """``rollout[key]`` as a bool tensor of the rollout's shape ``(*batch, T)``."""
    return rollout.get(key).reshape(rollout.shape).bool()


def episode_metrics(rollout: TensorDictBase) -> dict[str, torch.Tensor]:
    """The paper's metrics of the first episode in each row of a rollout (time the last dim).

    The first episode of a row runs up to and including its first ``("next", "done")``; later steps
    (after an auto-reset, with ``break_when_any_done=False``) are ignored.

    Args:
        rollout: a TensorDict ``(*batch, T)`` from ``env.rollout(...)`` holding ``("next", "reward")``
            and ``("next", "done")``; ``"distance_to_finish"``, ``("next", "success")``,
            ``("next", "crashed")``, ``("next", "terminated")``/``("next", "truncated")`` where the
            task reports them.

    Returns:
        one float64 tensor of shape ``batch`` for each of ``accomplish_rate`` (the success without a
        ``"distance_to_finish"``), ``success``, ``crashed``, ``episode_length`` and ``env_return``.

    Raises:
        ValueError: without a time dimension or without ``("next", "done")`` (the episodes cannot be told apart).

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> td = TensorDict({"next": {"reward": torch.ones(2, 4, 1),
        ...                           "done": torch.tensor([[0, 1, 0, 0], [0, 0, 0, 1]]).bool().unsqueeze(-1),
        ...                           "terminated": torch.tensor([[0, 1, 0, 0], [0, 0, 0, 0]]).bool().unsqueeze(-1),
        ...                           "truncated": torch.tensor([[0, 0, 0, 0], [0, 0, 0, 1]]).bool().unsqueeze(-1)}},
        ...                 batch_size=[2, 4])
        >>> m = episode_metrics(td)
        >>> m["episode_length"].tolist(), m["env_return"].tolist(), m["success"].tolist()
        ([2.0, 4.0], [2.0, 4.0], [1.0, 0.0])
    """
    keys = rollout.keys(True)
    if rollout.ndim == 0:
        raise ValueError("episode_metrics expects a rollout with a time dimension (the last one).")
    if ("next", "done") not in keys:
        raise ValueError("episode_metrics needs ('next', 'done') to tell one episode from the next.")
    mask = _first_episode_mask(_flag(rollout, ("next", "done")))
    if ("next", "success") in keys:
        success = episode_success(rollout)  # the flag within the first episode
    elif ("next", "terminated") in keys:  # a termination that is not a truncation, within the first episode
        ended = _flag(rollout, ("next", "terminated")) & mask
        if ("next", "truncated") in keys:
            ended = ended & ~_flag(rollout, ("next", "truncated"))
        success = ended.any(-1)
    else:
        success = torch.zeros(rollout.shape[:-1], dtype=torch.bool)
    success = success.to(torch.float64)
    if ("next", "distance_to_finish") in keys:
        rate = accomplish_rate_from_rollout(rollout)
    else:
        rate = success
    crashed = (_flag(rollout, ("next", "crashed")) & mask).any(-1) if ("next", "crashed") in keys else torch.zeros_like(mask[..., 0])
    reward = rollout.get(("next", "reward")).reshape(rollout.shape).to(torch.float64)
    return {
        "accomplish_rate": rate.to(torch.float64),
        "success": success,
        "crashed": crashed.to(torch.float64),
        "episode_length": mask.sum(-1).to(torch.float64),
        "env_return": torch.where(mask, reward, torch.zeros_like(reward)).sum(-1),
    }


def _check_batched(env: EnvBase) -> int:
    """The number of copies ``N`` of a batched environment (1 for a single one)."""
    if env.batch_size == torch.Size([]):
        return 1
    if len(env.batch_size) != 1:
        raise ValueError(
            f"evaluate_episodes: cannot tell the episodes of an environment of batch size {tuple(env.batch_size)} "
            "apart; use a single environment or a SerialEnv / ParallelEnv of single ones (batch size [N])."
        )
    return int(env.batch_size[0])


def _seeded_reset(env: EnvBase, seeds: list[int]) -> None:
    """Seeds copy ``j`` of a batched environment with ``seeds[j]``, as ``set_seed`` seeds a single one (a reset)."""
    try:
        env.reset(list_of_kwargs=[{"seed": s} for s in seeds])
    except TypeError as err:
        raise ValueError(
            "evaluate_episodes: the copies of a batched environment are seeded one by one with "
            "env.reset(list_of_kwargs=[{'seed': s}, ...]) (SerialEnv / ParallelEnv of GymEnv); this one refused: "
            f"{err}"
        ) from err


@torch.no_grad()
def evaluate_episodes(
    env: EnvBase,
    policy: TensorDictModuleBase,
    *,
    episodes: int,
    max_steps: int,
    seed: int,
    deterministic: bool = True,
) -> dict[str, torch.Tensor]:
    """Plays ``episodes`` seeded episodes and returns the paper's metrics of each one.

    Episode ``i`` is seeded with ``seed + i``. A single environment plays them one after the other;
    a batched one (batch size ``[N]``, e.g. :func:`~torchrl_csirl.tasks.make_serial_env` or a
    :class:`~torchrl.envs.ParallelEnv`) ``N`` at a time: copy ``j`` of round ``r`` plays episode
    ``r * N + j``, the rollout runs with ``break_when_any_done=False`` for ``max_steps`` steps, and
    each copy's first episode (up to its first ``done``) is kept (:func:`episode_metrics`). The
    numbers are those of the single environment, episode by episode.

    Args:
        env: a task's environment (:func:`~torchrl_csirl.tasks.make_env`), single or batched.
        policy: the actor.
        episodes: number of episodes.
        max_steps: episode limit (the scenario's ``max_steps``).
        seed: seed of the first episode.
        deterministic: evaluate the deterministic (mode) policy, as the paper does.

    Returns:
        ``accomplish_rate``, ``success``, ``crashed``, ``episode_length``, ``env_return``: one
        float64 tensor of ``episodes`` entries each, in episode order.

    Raises:
        ValueError: for a batch of more than one dimension, or copies that cannot be seeded one by one.

    Examples:
        >>> from torchrl_csirl.tasks import SCENARIOS, make_serial_env
        >>> from torchrl_csirl.modules import make_actor
        >>> spec = SCENARIOS["merge"]
        >>> env = make_serial_env("merge", 2)
        >>> out = evaluate_episodes(env, make_actor(spec.obs_dim, spec.action_dim), episodes=3, max_steps=4, seed=0)
        >>> out["accomplish_rate"].shape, out["episode_length"].max().item() <= 4
        (torch.Size([3]), True)
        >>> env.close()
    """
    if episodes <= 0:
        raise ValueError(f"episodes must be positive, got {episodes}.")
    num_envs = _check_batched(env)
    rows: list[dict[str, torch.Tensor]] = []
    exploration = ExplorationType.DETERMINISTIC if deterministic else ExplorationType.RANDOM
    with set_exploration_type(exploration):
        if num_envs == 1:
            for i in range(episodes):
                env.set_seed(seed + i)
                rows.append(episode_metrics(env.rollout(max_steps, policy, break_when_any_done=True)))
        else:
            for start in range(0, episodes, num_envs):
                _seeded_reset(env, [seed + start + j for j in range(num_envs)])
                rollout = env.rollout(max_steps, policy, break_when_any_done=False)  # resets, as after set_seed
                rows.append(episode_metrics(rollout))
    return {key: torch.cat([row[key].reshape(-1) for row in rows])[:episodes] for key in EPISODE_KEYS}


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
    numbers whatever happened in between. ``env`` may be batched (``SerialEnv`` / ``ParallelEnv``,
    batch size ``[N]``): ``N`` episodes are played at once, with the same numbers
    (:func:`evaluate_episodes`).

    Args:
        env: a task's environment (:func:`~torchrl_csirl.tasks.make_env`), single or batched.
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
        >>> from torchrl_csirl.tasks import SCENARIOS, make_env
        >>> from torchrl_csirl.modules import make_actor
        >>> spec = SCENARIOS["merge"]
        >>> env = make_env("merge")
        >>> out = evaluate_policy(env, make_actor(spec.obs_dim, spec.action_dim), episodes=1,
        ...                       max_steps=5, seed=0)
        >>> 0.0 <= out["accomplish_rate"] <= 1.0
        True
    """
    per_episode = evaluate_episodes(env, policy, episodes=episodes, max_steps=max_steps, seed=seed,
                                    deterministic=deterministic)
    rate = per_episode["accomplish_rate"]
    return {
        "accomplish_rate": float(rate.mean()),
        "accomplish_rate_std": float(rate.std(unbiased=False)),
        "success_rate": float(per_episode["success"].mean()),
        "crash_rate": float(per_episode["crashed"].mean()),
        "episode_length": float(per_episode["episode_length"].mean()),
        "env_return": float(per_episode["env_return"].mean()),
    }
