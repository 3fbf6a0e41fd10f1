"""The one description every CSIRL task shares, driving or robotics: :class:`TaskSpec`.

Recipes, metrics and pictures read a task's spec instead of branching on its name: the flat
observation layout (named slices), the matching features ``h(s)`` (the potential of the
matching reward) and the features of the nearest-state search, the finish (or goal), the
episode limit and how to build the gymnasium environment.

* :class:`~torchrl_csirl.tasks.ScenarioSpec` (driving, highway-env scenes) adds the Kinematics
  feature ranges and the highway-env config;
* :class:`~torchrl_csirl.tasks.robotics.RoboticsTaskSpec` (AntMaze U-maze, Adroit Relocate) adds
  the gymnasium-robotics environment it wraps.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Mapping

__all__ = ["TaskSpec"]


@dataclass(frozen=True, kw_only=True)
class TaskSpec:
    """What every task is: observation layout, matching features, goal, episode limit.

    Attributes:
        name: short name (``"merge"``, ``"antmaze-umaze"``, ...).
        gym_id: registered gymnasium id (``"csirl/<name>-v0"``), registered on
            ``import torchrl_csirl.tasks``; empty for a task registered with its own factory
            (:func:`~torchrl_csirl.tasks.register_task`).
        entry_point: ``"module:Class"`` of the environment (empty: as ``gym_id``).
        family: ``"driving"``, ``"robotics"``, ``"gymnasium"`` (``env.gym_id=``) or ``"custom"``
            (the default: a task of your own).
        obs_dim: flat observation size.
        action_dim: action size (actions in ``[-1, 1]``).
        max_steps: episode limit in policy steps; reaching it truncates.
        finish_position: the fixed finish / goal in world coordinates (driving: (x, y) [m];
            AntMaze: the goal (x, y) [m]), or ``None`` when the goal changes per episode and is
            part of the observation (Relocate: the object-target vector).
        ego_feature_indices: observation indices of the agent's own state, used for the
            nearest-state search of the matching reward.
        position_feature_indices: observation indices of the matching features ``h(s)``,
            the potential of the matching reward.
        matching_scale: scale of the matching reward.
        hidden_feature_indices: observation indices the networks do not read (the matching reward
            does): they read the observation through :class:`~torchrl_csirl.modules.DropFeatures`
            (the locomotion tasks' torso x, an absolute position a policy should not see).
        episode_ends_at_goal: whether reaching the goal completes the task, so that recorded
            demonstrations end there (driving: arrival at the finish; AntMaze: the goal); False
            where the goal must be held (Relocate: the ball stays at the target).
        dt: seconds per policy step.
        expert: ``"module:function"`` of the task's expert factory, ``factory(name, **options)`` returning
            an object with ``reset(env)`` and ``act(env) -> action`` (what
            :func:`~torchrl_csirl.tasks.experts.make_expert` builds); empty: the task has no expert.
        observation_layout: name -> ``(start, stop)`` slice of the flat observation.
        description: one line on the task.

    Examples:
        >>> from torchrl_csirl.tasks import resolve_scenario
        >>> spec = resolve_scenario("antmaze-umaze")
        >>> spec.family, spec.obs_dim, spec.matching_features
        ('robotics', 29, ('x', 'y'))
        >>> resolve_scenario("merge").matching_features
        ('x',)
    """

    name: str
    gym_id: str = ""
    entry_point: str = ""
    obs_dim: int
    action_dim: int
    max_steps: int
    finish_position: tuple[float, ...] | None
    ego_feature_indices: tuple[int, ...]
    position_feature_indices: tuple[int, ...]
    matching_scale: float
    hidden_feature_indices: tuple[int, ...] = ()
    episode_ends_at_goal: bool = True
    dt: float = 0.2
    family: str = "custom"
    expert: str = ""
    observation_layout: Mapping[str, tuple[int, int]] = field(
        default_factory=lambda: MappingProxyType({}), compare=False
    )
    description: str = ""

    def __post_init__(self) -> None:
        for name in ("ego_feature_indices", "position_feature_indices"):
            indices = getattr(self, name)
            bad = [i for i in indices if not 0 <= i < self.obs_dim]
            if not indices or bad:
                raise ValueError(
                    f"{self.name}: {name} must be non-empty indices in [0, {self.obs_dim}), got {indices}."
                )
        hidden = self.hidden_feature_indices
        if any(not 0 <= i < self.obs_dim for i in hidden) or len(set(hidden)) >= self.obs_dim:
            raise ValueError(f"{self.name}: hidden_feature_indices must be indices in [0, {self.obs_dim}) that leave "
                             f"the networks some input, got {hidden}.")

    @property
    def matching_features(self) -> tuple[str, ...]:
        """Names of the matching features ``h(s)`` (one per :attr:`position_feature_indices`)."""
        return tuple(self.feature_name(i) for i in self.position_feature_indices)

    def feature_name(self, index: int) -> str:
        """Name of one flat observation entry, from :attr:`observation_layout`.

        A slice of length 1 gives its own name, a longer one ``"<name>[k]"``; entries outside
        the layout are ``"obs[<index>]"``.
        """
        for name, (start, stop) in self.observation_layout.items():
            if start <= index < stop:
                return name if stop - start == 1 else f"{name}[{index - start}]"
        return f"obs[{index}]"

    def gym_make_kwargs(self, render_mode: str | None = None, **overrides: Any) -> dict[str, Any]:
        """Keyword arguments of ``gym.make(self.gym_id, ...)`` for these overrides.

        Each family says how its overrides reach its environment (driving: a highway-env
        ``config=`` dict; robotics: constructor keywords).
        """
        raise NotImplementedError(f"{type(self).__name__} does not say how to build its environment.")
