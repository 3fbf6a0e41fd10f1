"""Expert demonstrations shipped with the package (recorded with our own experts).

Layout: ``torchrl_csirl/data/experts/<task>/<curriculum>_25.npz``. Driving scenarios (our expert
driver): ``curriculum`` in ``"empty"`` (trajectory 0 recorded on an empty road, as in the paper)
and ``"traffic"`` (trajectory 0 recorded with traffic); both files share trajectories 1..24
(successful expert episodes with traffic). Relocate (the DAPG policy), AntMaze (the waypoint-driven
ant) and the locomotion tasks (their SAC experts, whole 1 000-step episodes): one file each,
``"expert"``; so do the gymnasium ids ``PointMaze_UMaze-v3`` and ``PointMaze_Medium-v3`` (their waypoint
expert; ``<task>`` is the id), found once the id is a task (``env.gym_id=``). The paper's dataset
sizes N in {1, 5, 10, 15, 20, 25} are the nested prefixes: the dataset of size N is the first N
trajectories, so every size contains the curriculum trajectory.
See ``docs/experts.md`` for how the files were generated.

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

from torchrl_csirl._paths import EXPERTS_DIR
from torchrl_csirl.data.expert import ExpertDemonstrations

__all__ = [
    "DATASET_SIZES",
    "CURRICULA",
    "EXPERTS_DIR",
    "available_expert_datasets",
    "curriculum_trajectory",
    "expert_dataset_path",
    "load_expert_demonstrations",
    "task_curricula",
]

DATASET_SIZES = (1, 5, 10, 15, 20, 25)
"""The paper's dataset sizes."""
CURRICULA = ("empty", "traffic")
"""The driving scenarios' curricula."""
_FILE_SIZE = 25


def task_curricula() -> dict[str, tuple[str, ...]]:
    """Task -> the curricula of its shipped files (the first is the default): :data:`CURRICULA` for the
    driving scenarios, ``("expert",)`` for every other task with an expert (read from the task registry).

    Examples:
        >>> task_curricula()["merge"], task_curricula()["relocate"]
        (('empty', 'traffic'), ('expert',))
    """
    from torchrl_csirl.tasks.experts import expert_tasks
    from torchrl_csirl.tasks.registry import task_names

    driving = task_names(family="driving")
    return {**{name: CURRICULA for name in driving}, **{name: ("expert",) for name in expert_tasks() if name not in driving}}


def available_expert_datasets() -> dict[str, list[str]]:
    """Task -> curricula for which a shipped file exists (a gymnasium id's, PointMaze's, once it is a task:
    :func:`~torchrl_csirl.tasks.make_gymnasium_task`).

    Examples:
        >>> datasets = available_expert_datasets()
        >>> datasets["merge"], datasets["antmaze-umaze"], "hopper" in datasets
        (['empty', 'traffic'], ['expert'], True)
    """
    found: dict[str, list[str]] = {}
    for scenario, curricula_of_task in task_curricula().items():
        curricula = [c for c in curricula_of_task if os.path.exists(_path(scenario, c))]
        if curricula:
            found[scenario] = curricula
    return found


def _path(scenario: str, curriculum: str) -> str:
    return os.path.join(EXPERTS_DIR, scenario, f"{curriculum}_{_FILE_SIZE}.npz")


def expert_dataset_path(scenario: str, curriculum: str | None = None) -> str:
    """Path of the shipped file of a task (raises a clear error when unknown/missing).

    ``curriculum=None`` picks the task's default (driving ``"empty"``, robotics ``"expert"``).

    Examples:
        >>> os.path.basename(expert_dataset_path("relocate"))
        'expert_25.npz'
    """
    known = task_curricula()
    if scenario not in known:
        raise ValueError(f"Unknown scenario {scenario!r}; expected one of {list(known)}.")
    curricula = known[scenario]
    curriculum = curricula[0] if curriculum is None else curriculum
    if curriculum not in curricula:
        raise ValueError(f"Unknown curriculum {curriculum!r} for {scenario!r}; expected one of {list(curricula)}.")
    path = _path(scenario, curriculum)
    if not os.path.exists(path):
        raise FileNotFoundError(
            f"No shipped expert dataset for {scenario!r} ({curriculum}); available: "
            f"{available_expert_datasets()}. Regenerate it with the command in docs/experts.md."
        )
    return path


def load_expert_demonstrations(
    scenario: str, num_trajectories: int = 25, curriculum: str | None = None
) -> ExpertDemonstrations:
    """Load the shipped expert demonstrations of a scenario.

    Args:
        scenario: ``"highway-fast"``, ``"merge"``, ``"roundabout"``, ``"intersection"``,
            ``"relocate"`` or ``"antmaze-umaze"``.
        num_trajectories: one of the paper's sizes ``(1, 5, 10, 15, 20, 25)``; the dataset of size N
            is the first N trajectories of the file (nested prefixes).
        curriculum: driving: ``"empty"`` (trajectory 0 recorded on an empty road, the paper's
            setting; the default) or ``"traffic"`` (trajectory 0 recorded with traffic);
            Relocate: ``"expert"`` (the default).

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


def curriculum_trajectory(scenario: str, curriculum: str | None = None) -> TensorDictBase:
    """The single curriculum trajectory (trajectory 0) of a scenario's shipped dataset.

    Examples:
        >>> traj = curriculum_trajectory("roundabout")
        >>> traj["action"].shape[-1]
        2
    """
    return load_expert_demonstrations(scenario, 1, curriculum).trajectory(0)
