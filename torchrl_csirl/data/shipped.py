"""Expert demonstrations shipped with the package (recorded with our own expert driver).

Layout: ``torchrl_csirl/data/experts/<scenario>/<curriculum>_25.npz`` with ``curriculum`` in
``"empty"`` (trajectory 0 recorded on an empty road, as in the paper) and ``"traffic"``
(trajectory 0 recorded with traffic). Both files share trajectories 1..24 (successful expert
episodes with traffic). The paper's dataset sizes N in {1, 5, 10, 15, 20, 25} are the nested
prefixes: the dataset of size N is the first N trajectories, so every size contains the
curriculum trajectory. See ``docs/EXPERTS.md`` for how the files were generated.

Examples:
    >>> from torchrl_csirl.data.shipped import load_expert_demonstrations, curriculum_trajectory
    >>> demos = load_expert_demonstrations("merge", num_trajectories=5)
    >>> demos.num_trajectories
    5
    >>> curriculum_trajectory("merge")["observation"].shape[-1]
    25
"""
from __future__ import annotations

import os

from tensordict import TensorDictBase

from torchrl_csirl.data.expert import ExpertDemonstrations

__all__ = [
    "DATASET_SIZES",
    "CURRICULA",
    "EXPERTS_DIR",
    "available_expert_datasets",
    "curriculum_trajectory",
    "expert_dataset_path",
    "load_expert_demonstrations",
]

EXPERTS_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "experts")
"""Folder holding the shipped ``.npz`` files."""
DATASET_SIZES = (1, 5, 10, 15, 20, 25)
"""The paper's dataset sizes."""
CURRICULA = ("empty", "traffic")
SCENARIO_NAMES = ("highway-fast", "merge", "roundabout", "intersection")
_FILE_SIZE = 25


def available_expert_datasets() -> dict[str, list[str]]:
    """Scenario -> curricula for which a shipped file exists.

    Examples:
        >>> sorted(available_expert_datasets())
        ['highway-fast', 'intersection', 'merge', 'roundabout']
    """
    found: dict[str, list[str]] = {}
    for scenario in SCENARIO_NAMES:
        curricula = [c for c in CURRICULA if os.path.exists(_path(scenario, c))]
        if curricula:
            found[scenario] = curricula
    return found


def _path(scenario: str, curriculum: str) -> str:
    return os.path.join(EXPERTS_DIR, scenario, f"{curriculum}_{_FILE_SIZE}.npz")


def expert_dataset_path(scenario: str, curriculum: str = "empty") -> str:
    """Path of the shipped file of a scenario (raises a clear error when unknown/missing)."""
    if scenario not in SCENARIO_NAMES:
        raise ValueError(f"Unknown scenario {scenario!r}; expected one of {list(SCENARIO_NAMES)}.")
    if curriculum not in CURRICULA:
        raise ValueError(f"Unknown curriculum {curriculum!r}; expected one of {list(CURRICULA)}.")
    path = _path(scenario, curriculum)
    if not os.path.exists(path):
        raise FileNotFoundError(
            f"No shipped expert dataset for {scenario!r} ({curriculum}); available: "
            f"{available_expert_datasets()}. Regenerate it with "
            f"`python recipes/generate_experts.py --scenario {scenario} --shipped`."
        )
    return path


def load_expert_demonstrations(
    scenario: str, num_trajectories: int = 25, curriculum: str = "empty"
) -> ExpertDemonstrations:
    """Load the shipped expert demonstrations of a scenario.

    Args:
        scenario: ``"highway-fast"``, ``"merge"``, ``"roundabout"`` or ``"intersection"``.
        num_trajectories: one of the paper's sizes ``(1, 5, 10, 15, 20, 25)``; the dataset of size N
            is the first N trajectories of the file (nested prefixes).
        curriculum: ``"empty"`` (trajectory 0 recorded on an empty road, the paper's setting) or
            ``"traffic"`` (trajectory 0 recorded with traffic).

    Returns:
        the demonstrations; ``metadata`` records the scenario, curriculum, seeds and per-episode stats.

    Examples:
        >>> demos = load_expert_demonstrations("intersection", 10, curriculum="traffic")
        >>> demos.num_trajectories, demos.metadata["curriculum"]
        (10, 'traffic')
    """
    if isinstance(num_trajectories, bool) or not isinstance(num_trajectories, int):
        raise TypeError(f"num_trajectories must be an int, got {type(num_trajectories).__name__}.")
    if num_trajectories not in DATASET_SIZES:
        raise ValueError(
            f"num_trajectories must be one of the shipped sizes {DATASET_SIZES}, got {num_trajectories}."
        )
    demos = ExpertDemonstrations.load(expert_dataset_path(scenario, curriculum))
    meta = demos.metadata
    if num_trajectories < demos.num_trajectories:
        demos = demos.subset(num_trajectories)
    episodes = meta.get("episodes")
    updates = {"num_trajectories": num_trajectories}
    if isinstance(episodes, list):
        updates["episodes"] = episodes[:num_trajectories]
    return demos.with_metadata(**updates)


def curriculum_trajectory(scenario: str, curriculum: str = "empty") -> TensorDictBase:
    """The single curriculum trajectory (trajectory 0) of a scenario's shipped dataset.

    Examples:
        >>> traj = curriculum_trajectory("roundabout")
        >>> traj["action"].shape[-1]
        2
    """
    return load_expert_demonstrations(scenario, 1, curriculum).trajectory(0)
