"""Synthetic expert files in the layout of the authors' published data (issue 17, section 1).

The published files are not available here; :func:`write_published_files` writes files that
reproduce every fact checked against them (SPEC section 3, ``docs/experts.md``), built from the
shipped demonstrations of our own expert (real episodes of our scenes):

* one file per dataset size N in :data:`PUBLISHED_SIZES`, a dict saved with ``numpy.save``
  (only numpy classes in the pickle), file N = the empty-road curriculum trajectory + N-1 others;
* every trajectory stored for the full padded width L (:data:`PADDED_WIDTH`), ``lengths`` a plain
  list equal to L; a recording shorter than L is continued at constant velocity (the recorder
  went on); highway's longer ones are the L steps ending at x = 625 m (episodes end at x of
  600-650 m);
* ``dones`` True on the last five steps of every trajectory (the recorder's padding);
* roundabout: an earlier ``done`` in some trajectories (:data:`ROUNDABOUT_EARLY_DONES`, three
  steps after the arrival, where the continued ego has left the road), and in the 24-file one
  trajectory (the last) that stalls before the ring and never reaches the exit;
* an extra ``d_actions`` key (actions in m/s^2 and rad) in the files of :data:`D_ACTIONS_SIZES`;
* merge: recorded past our termination at 370 m (the ego continued linearly to x = 390 m), the
  traffic trajectories are all copies of one episode (so the 25-file holds two distinct
  trajectories), and the expert never accelerates (accelerations clipped at 0);
* intersection: the curriculum trajectory stops one step short of our finish line (about 2-3 m)
  and stands there.

Examples:
    >>> import tempfile
    >>> paths = write_published_files(tempfile.mkdtemp(), "merge", sizes=(1, 25))
    >>> sorted(paths)
    [1, 25]
"""
from __future__ import annotations

import functools
import os

import numpy as np

from torchrl_csirl.data import ExpertDemonstrations, expert_dataset_path
from torchrl_csirl.tasks import SCENARIOS

PUBLISHED_SIZES = (1, 4, 5, 9, 10, 14, 15, 19, 20, 24, 25)
PADDED_WIDTH = {"highway-fast": 75, "merge": 60, "roundabout": 55, "intersection": 65}
PADDING_DONES = 5
D_ACTIONS_SIZES = (10, 20, 24)
ROUNDABOUT_EARLY_DONES = (2, 5)
MERGE_RECORDED_TO_X = 390.0
HIGHWAY_END_X = 625.0
_STALL_STEP = 8


@functools.lru_cache(maxsize=None)
def _shipped(scenario: str, curriculum: str) -> ExpertDemonstrations:
    return ExpertDemonstrations.load(expert_dataset_path(scenario, curriculum))


def _world(spec, feature: str, value: np.ndarray) -> np.ndarray:
    low, high = spec.features_range[feature]
    return low + (value + 1.0) * (high - low) / 2.0


def _normalised(spec, feature: str, value: np.ndarray) -> np.ndarray:
    low, high = spec.features_range[feature]
    return np.clip(-1.0 + (value - low) * 2.0 / (high - low), -1.0, 1.0)


def _continue(spec, last: np.ndarray, steps: int, *, stand: bool = False, ego_to_x: float | None = None) -> np.ndarray:
    """``steps`` observations after ``last``: every present vehicle at constant velocity.

    ``stand`` stops the ego where it is; ``ego_to_x`` moves it linearly to that x [m] instead.
    """
    rows = last.reshape(spec.vehicles_count, len(spec.features)).astype(np.float64)
    index = {name: spec.features.index(name) for name in ("x", "y", "vx", "vy")}
    out = np.repeat(rows[None], steps, 0)
    time = spec.dt * np.arange(1, steps + 1)[:, None]
    for axis, speed in (("x", "vx"), ("y", "vy")):
        position = _world(spec, axis, rows[:, index[axis]])
        velocity = _world(spec, speed, rows[:, index[speed]]) * (rows[:, 0] > 0.5)
        out[:, :, index[axis]] = _normalised(spec, axis, position + velocity * time)
    if stand:
        out[:, 0, [index["x"], index["y"]]] = rows[0, [index["x"], index["y"]]]
        out[:, 0, [index["vx"], index["vy"]]] = _normalised(spec, "vx", np.zeros(2))
    if ego_to_x is not None:
        start = _world(spec, "x", rows[0, index["x"]])
        out[:, 0, index["x"]] = _normalised(spec, "x", start + (ego_to_x - start) * time[:, 0] / time[-1, 0])
    return out.reshape(steps, -1).astype(np.float32)


def _padded(spec, demos: ExpertDemonstrations, index: int, width: int, *, keep: int | None = None,
            stand: bool = False, ego_to_x: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(observations [width + 1, D], actions [width, 2])`` of one shipped trajectory at width L."""
    observations = demos.trajectory_observations(index, include_final=True).numpy()
    actions = demos.trajectory(index)["action"].numpy()
    if keep is not None:
        observations, actions = observations[: keep + 1], actions[:keep]
    if spec.name == "highway-fast" and len(actions) > width:
        # the published highway episodes end at x of 600-650 m after L steps: the L steps ending there
        x = _world(spec, "x", observations[:, spec.features.index("x")])
        end = max(int(np.argmax(x >= HIGHWAY_END_X)), width)
        observations, actions = observations[end - width : end + 1], actions[end - width : end]
    missing = width + 1 - len(observations)
    if missing > 0:
        more = _continue(spec, observations[-1], missing, stand=stand, ego_to_x=ego_to_x)
        observations = np.concatenate([observations, more])
        actions = np.concatenate([actions, np.zeros((missing, actions.shape[1]), np.float32)])
    return observations[: width + 1], actions[:width]


def _trajectories(scenario: str, size: int) -> list[tuple[np.ndarray, np.ndarray, list[int]]]:
    """``(observations, actions, early done steps)`` of the ``size`` trajectories of one file."""
    spec, width = SCENARIOS[scenario], PADDED_WIDTH[scenario]
    empty, traffic = _shipped(scenario, "empty"), _shipped(scenario, "traffic")
    if scenario == "intersection":  # the curriculum trajectory stops one step short of the finish
        first = _padded(spec, empty, 0, width, keep=int(empty.lengths[0]) - 1, stand=True)
    else:
        first = _padded(spec, empty, 0, width, ego_to_x=MERGE_RECORDED_TO_X if scenario == "merge" else None)
    out = [(*first, [])]
    for i in range(1, size):
        source = 1 if scenario == "merge" else i  # merge: one traffic episode, copied
        if scenario == "roundabout" and size == 24 and i == size - 1:
            obs, act = _padded(spec, traffic, source, width, keep=_STALL_STEP, stand=True)
        else:
            obs, act = _padded(spec, traffic, source, width,
                               ego_to_x=MERGE_RECORDED_TO_X if scenario == "merge" else None)
        early = []
        if scenario == "roundabout" and i in ROUNDABOUT_EARLY_DONES:
            early = [int(traffic.lengths[source]) + 2]
        out.append((obs, act, early))
    return out


def published_dict(scenario: str, size: int) -> dict:
    """The content of the published-format file of ``size`` trajectories of ``scenario``."""
    width = PADDED_WIDTH[scenario]
    trajectories = _trajectories(scenario, size)
    observations = np.stack([t[0] for t in trajectories])
    actions = np.stack([t[1] for t in trajectories])
    if scenario == "merge":
        actions[..., 0] = np.minimum(actions[..., 0], 0.0)  # this expert never accelerates
    dones = np.zeros((size, width), dtype=bool)
    dones[:, -PADDING_DONES:] = True
    for i, (_, _, early) in enumerate(trajectories):
        dones[i, early] = True
    data = {
        "states": observations[:, :-1],
        "next_states": observations[:, 1:],
        "actions": actions,
        "rewards": np.zeros((size, width), dtype=np.float32),
        "dones": dones,
        "lengths": [width] * size,
    }
    if size in D_ACTIONS_SIZES:
        data["d_actions"] = actions * np.array([15.0, np.pi / 2], dtype=np.float32)
    return data


def write_published_files(folder: str | os.PathLike, scenario: str,
                          sizes: tuple[int, ...] = PUBLISHED_SIZES) -> dict[int, str]:
    """Writes ``<folder>/<scenario>_<N>.npy`` for every N in ``sizes``; returns N -> path."""
    os.makedirs(folder, exist_ok=True)
    paths = {}
    for size in sizes:
        paths[size] = os.path.join(os.fspath(folder), f"{scenario}_{size}.npy")
        np.save(paths[size], published_dict(scenario, size), allow_pickle=True)
    return paths
