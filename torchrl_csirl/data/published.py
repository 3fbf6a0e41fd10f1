"""Importer for the published CSIRL / IQ-Learn expert files (pickled dict saved with numpy).

The published layout (SPEC section 3) is a dict saved with ``numpy.save`` (so a ``.npy`` file
holding a pickled 0-d object array), with arrays of shape ``(N, L, ...)`` padded to ``L``:

* ``states``, ``next_states``: ``(N, L, D)``;
* ``actions``: ``(N, L, A)``, normalised to ``[-1, 1]``;
* ``rewards`` (optional here): ``(N, L)`` or ``(N, L, 1)``;
* ``dones``: ``(N, L)`` or ``(N, L, 1)``;
* ``lengths``: ``(N,)``, the number of valid steps of each trajectory (``1 <= length <= L``).

The pickle is read with a **restricted unpickler** that only reconstructs plain containers and
numpy arrays/dtypes/scalars: any other global (``os.system``, ``builtins.eval``, ...) is refused
with :class:`pickle.UnpicklingError`, so no code from the file is ever executed.

Mapping of ``dones``: the published data set ``done`` both on crashes/arrival (termination)
and when the time limit ends an episode (truncation). With ``done_mapping="full_length"``
(default) a ``done`` on the final step of an episode that lasted ``max_episode_steps`` steps
(default: the padded width ``L``) is read as **truncated**; any other final ``done`` as
**terminated**. A final step without ``done`` is truncated (the recording stopped there).
``done_mapping="terminated"`` reads every ``done`` as termination (the published code's view).
A ``done`` before the last valid step is malformed and rejected.
"""
from __future__ import annotations

import io
import os
import pickle
from typing import Any

import numpy as np
import torch

from torchrl_csirl.data.expert import ExpertDemonstrations

__all__ = ["import_published", "load_published_dict", "RestrictedUnpickler"]

_REQUIRED_KEYS = ("states", "next_states", "actions", "dones", "lengths")
_DONE_MAPPINGS = ("full_length", "terminated")


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


def import_published(
    path: str | os.PathLike,
    *,
    done_mapping: str = "full_length",
    max_episode_steps: int | None = None,
    action_tolerance: float = 1e-6,
    metadata: dict[str, Any] | None = None,
) -> ExpertDemonstrations:
    """Imports a published CSIRL / IQ-Learn expert file as :class:`ExpertDemonstrations`.

    Args:
        path (path-like): the file (``numpy.save``'d pickled dict, see the module docstring).
        done_mapping (str): ``"full_length"`` (default: a final ``done`` of an episode lasting
            ``max_episode_steps`` steps is a truncation, other dones terminations) or
            ``"terminated"`` (every ``done`` is a termination).
        max_episode_steps (int, optional): the time limit; defaults to the padded width ``L``.
        action_tolerance (float): slack allowed outside ``[-1, 1]``. Defaults to ``1e-6``.
        metadata (dict, optional): extra metadata; ``source`` and ``done_mapping`` are recorded.

    Returns:
        ExpertDemonstrations: trajectories in file order.

    Raises:
        pickle.UnpicklingError: the pickle references a forbidden global (never executed).
        ValueError: a missing key, wrong shapes, NaN/inf values, actions outside ``[-1, 1]``,
            lengths out of range or a ``done`` before the end of an episode.

    Examples:
        >>> import numpy as np, tempfile, os
        >>> n, L, d = 2, 4, 3
        >>> data = {"states": np.zeros((n, L, d)), "next_states": np.ones((n, L, d)),
        ...         "actions": np.zeros((n, L, 2)), "rewards": np.zeros((n, L)),
        ...         "dones": np.zeros((n, L)), "lengths": np.array([4, 2])}
        >>> path = os.path.join(tempfile.mkdtemp(), "expert.npy")
        >>> np.save(path, data, allow_pickle=True)
        >>> demos = import_published(path)
        >>> demos.lengths.tolist(), demos.trajectory(1)["next", "truncated"].squeeze(-1).tolist()
        ([4, 2], [False, True])
    """
    if done_mapping not in _DONE_MAPPINGS:
        raise ValueError(f"done_mapping must be one of {_DONE_MAPPINGS}, got {done_mapping!r}.")
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
    n, width, _ = states.shape
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
    limit = width if max_episode_steps is None else int(max_episode_steps)
    if limit < 1:
        raise ValueError(f"max_episode_steps must be positive, got {max_episode_steps}.")

    episodes = []
    for i, length in enumerate(lengths.tolist()):
        valid = {"states": states[i, :length], "next_states": next_states[i, :length], "actions": actions[i, :length]}
        if rewards is not None:
            valid["rewards"] = rewards[i, :length]
        for key, value in valid.items():
            if not np.all(np.isfinite(value)):
                raise ValueError(f"{path}: trajectory {i}: {key!r} contains NaN or infinite values.")
        low, high = float(valid["actions"].min()), float(valid["actions"].max())
        if low < -1 - action_tolerance or high > 1 + action_tolerance:
            raise ValueError(
                f"{path}: trajectory {i}: actions must lie in [-1, 1], found range [{low:.4g}, {high:.4g}]."
            )
        done = dones[i, :length]
        if np.any(done[:-1]):
            first = int(np.flatnonzero(done[:-1])[0])
            raise ValueError(f"{path}: trajectory {i}: done at step {first} before its last step {length - 1}.")
        terminated = np.zeros(length, dtype=bool)
        truncated = np.zeros(length, dtype=bool)
        if done[-1] and (done_mapping == "terminated" or length < limit):
            terminated[-1] = True
        else:
            truncated[-1] = True
        episode = {
            "observation": torch.as_tensor(valid["states"], dtype=torch.float32),
            "action": torch.as_tensor(valid["actions"], dtype=torch.float32),
            "next_observation": torch.as_tensor(valid["next_states"], dtype=torch.float32),
            "terminated": torch.from_numpy(terminated),
            "truncated": torch.from_numpy(truncated),
        }
        if rewards is not None:
            episode["reward"] = torch.as_tensor(valid["rewards"], dtype=torch.float32)
        episodes.append(episode)
    info = {
        "source": "published",
        "source_file": os.path.basename(path),
        "done_mapping": done_mapping,
        "max_episode_steps": limit,
        **(metadata or {}),
    }
    return ExpertDemonstrations.from_episodes(episodes, metadata=info)
