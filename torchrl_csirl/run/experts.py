"""A run's demonstrations: the shipped ones or ``expert.path`` (an ``.npz``, a Minari dataset, a published
file), checked against the task, with the curriculum trajectory first (the ``expert`` section)."""
from __future__ import annotations

import os

import torch
from omegaconf import DictConfig

from torchrl_csirl.data import (
    ExpertDemonstrations,
    available_expert_datasets,
    import_published,
    load_expert_demonstrations,
    load_minari_dataset,
)
from torchrl_csirl.run.run import ExpertDataError
from torchrl_csirl.tasks import SCENARIOS, ScenarioSpec, TaskSpec  # noqa: F401 - SCENARIOS: doctests


# ---------------------------------------------------------------------------------------- data
def load_experts(expert: DictConfig, spec: ScenarioSpec) -> ExpertDemonstrations:
    """The demonstrations: the shipped ones, or ``expert.path`` (checked against the scenario).

    ``expert.path`` is an :class:`ExpertDemonstrations` ``.npz``, ``minari:<dataset id>`` (a local Minari
    dataset) or a published file (read by :func:`~torchrl_csirl.data.import_published` with
    ``end_at=expert.end_at``); a task without shipped demonstrations needs it. ``expert.curriculum`` picks
    its curriculum trajectory (:func:`curriculum_first`), then the first
    ``expert.num_trajectories`` are kept.

    Raises:
        ExpertDataError: a missing, malformed or mismatched file, naming it.
    """
    n = expert.num_trajectories
    if expert.path is None:
        if spec.name not in available_expert_datasets():
            raise ExpertDataError(f"expert.path: required for {spec.name!r}, which ships no demonstrations "
                                  "(an .npz of ExpertDemonstrations, or minari:<dataset id>)")
        try:
            return load_expert_demonstrations(spec.name, n, curriculum=expert.curriculum)
        except ValueError as err:  # a size that is not shipped
            raise ExpertDataError(f"expert.num_trajectories={n}: {err}") from None
    if str(expert.path).startswith("minari:"):
        path = str(expert.path)
        try:
            demos = load_minari_dataset(path.removeprefix("minari:"), task=spec)
        except Exception as err:
            raise ExpertDataError(f"expert.path={path}: cannot read it ({type(err).__name__}: {err})") from None
        return _checked_demonstrations(demos, expert, spec, path)
    path = os.path.abspath(os.path.expanduser(str(expert.path)))
    if not os.path.isfile(path):
        raise ExpertDataError(f"expert.path: no such file {path!r}.")
    if path.endswith(".npz") and expert.end_at != "recording":
        raise ExpertDataError(f"expert.end_at={expert.end_at} applies to published files; {path!r} is an .npz "
                              "of ExpertDemonstrations (its episodes end where they were recorded).")
    try:
        if path.endswith(".npz"):
            demos = ExpertDemonstrations.load(path)
        else:
            demos = import_published(path, end_at=expert.end_at, scenario=spec.name)
    except Exception as err:
        raise ExpertDataError(f"expert.path: {path!r} is not a valid expert file ({type(err).__name__}: {err}).") from None
    return _checked_demonstrations(demos, expert, spec, path)


def _checked_demonstrations(demos: ExpertDemonstrations, expert: DictConfig, spec: TaskSpec,
                            path: str) -> ExpertDemonstrations:
    """A file's demonstrations matched against the task, curriculum first, the first ``num_trajectories``."""
    n = expert.num_trajectories
    if demos.observation_dim != spec.obs_dim or demos.action_dim != spec.action_dim:
        raise ExpertDataError(
            f"expert.path: {path!r} has observations of size {demos.observation_dim} and actions of size "
            f"{demos.action_dim}, but {spec.name!r} has {spec.obs_dim} and {spec.action_dim}.")
    if demos.num_trajectories < n:
        raise ExpertDataError(
            f"expert.path: {path!r} holds {demos.num_trajectories} trajectories, "
            f"expert.num_trajectories asks for {n}.")
    demos = curriculum_first(demos, expert.curriculum, spec, path)
    return demos.subset(n) if n < demos.num_trajectories else demos


def recorded_in_traffic(observations: torch.Tensor, spec: ScenarioSpec) -> bool:
    """Whether another vehicle is present in any of the observations ``[T, D]`` of a trajectory.

    Examples:
        >>> obs = torch.zeros(3, 25)
        >>> recorded_in_traffic(obs, SCENARIOS["merge"])
        False
        >>> obs[1, 5] = 1.0  # presence of the first other vehicle
        >>> recorded_in_traffic(obs, SCENARIOS["merge"])
        True
    """
    rows = observations.reshape(observations.shape[0], spec.vehicles_count, len(spec.features))
    return bool((rows[:, 1:, spec.features.index("presence")] > 0.5).any())


def curriculum_first(demos: ExpertDemonstrations, curriculum: str, spec: ScenarioSpec,
                     path: str = "expert.path") -> ExpertDemonstrations:
    """The demonstrations of a file with the curriculum trajectory chosen by ``expert.curriculum`` first.

    ``"empty"``: trajectory 0 as stored (the published files, like ours, store the empty-road
    trajectory first). ``"traffic"``: the first trajectory in which another vehicle is observed,
    moved to the front (the others keep their order); ``metadata["curriculum_trajectory"]`` is its
    index in the file.

    Raises:
        ExpertDataError: ``"traffic"`` and no trajectory of the file was recorded in traffic.
    """
    if curriculum != "traffic":
        return demos.with_metadata(curriculum_trajectory=0)
    found = [i for i in range(demos.num_trajectories)
             if recorded_in_traffic(demos.trajectory(i)["observation"], spec)]
    if not found:
        raise ExpertDataError(f"expert.curriculum=traffic: no trajectory of {path!r} was recorded in traffic "
                              "(no other vehicle observed); use expert.curriculum=empty.")
    first = found[0]
    if first == 0:
        return demos.with_metadata(curriculum_trajectory=0)
    order = [first, *(i for i in range(demos.num_trajectories) if i != first)]
    metadata = demos.metadata
    if len(metadata.get("episodes") or []) == demos.num_trajectories:
        metadata["episodes"] = [metadata["episodes"][i] for i in order]
    metadata["curriculum_trajectory"] = first
    return ExpertDemonstrations.from_episodes([demos.trajectory(i) for i in order], metadata=metadata)
