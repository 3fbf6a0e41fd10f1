"""Minari interop: our :class:`ExpertDemonstrations` as a local Minari dataset, and back.

Minari (the format D4RL's successors use) stores a dataset under
``<MINARI_DATASETS_PATH>/<dataset_id>/`` (``metadata.json`` and ``data/main_data.hdf5``, one
group ``episode_<i>`` per episode with ``observations`` ``[T + 1, D]``, ``actions``,
``rewards``, ``terminations``, ``truncations`` ``[T]``). Everything here is local: no network.

* :func:`save_minari_dataset`: write demonstrations as a local Minari dataset (hdf5), readable
  by ``minari.load_dataset`` and by TorchRL's
  ``MinariExperienceReplay(dataset_id, batch_size, load_from_local_minari=True)``;
* :func:`load_minari_dataset`: read a local Minari dataset (ours or e.g. a D4RL successor's;
  dict observations are flattened, AntMaze's as ``observation`` + ``achieved_goal``) into
  :class:`ExpertDemonstrations`, checked against a task's dimensions;
* :func:`minari_experience_replay`: TorchRL's ``MinariExperienceReplay`` on a local dataset,
  with the same dimension check (and the transitions TorchRL 0.14.1 drops written back, see
  :func:`_restore_minari_contents`).

Examples:
    >>> import tempfile
    >>> from torchrl_csirl.data import load_expert_demonstrations
    >>> demos = load_expert_demonstrations("merge", 1)
    >>> root = tempfile.mkdtemp()
    >>> _ = save_minari_dataset(demos, "csirl/merge/expert-v0", root=root, task="merge")
    >>> load_minari_dataset("csirl/merge/expert-v0", root=root, task="merge") == demos
    True
"""
from __future__ import annotations

import contextlib
import json
import os
import shutil
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np
import torch
from tensordict import TensorDict

from torchrl_csirl.data.expert import ExpertDemonstrations

__all__ = ["load_minari_dataset", "minari_experience_replay", "save_minari_dataset"]

_METADATA_KEY = "csirl_metadata"
#: dict observations flattened in this order when present (AntMaze: the 29-dim state)
DEFAULT_OBSERVATION_KEYS: tuple[str, ...] = ("observation", "achieved_goal")


@contextlib.contextmanager
def _minari_root(root: str | os.PathLike | None) -> Iterator[None]:
    """Point ``MINARI_DATASETS_PATH`` at ``root`` for the duration (``None``: leave it)."""
    if root is None:
        yield
        return
    previous = os.environ.get("MINARI_DATASETS_PATH")
    os.environ["MINARI_DATASETS_PATH"] = os.fspath(root)
    try:
        yield
    finally:
        if previous is None:
            os.environ.pop("MINARI_DATASETS_PATH", None)
        else:
            os.environ["MINARI_DATASETS_PATH"] = previous


def _task_dims(task: Any) -> tuple[str, int, int]:
    from torchrl_csirl.tasks import resolve_scenario

    spec = resolve_scenario(task)
    return spec.name, spec.obs_dim, spec.action_dim


def check_dimensions(observation_dim: int, action_dim: int, task: Any, source: str) -> None:
    """Raise one clear ``ValueError`` when a dataset's dimensions are not the task's.

    Examples:
        >>> check_dimensions(39, 30, "relocate", "my dataset")
        >>> check_dimensions(29, 8, "relocate", "my dataset")
        Traceback (most recent call last):
        ...
        ValueError: my dataset has observations of size 29 and actions of size 8, but task 'relocate' has 39 and 30.
    """
    name, obs_dim, act_dim = _task_dims(task)
    if (observation_dim, action_dim) != (obs_dim, act_dim):
        raise ValueError(
            f"{source} has observations of size {observation_dim} and actions of size {action_dim}, "
            f"but task {name!r} has {obs_dim} and {act_dim}."
        )


def _episode_buffers(demos: ExpertDemonstrations) -> list:
    from minari.data_collector import EpisodeBuffer

    seeds = [e.get("seed") for e in demos.metadata.get("episodes", [])]
    buffers = []
    for i in range(demos.num_trajectories):
        traj = demos.trajectory(i)
        obs = traj["observation"].numpy()
        next_obs = traj["next", "observation"].numpy()
        if obs.shape[0] > 1 and not np.array_equal(obs[1:], next_obs[:-1]):
            raise ValueError(
                f"trajectory {i}: next observations are not the following observations; a Minari "
                "episode stores one observation sequence and cannot represent it."
            )
        reward = traj.get(("next", "reward"), None)
        rewards = np.zeros(obs.shape[0], np.float32) if reward is None else reward.reshape(-1).numpy()
        seed = seeds[i] if i < len(seeds) and isinstance(seeds[i], int) else None
        buffers.append(
            EpisodeBuffer(
                id=i,
                seed=seed,
                observations=np.concatenate([obs, next_obs[-1:]]),
                actions=traj["action"].numpy(),
                rewards=rewards,
                terminations=traj["next", "terminated"].reshape(-1).numpy(),
                truncations=traj["next", "truncated"].reshape(-1).numpy(),
                infos={},
            )
        )
    return buffers


def save_minari_dataset(
    demos: ExpertDemonstrations,
    dataset_id: str,
    root: str | os.PathLike | None = None,
    task: Any | None = None,
    overwrite: bool = False,
    description: str | None = None,
    author: str = "torchrl-csirl",
) -> str:
    """Write demonstrations as a local Minari dataset (hdf5 format).

    Args:
        demos: the demonstrations; trajectory ``i`` becomes ``episode_i`` (with its reset seed
            when the metadata records one). Without rewards, rewards of 0 are written.
        dataset_id: Minari id, ``(namespace/)(env_name/)name-v<version>``.
        root: datasets folder (``MINARI_DATASETS_PATH``; default: Minari's, ``~/.minari/datasets``).
        task: the task the data belongs to (name or spec): its dimensions are checked and the
            dataset records the task's gymnasium id (``dataset.recover_environment()`` then
            builds it, with ``torchrl_csirl`` installed).
        overwrite: replace an existing dataset of that id (else Minari refuses).
        description: the dataset's description (default: one line from the metadata).
        author: the dataset's author.

    Returns:
        the dataset's folder.
    """
    import gymnasium as gym
    import minari

    if demos.num_trajectories == 0:
        raise ValueError("no trajectory to write.")
    env_spec = None
    if task is not None:
        check_dimensions(demos.observation_dim, demos.action_dim, task, "the demonstrations")
        from torchrl_csirl.tasks import resolve_scenario
        from torchrl_csirl.tasks.catalog import register_scenarios

        register_scenarios()
        env_spec = _task_env_spec(resolve_scenario(task))
    observation_space = gym.spaces.Box(-np.inf, np.inf, (demos.observation_dim,), np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, (demos.action_dim,), np.float32)
    with _minari_root(root):
        from minari.storage import get_dataset_path

        path = get_dataset_path(dataset_id)
        if overwrite and os.path.exists(path):
            shutil.rmtree(path)
        dataset = minari.create_dataset_from_buffers(
            dataset_id=dataset_id,
            buffer=_episode_buffers(demos),
            env=env_spec,
            algorithm_name=str(demos.metadata.get("generator", "expert")),
            author=author,
            action_space=action_space,
            observation_space=observation_space,
            description=description
            or f"torchrl-csirl expert demonstrations ({demos.metadata.get('scenario', 'unknown task')})",
            data_format="hdf5",
        )
        dataset.storage.update_metadata({_METADATA_KEY: json.dumps(demos.metadata, sort_keys=True)})
    return os.fspath(path)


def _task_env_spec(spec: Any) -> Any:
    """The gymnasium ``EnvSpec`` a dataset of ``spec``'s task records (``recover_environment()`` builds it): the
    task's own id; a locomotion task's gymnasium id with x kept in the observation; a gymnasium id run as a task;
    None for a task of one's own (registered with its factory only: the dataset then records no environment)."""
    import dataclasses

    import gymnasium as gym

    from torchrl_csirl.tasks.locomotion import LOCOMOTION_GYM_IDS, LOCOMOTION_MAKE_KWARGS

    if spec.gym_id:
        return gym.spec(spec.gym_id)
    if spec.name in LOCOMOTION_GYM_IDS:
        base = gym.spec(LOCOMOTION_GYM_IDS[spec.name])
        return dataclasses.replace(base, kwargs={**base.kwargs, **LOCOMOTION_MAKE_KWARGS})
    if spec.family == "gymnasium" and spec.name in gym.registry:
        return gym.spec(spec.name)
    return None


def _flat_observations(observations: Any, keys: Sequence[str], episode: int) -> np.ndarray:
    if isinstance(observations, dict):
        missing = [k for k in keys if k not in observations]
        if missing:
            raise ValueError(
                f"episode {episode}: dict observations have keys {sorted(observations)}, missing {missing}; "
                "pass observation_keys=..."
            )
        parts = [np.asarray(observations[k]).reshape(len(observations[k]), -1) for k in keys]
        return np.concatenate(parts, axis=1)
    obs = np.asarray(observations)
    return obs.reshape(obs.shape[0], -1)


def load_minari_dataset(
    dataset_id: str,
    root: str | os.PathLike | None = None,
    task: Any | None = None,
    observation_keys: Sequence[str] = DEFAULT_OBSERVATION_KEYS,
) -> ExpertDemonstrations:
    """Read a local Minari dataset into :class:`ExpertDemonstrations`.

    Args:
        dataset_id: the dataset's Minari id.
        root: datasets folder (``MINARI_DATASETS_PATH``; default: Minari's).
        task: when given, the dataset's observation and action sizes must be the task's
            (one ``ValueError`` naming both otherwise).
        observation_keys: for dict observations (goal-conditioned datasets such as AntMaze's),
            the entries concatenated into the flat observation, in order.

    Returns:
        the demonstrations (float32); the metadata is ours when the dataset was written by
        :func:`save_minari_dataset`, else ``{"source": "minari", "dataset_id": ...}``.
    """
    import minari

    with _minari_root(root):
        dataset = minari.load_dataset(dataset_id)
        raw_metadata = dataset.storage.metadata
        episodes = []
        for i, episode in enumerate(dataset.iterate_episodes()):
            obs = _flat_observations(episode.observations, observation_keys, i)
            episodes.append(
                {
                    "observation": obs[:-1],
                    "next_observation": obs[1:],
                    "action": np.asarray(episode.actions).reshape(len(episode.actions), -1),
                    "reward": np.asarray(episode.rewards),
                    "terminated": np.asarray(episode.terminations),
                    "truncated": np.asarray(episode.truncations),
                }
            )
    if not episodes:
        raise ValueError(f"Minari dataset {dataset_id!r} has no episode.")
    if task is not None:
        check_dimensions(
            episodes[0]["observation"].shape[1], episodes[0]["action"].shape[1], task, f"Minari dataset {dataset_id!r}"
        )
    stored = raw_metadata.get(_METADATA_KEY)
    metadata = json.loads(stored) if isinstance(stored, str) else {"source": "minari", "dataset_id": dataset_id}
    return ExpertDemonstrations.from_episodes(episodes, metadata=metadata)


def minari_experience_replay(
    dataset_id: str,
    batch_size: int,
    root: str | os.PathLike | None = None,
    torchrl_root: str | os.PathLike | None = None,
    task: Any | None = None,
    observation_keys: Sequence[str] = DEFAULT_OBSERVATION_KEYS,
    **kwargs: Any,
):
    """TorchRL's ``MinariExperienceReplay`` on a local Minari dataset (``load_from_local_minari``).

    Args:
        dataset_id: the dataset's Minari id.
        batch_size: the replay buffer's sample size.
        root: Minari datasets folder holding ``<dataset_id>`` (default: ``MINARI_DATASETS_PATH``
            or Minari's default).
        torchrl_root: where TorchRL keeps its memory-mapped copy (``MinariExperienceReplay``'s
            ``root``; default: TorchRL's cache, ``~/.cache/torchrl/minari``). The copy is rebuilt
            on every call (``download="force"``) so that a rewritten dataset is never read stale.
        task: when given, the dataset's observation and action sizes must be the task's.
        observation_keys: for dict observations, the entries that make the task's state (the
            buffer keeps them nested, as TorchRL stores them: ``("observation", key)``).
        **kwargs: other ``MinariExperienceReplay`` arguments (``sampler``, ``transform``, ...).

    Returns:
        the replay buffer (keys ``"observation"``, ``"action"``, ``("next", "observation")``,
        ``("next", "reward")``, ``("next", "done")``, ``"episode"``, ...).
    """
    import minari
    from torchrl.data.datasets.minari_data import MinariExperienceReplay

    kwargs.setdefault("download", "force")
    with _minari_root(root):
        dataset = minari.load_dataset(dataset_id)
        if task is not None:
            obs_dim = observation_size(dataset.observation_space, observation_keys)
            check_dimensions(obs_dim, int(gym_flatdim(dataset.action_space)), task, f"Minari dataset {dataset_id!r}")
        if dataset.total_episodes < 2:
            raise ValueError(
                f"Minari dataset {dataset_id!r} has {dataset.total_episodes} episode; TorchRL 0.14.1's "
                "MinariExperienceReplay needs at least 2 (it takes max(*episode numbers)). Use "
                "load_minari_dataset(...).as_replay_buffer(...) instead."
            )
        buffer = MinariExperienceReplay(
            dataset_id,
            batch_size,
            root=None if torchrl_root is None else os.fspath(torchrl_root),
            load_from_local_minari=True,
            **kwargs,
        )
        _restore_minari_contents(buffer, dataset)
    return buffer


def _episode_transitions(episode: Any) -> TensorDict:
    """One Minari episode in TorchRL's layout (what ``MinariExperienceReplay`` stores)."""

    def as_data(value: Any) -> torch.Tensor | TensorDict:
        if isinstance(value, dict):
            return TensorDict({k: as_data(v) for k, v in value.items()}, batch_size=[len(next(iter(value.values())))])
        return torch.as_tensor(np.asarray(value))

    obs = as_data(episode.observations)
    steps = len(episode.actions)
    terminated = torch.as_tensor(np.asarray(episode.terminations)).reshape(steps, 1)
    truncated = torch.as_tensor(np.asarray(episode.truncations)).reshape(steps, 1)
    return TensorDict(
        {
            "observation": obs[:-1],
            "action": as_data(episode.actions),
            "episode": torch.full((steps,), int(episode.id), dtype=torch.int64),
            "next": {
                "observation": obs[1:],
                "reward": torch.as_tensor(np.asarray(episode.rewards)).reshape(steps, 1),
                "terminated": terminated,
                "truncated": truncated,
                "done": terminated | truncated,
            },
        },
        batch_size=[steps],
    )


def _restore_minari_contents(buffer: Any, dataset: Any) -> None:
    """Write the dataset's transitions into a ``MinariExperienceReplay``'s storage where they are missing.

    TorchRL 0.14.1's ``MinariExperienceReplay`` fills an in-memory TensorDict, then keeps
    ``td_data.memmap_like(...)``, a *contentless* copy: every entry reads 0
    (``tests/test_robotics.py`` pins this). The storage has the right keys, shapes and order
    (episodes by number, steps in order), so the transitions are written back through the
    public ``Storage.set``; nothing is done when the stored actions are already the dataset's.
    """
    ours = torch.cat([_episode_transitions(ep) for ep in dataset.iterate_episodes()])
    storage = buffer.storage
    stored = storage[:]
    if stored.batch_size != ours.batch_size:
        raise ValueError(
            f"MinariExperienceReplay holds {stored.batch_size[0]} transitions, the dataset {ours.batch_size[0]}."
        )
    if torch.equal(stored["action"], ours["action"].to(stored["action"].dtype)):
        return
    fixed = stored.clone()
    for key in stored.keys(True, True):
        if key in ours.keys(True, True):
            target = stored.get(key)
            fixed.set(key, ours.get(key).to(target.dtype).reshape(target.shape))
    storage.set(torch.arange(len(fixed)), fixed)


def observation_size(space: Any, keys: Sequence[str] = DEFAULT_OBSERVATION_KEYS) -> int:
    """Size of the flat observation made from a space (a Dict: its ``keys`` entries).

    Examples:
        >>> import gymnasium as gym
        >>> box = lambda n: gym.spaces.Box(-1, 1, (n,))
        >>> observation_size(gym.spaces.Dict({"observation": box(27), "achieved_goal": box(2), "desired_goal": box(2)}))
        29
    """
    from gymnasium.spaces import Dict

    if isinstance(space, Dict):
        missing = [k for k in keys if k not in space.spaces]
        if missing:
            raise ValueError(f"dict observations have keys {sorted(space.spaces)}, missing {missing}.")
        return sum(gym_flatdim(space.spaces[k]) for k in keys)
    return gym_flatdim(space)


def gym_flatdim(space: Any) -> int:
    """Size of a gymnasium space once flattened (Box, Dict of Boxes).

    Examples:
        >>> import gymnasium as gym
        >>> gym_flatdim(gym.spaces.Dict({"a": gym.spaces.Box(0, 1, (3,)), "b": gym.spaces.Box(0, 1, (2,))}))
        5
    """
    from gymnasium.spaces import flatdim

    return int(flatdim(space))
