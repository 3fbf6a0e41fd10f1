"""Expert demonstrations: a TensorDict-backed container and its deterministic ``.npz`` format.

Storage layout (in memory)
--------------------------
:class:`ExpertDemonstrations` stores **flat transitions**: one :class:`~tensordict.TensorDict`
with batch size ``[T]`` (``T`` = total number of transitions over all trajectories), ordered
trajectory by trajectory, with the keys

* ``"observation"`` ``[T, D]`` (float32), ``"action"`` ``[T, A]`` (float32),
* ``("next", "observation")`` ``[T, D]``,
* ``("next", "terminated")``, ``("next", "truncated")``, ``("next", "done")`` ``[T, 1]`` (bool),
  with ``done = terminated | truncated``,
* ``("next", "reward")`` ``[T, 1]`` (float32), only when the source had rewards,
* ``("collector", "traj_ids")`` ``[T]`` (int64): the trajectory index ``0..N-1``.

Trajectories are contiguous, so trajectory ``i`` is the slice
``offsets[i]:offsets[i] + lengths[i]``. This is the layout TorchRL's replay buffers and
slice samplers use (``("collector", "traj_ids")``), and it needs no padding mask.

On-disk format (``.npz``, version 1)
------------------------------------
A zip archive of ``.npy`` members, readable with ``numpy.load(path, allow_pickle=False)``:

========================== ============ ==============================================
member                     dtype        shape / meaning
========================== ============ ==============================================
``format_version``         int64        ``()``: ``1``
``metadata_json``          uint8        UTF-8 JSON (keys sorted) of :attr:`metadata`
``lengths``                int64        ``(N,)`` transitions per trajectory
``observation``            float32      ``(T, D)``
``action``                 float32      ``(T, A)``
``next_observation``       float32      ``(T, D)``
``terminated``             bool         ``(T,)``
``truncated``              bool         ``(T,)``
``done``                   bool         ``(T,)``
``traj_ids``               int64        ``(T,)``
``reward`` (optional)      float32      ``(T,)``
========================== ============ ==============================================

Files are written deterministically: members in sorted order, deflate-compressed, with a fixed
zip timestamp (1980-01-01), so the same content always gives the same bytes (and the same hash).
"""
from __future__ import annotations

import io
import json
import os
import zipfile
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase

__all__ = ["ExpertDemonstrations", "FORMAT_VERSION"]

FORMAT_VERSION = 1
_ZIP_DATE_TIME = (1980, 1, 1, 0, 0, 0)
_REQUIRED_MEMBERS = (
    "format_version",
    "metadata_json",
    "lengths",
    "observation",
    "action",
    "next_observation",
    "terminated",
    "truncated",
    "done",
    "traj_ids",
)
_FLAT_KEYS = {
    "observation": "observation",
    "action": "action",
    "next_observation": ("next", "observation"),
    "terminated": ("next", "terminated"),
    "truncated": ("next", "truncated"),
    "done": ("next", "done"),
    "reward": ("next", "reward"),
    "traj_ids": ("collector", "traj_ids"),
}


#: the float members a demonstration must hold finite
_FINITE_KEYS = ("observation", "action", "next_observation", "reward")


def non_finite_entries(transitions: TensorDictBase) -> str | None:
    """Where flat demonstration ``transitions`` hold NaN or infinite values, as one phrase (None: nowhere).

    Examples:
        >>> td = TensorDict({"observation": torch.zeros(3, 2), "action": torch.tensor([[0.0], [float("nan")], [0.0]]),
        ...                  "next": {"observation": torch.zeros(3, 2)},
        ...                  "collector": {"traj_ids": torch.zeros(3, dtype=torch.int64)}}, [3])
        >>> non_finite_entries(td)
        'action holds 1 non-finite value (NaN or inf), the first at transition 1 (trajectory 0)'
    """
    for name in _FINITE_KEYS:
        key = _FLAT_KEYS[name]
        value = transitions.get(key, None)
        if value is None or not value.is_floating_point():
            continue
        bad = ~torch.isfinite(value.reshape(value.shape[0], -1)).all(-1)
        if bad.any():
            count = int((~torch.isfinite(value)).sum())
            first = int(bad.nonzero()[0, 0])
            trajectory = int(transitions.get(("collector", "traj_ids"))[first])
            return (f"{name} holds {count} non-finite value{'s' if count > 1 else ''} (NaN or inf), the first at "
                    f"transition {first} (trajectory {trajectory})")
    return None


def _as_tensor(value: Any, dtype: torch.dtype, name: str) -> torch.Tensor:
    try:
        tensor = torch.as_tensor(np.asarray(value) if not isinstance(value, torch.Tensor) else value)
    except Exception as err:  # noqa: BLE001 - re-raised with context
        raise TypeError(f"{name} could not be converted to a tensor: {err}") from err
    return tensor.detach().to("cpu", dtype)


def _episode_get(episode: Any, *names: Any) -> Any:
    """Returns the first present entry among ``names`` of a mapping or a TensorDict (or ``None``)."""
    for name in names:
        if isinstance(episode, TensorDictBase):
            value = episode.get(name, None)
        elif isinstance(episode, Mapping):
            if isinstance(name, tuple):
                value = episode.get(name[0], None)
                for sub in name[1:]:
                    value = value.get(sub, None) if isinstance(value, Mapping) else None
                if value is None:
                    value = episode.get(name, None)
            else:
                value = episode.get(name, None)
        else:
            raise TypeError(
                f"episodes must be TensorDicts or mappings of arrays, got {type(episode).__name__}."
            )
        if value is not None:
            return value
    return None


def _flag(value: Any, length: int, name: str, index: int) -> torch.Tensor:
    flag = _as_tensor(value, torch.bool, f"episode {index} {name}").reshape(-1)
    if flag.numel() != length:
        raise ValueError(f"episode {index}: {name} has {flag.numel()} entries, expected {length}.")
    return flag


def _episode_to_td(episode: Any, index: int) -> TensorDict:
    """Normalises one episode (TensorDict or mapping) to the flat transition layout."""
    obs = _episode_get(episode, "observation", "observations", "states")
    act = _episode_get(episode, "action", "actions")
    next_obs = _episode_get(
        episode, ("next", "observation"), "next_observation", "next_observations", "next_states"
    )
    for name, value in (("observation", obs), ("action", act), ("next observation", next_obs)):
        if value is None:
            raise ValueError(f"episode {index} has no {name} entry.")
    obs = _as_tensor(obs, torch.float32, f"episode {index} observation")
    act = _as_tensor(act, torch.float32, f"episode {index} action")
    next_obs = _as_tensor(next_obs, torch.float32, f"episode {index} next observation")
    if obs.ndim != 2 or obs.shape[0] == 0:
        raise ValueError(
            f"episode {index}: observation must have shape [T, D] with T >= 1, got {tuple(obs.shape)}."
        )
    length = obs.shape[0]
    if act.ndim == 1:
        act = act.unsqueeze(-1)
    if act.ndim != 2 or act.shape[0] != length:
        raise ValueError(f"episode {index}: action must have shape [{length}, A], got {tuple(act.shape)}.")
    if next_obs.shape != obs.shape:
        raise ValueError(
            f"episode {index}: next observation shape {tuple(next_obs.shape)} != observation "
            f"shape {tuple(obs.shape)}."
        )
    terminated = _episode_get(episode, ("next", "terminated"), "terminated")
    truncated = _episode_get(episode, ("next", "truncated"), "truncated")
    done = _episode_get(episode, ("next", "done"), "done")
    if terminated is None:
        raise ValueError(f"episode {index} has no terminated entry.")
    terminated = _flag(terminated, length, "terminated", index)
    truncated = (
        torch.zeros(length, dtype=torch.bool)
        if truncated is None
        else _flag(truncated, length, "truncated", index)
    )
    expected_done = terminated | truncated
    if done is not None and not torch.equal(_flag(done, length, "done", index), expected_done):
        raise ValueError(f"episode {index}: done must equal terminated | truncated.")
    td = TensorDict(
        {
            "observation": obs,
            "action": act,
            "next": {
                "observation": next_obs,
                "terminated": terminated.unsqueeze(-1),
                "truncated": truncated.unsqueeze(-1),
                "done": expected_done.unsqueeze(-1),
            },
            "collector": {"traj_ids": torch.full((length,), index, dtype=torch.int64)},
        },
        batch_size=[length],
    )
    reward = _episode_get(episode, ("next", "reward"), "reward", "rewards")
    if reward is not None:
        reward = _as_tensor(reward, torch.float32, f"episode {index} reward").reshape(-1)
        if reward.numel() != length:
            raise ValueError(f"episode {index}: reward has {reward.numel()} entries, expected {length}.")
        td.set(("next", "reward"), reward.unsqueeze(-1))
    return td


def _validate_metadata(metadata: Mapping[str, Any] | None) -> dict[str, Any]:
    metadata = dict(metadata or {})
    try:
        # round trip: only JSON-serialisable metadata can be saved
        metadata = json.loads(json.dumps(metadata, sort_keys=True))
    except (TypeError, ValueError) as err:
        raise TypeError(f"metadata must be JSON-serialisable: {err}") from err
    return metadata


class ExpertDemonstrations:
    """Expert trajectories stored as flat TensorDict transitions (see the module docstring).

    Build one with :meth:`from_episodes` (or :func:`~torchrl_csirl.data.import_published`),
    save it with :meth:`save`, read it back with :meth:`load`.

    Args:
        transitions (TensorDictBase): flat transitions ``[T]`` in the layout of the module
            docstring, trajectories contiguous with ids ``0..N-1`` in order.
        metadata (dict, optional): JSON-serialisable metadata (scenario, seed, generator...).

    Examples:
        >>> import torch
        >>> from torchrl_csirl.data import ExpertDemonstrations
        >>> ep = {"observation": torch.zeros(3, 4), "action": torch.zeros(3, 2),
        ...       "next_observation": torch.ones(3, 4),
        ...       "terminated": torch.tensor([False, False, True])}
        >>> demos = ExpertDemonstrations.from_episodes([ep, ep], metadata={"scenario": "merge"})
        >>> demos.num_trajectories, len(demos), demos.trajectory(1).batch_size
        (2, 6, torch.Size([3]))
        >>> demos.transitions()["collector", "traj_ids"].tolist()
        [0, 0, 0, 1, 1, 1]
    """

    def __init__(
        self, transitions: TensorDictBase, metadata: Mapping[str, Any] | None = None
    ) -> None:
        if not isinstance(transitions, TensorDictBase):
            raise TypeError(f"transitions must be a TensorDict, got {type(transitions).__name__}.")
        if transitions.batch_dims != 1 or transitions.numel() == 0:
            raise ValueError(
                f"transitions must be a non-empty flat TensorDict [T], got batch size "
                f"{tuple(transitions.batch_size)}."
            )
        missing = [k for k in _FLAT_KEYS.values() if k != ("next", "reward") and k not in transitions.keys(True)]
        if missing:
            raise ValueError(f"transitions lack the keys {missing}.")
        traj_ids = transitions.get(("collector", "traj_ids")).to(torch.int64)
        ids, counts = torch.unique_consecutive(traj_ids, return_counts=True)
        if not torch.equal(ids, torch.arange(ids.numel())):
            raise ValueError(
                "trajectory ids must be contiguous blocks numbered 0..N-1 in order, got "
                f"{ids.tolist()[:10]}..."
            )
        non_finite = non_finite_entries(transitions)
        if non_finite is not None:
            raise ValueError(f"demonstrations with non-finite values: {non_finite}.")
        self._transitions = transitions
        self._lengths = counts.to(torch.int64)
        self._offsets = torch.cat([torch.zeros(1, dtype=torch.int64), self._lengths.cumsum(0)[:-1]])
        self._metadata = _validate_metadata(metadata)

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_episodes(
        cls, episodes: Sequence[Any], metadata: Mapping[str, Any] | None = None
    ) -> ExpertDemonstrations:
        """Builds the container from a sequence of episodes.

        Each episode is a TensorDict ``[T_i]`` as returned by ``env.rollout`` (keys
        ``"observation"``, ``"action"``, ``("next", "observation")``, ``("next", "terminated")``,
        optional ``("next", "truncated")``, ``("next", "done")``, ``("next", "reward")``), or a
        mapping of arrays with keys ``observation``, ``action``, ``next_observation``,
        ``terminated``, optional ``truncated``, ``done``, ``reward``. Missing ``truncated`` means
        ``False``; ``done`` is recomputed as ``terminated | truncated`` (and checked if given).

        Args:
            episodes (sequence): the episodes, in order.
            metadata (dict, optional): JSON-serialisable metadata.

        Returns:
            ExpertDemonstrations: the container.
        """
        episodes = list(episodes)
        if not episodes:
            raise ValueError("from_episodes needs at least one episode.")
        tds = [_episode_to_td(ep, i) for i, ep in enumerate(episodes)]
        dims = {(td["observation"].shape[-1], td["action"].shape[-1]) for td in tds}
        if len(dims) != 1:
            raise ValueError(f"all episodes must share observation/action sizes, got {sorted(dims)}.")
        with_reward = {("next", "reward") in td.keys(True) for td in tds}
        if len(with_reward) != 1:
            raise ValueError("either all episodes or none must carry a reward.")
        return cls(torch.cat(tds, 0), metadata)

    # ------------------------------------------------------------------ accessors
    @property
    def metadata(self) -> dict[str, Any]:
        """dict: JSON-serialisable metadata (a copy; use :meth:`with_metadata` to change it)."""
        return json.loads(json.dumps(self._metadata))

    def with_metadata(self, **updates: Any) -> ExpertDemonstrations:
        """Returns a container sharing the transitions, with ``metadata`` updated by ``updates``."""
        return ExpertDemonstrations(self._transitions, {**self._metadata, **updates})

    @property
    def num_trajectories(self) -> int:
        """int: the number of trajectories ``N``."""
        return int(self._lengths.numel())

    @property
    def lengths(self) -> torch.Tensor:
        """torch.Tensor: ``(N,)`` number of transitions of each trajectory."""
        return self._lengths.clone()

    @property
    def observation_dim(self) -> int:
        """int: observation size ``D``."""
        return int(self._transitions["observation"].shape[-1])

    @property
    def action_dim(self) -> int:
        """int: action size ``A``."""
        return int(self._transitions["action"].shape[-1])

    def __len__(self) -> int:
        return int(self._transitions.numel())

    def __repr__(self) -> str:
        return (
            f"{type(self).__name__}(num_trajectories={self.num_trajectories}, "
            f"num_transitions={len(self)}, observation_dim={self.observation_dim}, "
            f"action_dim={self.action_dim}, metadata={self._metadata})"
        )

    def transitions(self) -> TensorDictBase:
        """Returns all transitions as one flat TensorDict ``[T]`` (a clone)."""
        return self._transitions.clone()

    def trajectory(self, index: int) -> TensorDictBase:
        """Returns trajectory ``index`` as a TensorDict ``[L_i]`` (a clone; negative indices allowed)."""
        n = self.num_trajectories
        if not isinstance(index, int) or isinstance(index, bool):
            raise TypeError(f"trajectory index must be an int, got {type(index).__name__}.")
        if not -n <= index < n:
            raise IndexError(f"trajectory index {index} out of range for {n} trajectories.")
        index %= n
        start = int(self._offsets[index])
        return self._transitions[start : start + int(self._lengths[index])].clone()

    def trajectory_observations(self, index: int = 0, include_final: bool = False) -> torch.Tensor:
        """The states ``s_0..s_{L-1}`` of trajectory ``index``, shape ``[L, D]``.

        Args:
            index (int): trajectory index. Defaults to ``0`` (the curriculum trajectory).
            include_final (bool): append the last next-observation (so ``L`` = transitions + 1).
                Defaults to ``False`` (the published code uses the recorded states only).
        """
        traj = self.trajectory(index)
        obs = traj["observation"]
        if include_final:
            obs = torch.cat([obs, traj["next", "observation"][-1:]], 0)
        return obs

    def subset(self, n: int) -> ExpertDemonstrations:
        """Returns the first ``n`` trajectories (``1 <= n <= num_trajectories``)."""
        if not isinstance(n, int) or isinstance(n, bool):
            raise TypeError(f"n must be an int, got {type(n).__name__}.")
        if not 1 <= n <= self.num_trajectories:
            raise ValueError(f"n must be in [1, {self.num_trajectories}], got {n}.")
        end = int(self._offsets[n - 1] + self._lengths[n - 1])
        return ExpertDemonstrations(
            self._transitions[:end].clone(), {**self._metadata, "num_trajectories": n}
        )

    def as_replay_buffer(
        self, batch_size: int, *, device: torch.device | str | None = None, **kwargs: Any
    ):
        """A :class:`~torchrl.data.TensorDictReplayBuffer` holding all transitions.

        Args:
            batch_size (int): the sampling batch size (CSIRL uses 32 expert pairs).
            device (torch.device, optional): storage device. Defaults to CPU.
            **kwargs: forwarded to :class:`~torchrl.data.TensorDictReplayBuffer`
                (e.g. ``sampler``, ``transform``).

        Examples:
            >>> import torch
            >>> from torchrl_csirl.data import ExpertDemonstrations
            >>> ep = {"observation": torch.zeros(5, 4), "action": torch.zeros(5, 2),
            ...       "next_observation": torch.ones(5, 4), "terminated": torch.zeros(5, dtype=torch.bool)}
            >>> rb = ExpertDemonstrations.from_episodes([ep]).as_replay_buffer(batch_size=3)
            >>> rb.sample().batch_size
            torch.Size([3])
        """
        from torchrl.data import TensorDictReplayBuffer, TensorStorage

        if not isinstance(batch_size, int) or batch_size <= 0:
            raise ValueError(f"batch_size must be a positive int, got {batch_size!r}.")
        device = torch.device("cpu" if device is None else device)
        data = self._transitions.clone().to(device)
        # a pre-filled storage: full from the start, no writes needed
        storage = TensorStorage(data, max_size=len(self), device=device)
        return TensorDictReplayBuffer(storage=storage, batch_size=batch_size, **kwargs)

    # ------------------------------------------------------------------ I/O
    def _arrays(self) -> dict[str, np.ndarray]:
        td = self._transitions
        arrays = {
            "format_version": np.asarray(FORMAT_VERSION, dtype=np.int64),
            "metadata_json": np.frombuffer(
                json.dumps(self._metadata, sort_keys=True, separators=(",", ":")).encode("utf-8"),
                dtype=np.uint8,
            ).copy(),
            "lengths": self._lengths.numpy().astype(np.int64),
        }
        for name, key in _FLAT_KEYS.items():
            if key not in td.keys(True):
                continue
            value = td.get(key).numpy()
            if name in ("terminated", "truncated", "done"):
                value = value.reshape(-1).astype(np.bool_)
            elif name == "reward":
                value = value.reshape(-1).astype(np.float32)
            elif name == "traj_ids":
                value = value.astype(np.int64)
            else:
                value = value.astype(np.float32)
            arrays[name] = np.ascontiguousarray(value)
        return arrays

    def save(self, path: str | os.PathLike) -> str:
        """Writes the ``.npz`` file (deterministic bytes; see the module docstring).

        Args:
            path (path-like): destination; ``.npz`` is appended if missing.

        Returns:
            str: the path written.
        """
        path = os.fspath(path)
        if not path.endswith(".npz"):
            path = path + ".npz"
        parent = os.path.dirname(path)
        if parent:
            os.makedirs(parent, exist_ok=True)
        tmp = path + ".tmp"
        with zipfile.ZipFile(tmp, mode="w", compression=zipfile.ZIP_DEFLATED) as zf:
            for name, array in sorted(self._arrays().items()):
                buffer = io.BytesIO()
                np.lib.format.write_array(buffer, array, allow_pickle=False)
                info = zipfile.ZipInfo(name + ".npy", date_time=_ZIP_DATE_TIME)
                info.compress_type = zipfile.ZIP_DEFLATED
                info.external_attr = 0o644 << 16
                zf.writestr(info, buffer.getvalue(), compresslevel=6)
        os.replace(tmp, path)
        return path

    @classmethod
    def load(cls, path: str | os.PathLike) -> ExpertDemonstrations:
        """Reads a file written by :meth:`save` (``numpy.load(..., allow_pickle=False)``).

        Raises:
            ValueError: on a missing member, an unknown format version, inconsistent shapes or non-finite
                values (naming the file and the member).
        """
        path = os.fspath(path)
        with np.load(path, allow_pickle=False) as npz:
            arrays = {name: npz[name] for name in npz.files}
        missing = [name for name in _REQUIRED_MEMBERS if name not in arrays]
        if missing:
            raise ValueError(f"{path}: not an expert-demonstration file, missing members {missing}.")
        version = int(arrays["format_version"])
        if version != FORMAT_VERSION:
            raise ValueError(f"{path}: unsupported format version {version} (expected {FORMAT_VERSION}).")
        metadata = json.loads(arrays["metadata_json"].tobytes().decode("utf-8"))
        num = arrays["observation"].shape[0]
        for name in _FLAT_KEYS:
            if name in arrays and arrays[name].shape[0] != num:
                raise ValueError(f"{path}: member {name} has {arrays[name].shape[0]} rows, expected {num}.")
        if int(arrays["lengths"].sum()) != num:
            raise ValueError(f"{path}: lengths sum to {int(arrays['lengths'].sum())}, expected {num}.")
        flags = {
            name: torch.from_numpy(arrays[name].astype(np.bool_)).reshape(-1, 1)
            for name in ("terminated", "truncated", "done")
        }
        td = TensorDict(
            {
                "observation": torch.from_numpy(arrays["observation"].astype(np.float32)),
                "action": torch.from_numpy(arrays["action"].astype(np.float32)),
                "next": {
                    "observation": torch.from_numpy(arrays["next_observation"].astype(np.float32)),
                    **flags,
                },
                "collector": {"traj_ids": torch.from_numpy(arrays["traj_ids"].astype(np.int64))},
            },
            batch_size=[num],
        )
        if "reward" in arrays:
            td.set(("next", "reward"), torch.from_numpy(arrays["reward"].astype(np.float32)).reshape(-1, 1))
        non_finite = non_finite_entries(td)
        if non_finite is not None:
            raise ValueError(f"{path}: {non_finite}.")
        demos = cls(td, metadata)
        if not np.array_equal(demos._lengths.numpy(), arrays["lengths"]):
            raise ValueError(f"{path}: lengths do not match the trajectory ids.")
        return demos

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, ExpertDemonstrations):
            return NotImplemented
        return (
            self._metadata == other._metadata
            and set(self._transitions.keys(True, True)) == set(other._transitions.keys(True, True))
            and bool((self._transitions == other._transitions).all())
        )

    __hash__ = None  # type: ignore[assignment]
