"""Importer for the published CSIRL / IQ-Learn expert files (pickled dict saved with numpy).

The published layout (SPEC section 3) is a dict saved with ``numpy.save`` (so a ``.npy`` file
holding a pickled 0-d object array), with arrays of shape ``(N, L, ...)`` padded to ``L``:

* ``states``, ``next_states``: ``(N, L, D)``;
* ``actions``: ``(N, L, A)``, normalised to ``[-1, 1]``;
* ``rewards`` (optional here): ``(N, L)`` or ``(N, L, 1)``;
* ``dones``: ``(N, L)`` or ``(N, L, 1)``;
* ``lengths``: ``(N,)`` (a plain list in the published files), the number of recorded steps of
  each trajectory (``1 <= length <= L``);
* any other key (the published files sometimes carry ``d_actions``) is ignored and listed in
  ``metadata["ignored_keys"]``.

The pickle is read with a **restricted unpickler** that only reconstructs plain containers and
numpy arrays/dtypes/scalars: any other global (``os.system``, ``builtins.eval``, ...) is refused
with :class:`pickle.UnpicklingError`, so no code from the file is ever executed.

What the published files look like (see ``docs/experts.md``): every trajectory is recorded for
the full padded width ``L`` (``lengths`` = ``L``), and ``dones`` is True on the **last five
steps of every trajectory** whatever happened (padding of the recorder); some roundabout
trajectories also carry an earlier ``done`` (the ego left the road and the recorder went on).
So a ``done`` before the last step is normal. Where a trajectory ends is chosen by ``end_at``:

* ``"recording"`` (default): the whole recording, ``lengths[i]`` steps. The trailing run of
  ``dones`` is read as the end of the recording, earlier ``dones`` are kept in the data and listed
  in ``metadata["early_dones"]`` as ``[trajectory, step]`` pairs;
* ``"first_done"``: cut each trajectory after its first ``done`` (for the published files the
  first padding step, or the earlier off-road ``done``);
* ``"termination"``: cut where our scenario's environment would end the episode (needs
  ``scenario``): after a ``done`` recorded before the trailing run (crash, off-road), after the
  first step whose next state passes the scene's termination (merge: x > 370 m; intersection:
  arrival on the exit lane; roundabout: at the finish; highway-fast: x >= 650 m), or at the
  scenario's time limit; otherwise at the end of the recording.

Mapping of the last kept step to ``terminated`` / ``truncated``: with ``end_at="termination"``
the step is terminated when the cut is a termination of our scene, truncated otherwise. With the
other two, ``done_mapping="full_length"`` (default) reads a ``done`` on the last kept step as
**terminated** when the trajectory is shorter than ``max_episode_steps`` (default: the padded
width ``L``), as **truncated** otherwise (a full-width recording ended; so every trajectory of a
published file ends truncated by default); a last step without ``done`` is truncated.
``done_mapping="terminated"`` reads a ``done`` on the last kept step as termination (the
published code's view).
"""
from __future__ import annotations

import io
import os
import pickle
from typing import Any

import numpy as np
import torch

from torchrl_csirl.data.expert import ExpertDemonstrations

__all__ = ["END_AT", "import_published", "load_published_dict", "RestrictedUnpickler"]

_REQUIRED_KEYS = ("states", "next_states", "actions", "dones", "lengths")
_KNOWN_KEYS = (*_REQUIRED_KEYS, "rewards")
_DONE_MAPPINGS = ("full_length", "terminated")
END_AT = ("recording", "first_done", "termination")
"""Where :func:`import_published` ends each trajectory (see the module docstring)."""


def _numpy_global(module: str, name: str) -> Any:
    import importlib

    for candidate in (module, module.replace("numpy.core", "numpy._core", 1)):
        try:
            return getattr(importlib.import_module(candidate), name)
        except (ImportError, AttributeError):
            continue
    raise pickle.UnpicklingError(f"cannot resolve allowed global {module}.{name}")


class RestrictedUnpickler(pickle.Unpickler):
    """An unpickler that only rebuilds dicts, lists, tuples, scalars and numpy arrays.

    Every ``GLOBAL`` lookup outside a small allow-list of numpy reconstruction helpers raises
    :class:`pickle.UnpicklingError`, so ``__reduce__`` payloads cannot call arbitrary code.

    Examples:
        >>> import io, pickle, numpy as np
        >>> data = pickle.dumps({"x": np.arange(3)})
        >>> RestrictedUnpickler(io.BytesIO(data)).load()["x"].tolist()
        [0, 1, 2]
    """

    _ALLOWED = {
        ("numpy", "ndarray"),
        ("numpy", "dtype"),
        ("numpy._core.multiarray", "_reconstruct"),
        ("numpy.core.multiarray", "_reconstruct"),
        ("numpy._core.multiarray", "scalar"),
        ("numpy.core.multiarray", "scalar"),
        ("numpy._core.numeric", "_frombuffer"),
        ("numpy.core.numeric", "_frombuffer"),
        ("collections", "OrderedDict"),
    }

    def find_class(self, module: str, name: str) -> Any:
        if (module, name) not in self._ALLOWED:
            raise pickle.UnpicklingError(
                f"refusing to load global {module}.{name}: only plain containers and numpy "
                "arrays are allowed in expert files."
            )
        if module == "collections":
            import collections

            return collections.OrderedDict
        return _numpy_global(module, name)


def load_published_dict(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Reads the raw dict of a published file without executing code from it.

    Accepts a ``numpy.save``'d pickled dict (``.npy``), a raw pickle of a dict, or an ``.npz``.

    Raises:
        pickle.UnpicklingError: the pickle references a forbidden global.
        ValueError: the file does not hold a dict.
    """
    path = os.fspath(path)
    with open(path, "rb") as f:
        head = f.read(6)
        f.seek(0)
        if head == b"\x93NUMPY":
            version = np.lib.format.read_magic(f)
            if version == (1, 0):
                shape, _, dtype = np.lib.format.read_array_header_1_0(f)
            else:
                shape, _, dtype = np.lib.format.read_array_header_2_0(f)
            if dtype != np.dtype(object):
                raise ValueError(
                    f"{path}: expected a pickled dict saved with numpy, found a plain {dtype} array "
                    f"of shape {shape}."
                )
            obj = RestrictedUnpickler(io.BytesIO(f.read())).load()
        elif head[:2] == b"PK":
            with np.load(path, allow_pickle=False) as npz:
                obj = {name: npz[name] for name in npz.files}
        else:
            obj = RestrictedUnpickler(f).load()
    if isinstance(obj, np.ndarray) and obj.dtype == object and obj.shape == ():
        obj = obj.item()
    if not isinstance(obj, dict):
        raise ValueError(f"{path}: expected a dict of arrays, found {type(obj).__name__}.")
    return obj


def _array(data: dict[str, Any], key: str, path: str) -> np.ndarray:
    try:
        array = np.asarray(data[key])
    except Exception as err:  # noqa: BLE001
        raise ValueError(f"{path}: entry {key!r} is not an array: {err}") from err
    if array.dtype == object:
        try:
            array = np.stack([np.asarray(x, dtype=np.float64) for x in data[key]])
        except Exception as err:  # noqa: BLE001
            raise ValueError(f"{path}: entry {key!r} is not a numeric array.") from err
    if not (np.issubdtype(array.dtype, np.number) or array.dtype == np.bool_):
        raise ValueError(f"{path}: entry {key!r} has non-numeric dtype {array.dtype}.")
    return array


def _per_step(array: np.ndarray, key: str, n: int, length: int, path: str) -> np.ndarray:
    if array.ndim == 3 and array.shape[-1] == 1:
        array = array[..., 0]
    if array.shape != (n, length):
        raise ValueError(f"{path}: {key!r} must have shape ({n}, {length}) or ({n}, {length}, 1), got {array.shape}.")
    return array


def _trailing_run_start(done: np.ndarray) -> int:
    """Index where the run of ``done`` steps ending at the last step starts (``len`` if none).

    Examples:
        >>> _trailing_run_start(np.array([0, 1, 0, 1, 1], bool)), _trailing_run_start(np.zeros(3, bool))
        (3, 3)
    """
    start = len(done)
    while start > 0 and done[start - 1]:
        start -= 1
    return start


def _denormalise(spec: Any, feature: str, value: np.ndarray) -> np.ndarray:
    low, high = spec.features_range[feature]
    return low + (np.asarray(value, dtype=np.float64) + 1.0) * (high - low) / 2.0


class _SceneTermination:
    """Whether our scenario's environment terminates in a (next) state, from the ego row alone.

    Every scene ends on arrival at the finish, decided by the environment's own test on the
    scene's road network (merge: past ``merge_end_x``; intersection: on its exit lane;
    roundabout: at the finish or past it on the north exit; highway-fast: x >= 650 m). Crashes
    and off-road are read from the recorded ``dones``.
    """

    def __init__(self, scenario: str) -> None:
        from torchrl_csirl.tasks import resolve_scenario

        self.spec = resolve_scenario(scenario)
        self._env = None

    def _road_env(self) -> Any:
        if self._env is None:
            from torchrl_csirl.tasks import make_gym_env

            env = make_gym_env(self.spec.name)
            env.reset(seed=0)
            self._env = env.unwrapped
        return self._env

    def __call__(self, ego: np.ndarray) -> np.ndarray:
        """``ego``: ``(T, F)`` normalised ego rows; returns ``(T,)`` bool."""
        features = self.spec.features
        x = _denormalise(self.spec, "x", ego[:, features.index("x")])
        y = _denormalise(self.spec, "y", ego[:, features.index("y")])
        if "sin_h" in features:
            heading = np.arctan2(ego[:, features.index("sin_h")], ego[:, features.index("cos_h")])
        else:  # highway-fast and merge: straight roads along +x
            heading = np.zeros(len(ego))
        env = self._road_env()
        network = env.road.network
        out = np.zeros(len(ego), dtype=bool)
        for t, position in enumerate(np.stack([x, y], -1)):
            lane_index = network.get_closest_lane_index(position, float(heading[t]))
            out[t] = _arrived(env, _EgoState(lane_index, network.get_lane(lane_index), position))
        return out


def _arrived(env: Any, ego: _EgoState) -> bool:
    """The environment's arrival test (``has_arrived_at_finish``) applied to a recorded ego state."""
    controlled = env.controlled_vehicles
    env.controlled_vehicles = [ego]  # ``env.vehicle`` is the first controlled vehicle
    try:
        return bool(env.has_arrived_at_finish())
    finally:
        env.controlled_vehicles = controlled


class _EgoState:
    """The three attributes the environment's arrival test reads from a vehicle."""

    def __init__(self, lane_index: tuple, lane: Any, position: np.ndarray) -> None:
        self.lane_index, self.lane, self.position = lane_index, lane, position


def _end_of_trajectory(
    done: np.ndarray,
    end_at: str,
    done_mapping: str,
    limit: int,
    scene_end: np.ndarray | None,
) -> tuple[int, bool, list[int]]:
    """``(kept steps, terminated, early done steps)`` of one recorded trajectory.

    Examples:
        >>> done = np.array([0, 1, 0, 0, 1, 1], bool)
        >>> _end_of_trajectory(done, "recording", "full_length", 6, None)
        (6, False, [1])
        >>> _end_of_trajectory(done, "first_done", "full_length", 6, None)
        (2, True, [1])
    """
    length = len(done)
    early = np.flatnonzero(done[: _trailing_run_start(done)]).tolist()
    if end_at == "termination":
        candidates = [(limit, False), (length, False)]
        if early:
            candidates.append((early[0] + 1, True))
        if scene_end is not None and scene_end.any():
            candidates.append((int(np.flatnonzero(scene_end)[0]) + 1, True))
        # earliest cut; at equal steps a termination wins over the time limit
        end, terminated = min(candidates, key=lambda c: (c[0], not c[1]))
        return end, terminated, early
    end = length
    if end_at == "first_done" and done.any():
        end = int(np.flatnonzero(done)[0]) + 1
    last_done = bool(done[end - 1])
    terminated = last_done and (done_mapping == "terminated" or end < limit)
    return end, terminated, early


def import_published(
    path: str | os.PathLike,
    *,
    end_at: str = "recording",
    scenario: str | None = None,
    done_mapping: str = "full_length",
    max_episode_steps: int | None = None,
    action_tolerance: float = 1e-6,
    metadata: dict[str, Any] | None = None,
) -> ExpertDemonstrations:
    """Imports a published CSIRL / IQ-Learn expert file as :class:`ExpertDemonstrations`.

    Args:
        path (path-like): the file (``numpy.save``'d pickled dict, see the module docstring).
        end_at (str): where each trajectory ends: ``"recording"`` (default: the whole recording,
            the trailing padding ``dones`` read as its end), ``"first_done"`` (after the first
            ``done``) or ``"termination"`` (where our scenario's environment would end the
            episode; needs ``scenario``). See the module docstring.
        scenario (str, optional): the scenario the file was recorded in (``"merge"``, ...);
            required by ``end_at="termination"``, checked against the observation size and
            recorded in the metadata when given.
        done_mapping (str): ``"full_length"`` (default: a ``done`` on the last kept step of a
            trajectory shorter than ``max_episode_steps`` is a termination, otherwise the
            recording was truncated) or ``"terminated"`` (a ``done`` there is a termination).
            Not used by ``end_at="termination"``.
        max_episode_steps (int, optional): the time limit; defaults to the padded width ``L``
            (``end_at="termination"``: the scenario's episode limit).
        action_tolerance (float): slack allowed outside ``[-1, 1]``. Defaults to ``1e-6``.
        metadata (dict, optional): extra metadata; ``source``, ``end_at``, ``done_mapping``,
            ``recorded_lengths``, ``early_dones`` and ``ignored_keys`` are recorded.

    Returns:
        ExpertDemonstrations: trajectories in file order.

    Raises:
        pickle.UnpicklingError: the pickle references a forbidden global (never executed).
        ValueError: a bad ``end_at`` / ``done_mapping`` / ``scenario``, a missing key, wrong
            shapes, NaN/inf values in the kept steps, actions outside ``[-1, 1]`` or lengths out
            of range.

    Examples:
        >>> import numpy as np, tempfile, os
        >>> n, L, d = 2, 8, 3
        >>> dones = np.zeros((n, L), bool); dones[:, -5:] = True  # the recorder's padding
        >>> data = {"states": np.zeros((n, L, d)), "next_states": np.ones((n, L, d)),
        ...         "actions": np.zeros((n, L, 2)), "rewards": np.zeros((n, L)),
        ...         "dones": dones, "lengths": [L, L]}
        >>> path = os.path.join(tempfile.mkdtemp(), "expert.npy")
        >>> np.save(path, data, allow_pickle=True)
        >>> demos = import_published(path)
        >>> demos.lengths.tolist(), demos.trajectory(1)["next", "truncated"][-1].item()
        ([8, 8], True)
        >>> import_published(path, end_at="first_done").lengths.tolist()
        [4, 4]
    """
    if end_at not in END_AT:
        raise ValueError(f"end_at must be one of {END_AT}, got {end_at!r}.")
    if done_mapping not in _DONE_MAPPINGS:
        raise ValueError(f"done_mapping must be one of {_DONE_MAPPINGS}, got {done_mapping!r}.")
    if end_at == "termination" and scenario is None:
        raise ValueError('end_at="termination" needs the scenario the file was recorded in (scenario=...).')
    termination = _SceneTermination(scenario) if scenario is not None else None
    path = os.fspath(path)
    data = load_published_dict(path)
    missing = [key for key in _REQUIRED_KEYS if key not in data]
    if missing:
        raise ValueError(f"{path}: missing key(s) {missing}; found {sorted(map(str, data))}.")
    states = _array(data, "states", path)
    next_states = _array(data, "next_states", path)
    actions = _array(data, "actions", path)
    lengths = _array(data, "lengths", path).reshape(-1)
    if states.ndim != 3:
        raise ValueError(f"{path}: 'states' must have shape (N, L, D), got {states.shape}.")
    n, width, obs_dim = states.shape
    if termination is not None and obs_dim != termination.spec.obs_dim:
        raise ValueError(
            f"{path}: observations of size {obs_dim}, but {termination.spec.name!r} has {termination.spec.obs_dim}."
        )
    if next_states.shape != states.shape:
        raise ValueError(f"{path}: 'next_states' shape {next_states.shape} != 'states' shape {states.shape}.")
    if actions.ndim == 2:
        actions = actions[..., None]
    if actions.ndim != 3 or actions.shape[:2] != (n, width):
        raise ValueError(f"{path}: 'actions' must have shape ({n}, {width}, A), got {actions.shape}.")
    dones = _per_step(_array(data, "dones", path), "dones", n, width, path).astype(bool)
    rewards = None
    if "rewards" in data:
        rewards = _per_step(_array(data, "rewards", path), "rewards", n, width, path)
    if lengths.shape != (n,):
        raise ValueError(f"{path}: 'lengths' must have shape ({n},), got {lengths.shape}.")
    if not np.all(np.equal(np.mod(lengths, 1), 0)):
        raise ValueError(f"{path}: 'lengths' must be integers, got {lengths.tolist()}.")
    lengths = lengths.astype(np.int64)
    if np.any(lengths < 1) or np.any(lengths > width):
        raise ValueError(f"{path}: 'lengths' must lie in [1, {width}], got {lengths.tolist()}.")
    if max_episode_steps is not None:
        limit = int(max_episode_steps)
    else:
        limit = termination.spec.max_steps if end_at == "termination" else width
    if limit < 1:
        raise ValueError(f"max_episode_steps must be positive, got {max_episode_steps}.")

    episodes, early_dones = [], []
    for i, recorded in enumerate(lengths.tolist()):
        scene_end = None
        if end_at == "termination":
            ego = np.asarray(next_states[i, :recorded, : len(termination.spec.features)], dtype=np.float64)
            scene_end = termination(np.nan_to_num(ego))
        length, terminated, early = _end_of_trajectory(dones[i, :recorded], end_at, done_mapping, limit, scene_end)
        early_dones.extend([i, step] for step in early)
        episodes.append(_episode(i, length, terminated, states, next_states, actions, rewards, action_tolerance, path))
    info = {
        "source": "published",
        "source_file": os.path.basename(path),
        "end_at": end_at,
        "done_mapping": done_mapping,
        "max_episode_steps": limit,
        "recorded_lengths": lengths.tolist(),
        "early_dones": early_dones,
        "ignored_keys": sorted(str(key) for key in data if key not in _KNOWN_KEYS),
        **({"scenario": termination.spec.name} if termination is not None else {}),
        **(metadata or {}),
    }
    return ExpertDemonstrations.from_episodes(episodes, metadata=info)


def _episode(
    i: int,
    length: int,
    terminated_at_end: bool,
    states: np.ndarray,
    next_states: np.ndarray,
    actions: np.ndarray,
    rewards: np.ndarray | None,
    action_tolerance: float,
    path: str,
) -> dict[str, torch.Tensor]:
    """The first ``length`` steps of trajectory ``i``, checked, as an episode mapping."""
    valid = {"states": states[i, :length], "next_states": next_states[i, :length], "actions": actions[i, :length]}
    if rewards is not None:
        valid["rewards"] = rewards[i, :length]
    for key, value in valid.items():
        if not np.all(np.isfinite(value)):
            raise ValueError(f"{path}: trajectory {i}: {key!r} contains NaN or infinite values.")
    low, high = float(valid["actions"].min()), float(valid["actions"].max())
    if low < -1 - action_tolerance or high > 1 + action_tolerance:
        raise ValueError(f"{path}: trajectory {i}: actions must lie in [-1, 1], found range [{low:.4g}, {high:.4g}].")
    terminated = np.zeros(length, dtype=bool)
    truncated = np.zeros(length, dtype=bool)
    (terminated if terminated_at_end else truncated)[-1] = True
    episode = {
        "observation": torch.as_tensor(valid["states"], dtype=torch.float32),
        "action": torch.as_tensor(valid["actions"], dtype=torch.float32),
        "next_observation": torch.as_tensor(valid["next_states"], dtype=torch.float32),
        "terminated": torch.from_numpy(terminated),
        "truncated": torch.from_numpy(truncated),
    }
    if rewards is not None:
        episode["reward"] = torch.as_tensor(valid["rewards"], dtype=torch.float32)
    return episode
