"""The paper's four driving scenarios: specifications, gymnasium registration, factory.

Each :class:`ScenarioSpec` describes one scene (see ``docs/scenarios.md``): the gymnasium id
registered on ``import torchrl_csirl.tasks``, the flattened observation layout (which entries
are the ego vehicle, which are its position), the episode limit, the finish position used by
the accomplish-rate metric and the published matching-reward scale.
"""
from __future__ import annotations

import copy
import os
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Mapping

import gymnasium as gym
import numpy as np
import torch
from torchrl.envs import EnvBase
from torchrl.envs.libs.gym import GymEnv

from torchrl_csirl.tasks.driving.driving import (
    CSIRLHighwayEnv,
    CSIRLIntersectionEnv,
    CSIRLMergeEnv,
    CSIRLRoundaboutEnv,
)
from torchrl_csirl.tasks.info import INFO_KEYS, ScenarioInfoReader, info_spec
from torchrl_csirl.tasks.locomotion import LOCOMOTION_TASKS
from torchrl_csirl.tasks.robotics.ant_goal import ANT_GOAL_SPEC
from torchrl_csirl.tasks.robotics.tasks import ROBOTICS_TASKS
from torchrl_csirl.tasks.spec import TaskSpec

__all__ = [
    "SCENARIOS",
    "ScenarioSpec",
    "TASKS",
    "make_gym_env",
    "make_scenario_env",
    "register_scenarios",
    "resolve_scenario",
    "sample_lane_centres",
    "scenario_config_overrides",
]

#: spacing [m] of the lane centre-line points (:func:`sample_lane_centres`)
LANE_SAMPLE_SPACING = 1.0


@dataclass(frozen=True, kw_only=True)
class ScenarioSpec(TaskSpec):
    """Static description of a CSIRL driving scenario (a :class:`~torchrl_csirl.tasks.spec.TaskSpec`).

    Attributes (besides :class:`~torchrl_csirl.tasks.spec.TaskSpec`'s):
        name: short name ("highway-fast", "merge", "roundabout", "intersection").
        gym_id: registered gymnasium id ("csirl/<name>-v0").
        base_env: the highway-env scene it derives from.
        entry_point: "module:Class" of the environment.
        features: per-vehicle Kinematics features, in observation order.
        features_range: feature -> (low, high) range mapped to [-1, 1] (then clipped).
        vehicles_count: observed vehicles (ego first, then the nearest others).
        obs_dim: flattened observation size (``vehicles_count * len(features)``).
        action_dim: 2 ([acceleration, steering] in [-1, 1]).
        max_steps: episode limit in policy steps (0.2 s each); reaching it truncates.
        finish_position: (x, y) [m] of the finish, for the accomplish rate.
        ego_feature_indices: flattened-observation indices of the ego row.
        position_feature_indices: flattened indices of the ego position used by the
            matching reward (x for highway/merge, (x, y) for roundabout/intersection).
        matching_scale: published scale of the matching reward.
        dt: seconds per step.
        description: one line on the scene.

    Examples:
        >>> from torchrl_csirl.tasks import SCENARIOS
        >>> spec = SCENARIOS["merge"]
        >>> spec.obs_dim, spec.max_steps, spec.position_feature_indices
        (25, 60, (1,))
        >>> spec.normalize_position((400.0, 4.0)).tolist()  # merge matches on x only
        [0.8]
    """

    base_env: str
    features: tuple[str, ...]
    features_range: Mapping[str, tuple[float, float]]
    vehicles_count: int
    finish_position: tuple[float, float]
    config: Mapping = field(default_factory=dict, repr=False, compare=False)

    @property
    def position_features(self) -> tuple[str, ...]:
        """Names of the position features used by the matching reward ("x" or ("x", "y"))."""
        return tuple(self.features[i] for i in self.position_feature_indices)

    def normalize_position(self, position) -> np.ndarray:
        """Map a world position (x[, y]) [m] to the observation's normalised coordinates.

        Only the coordinates named by :attr:`position_features` are returned (unclipped).
        """
        position = np.asarray(position, dtype=np.float64).reshape(-1)
        out = []
        for i, name in enumerate(("x", "y")):
            if name in self.position_features:
                lo, hi = self.features_range[name]
                out.append(-1.0 + (position[i] - lo) * 2.0 / (hi - lo))
        return np.asarray(out)

    def lane_centres(self, spacing: float = LANE_SAMPLE_SPACING) -> np.ndarray:
        """Points along the road's lane centre lines (:func:`sample_lane_centres`): what
        :class:`~torchrl_csirl.modules.LaneFeatures` measures the ego against."""
        return sample_lane_centres(self.name, spacing)

    def default_config(self) -> dict:
        """A deep copy of the scenario's full highway-env config."""
        return copy.deepcopy(dict(self.config))

    def feature_name(self, index: int) -> str:
        """``"x"`` for the ego's x, ``"vehicle<k>.<feature>"`` for the k-th other vehicle."""
        vehicle, feature = divmod(index, len(self.features))
        name = self.features[feature]
        return name if vehicle == 0 else f"vehicle{vehicle}.{name}"

    def gym_make_kwargs(self, render_mode: str | None = None, **config_overrides) -> dict:
        """``config=`` (overrides merged by :func:`scenario_config_overrides`) and ``render_mode``.

        Headless pictures need ``offscreen_rendering=True``, set for ``"rgb_array"`` (with
        :func:`quiet_headless_sdl`).
        """
        config = scenario_config_overrides(self, **config_overrides)
        if render_mode == "rgb_array":
            config.setdefault("offscreen_rendering", True)
            quiet_headless_sdl()
        kwargs: dict = {"config": config}
        if render_mode is not None:
            kwargs["render_mode"] = render_mode
        return kwargs


def quiet_headless_sdl() -> None:
    """On a machine without a display, has SDL (pygame, which draws highway-env's pictures) use its
    ``offscreen`` video driver unless ``SDL_VIDEODRIVER`` is set.

    Without it SDL probes the display drivers and prints ``error: XDG_RUNTIME_DIR is invalid or not
    set in the environment.`` before drawing good pictures. Not ``dummy``: highway-env stops drawing
    under that driver. Call it before pygame's display starts (an environment's first ``render``).
    """
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        os.environ.setdefault("SDL_VIDEODRIVER", "offscreen")


def _spec(
    name: str,
    env_class: type,
    base_env: str,
    position_features: tuple[str, ...],
    matching_scale: float,
    description: str,
) -> ScenarioSpec:
    config = env_class.default_config()
    obs = config["observation"]
    features = tuple(obs["features"])
    n_features = len(features)
    vehicles_count = int(obs["vehicles_count"])
    return ScenarioSpec(
        name=name,
        gym_id=f"csirl/{name}-v0",
        base_env=base_env,
        entry_point=f"{env_class.__module__}:{env_class.__name__}",
        features=features,
        features_range=MappingProxyType(
            {k: (float(v[0]), float(v[1])) for k, v in obs["features_range"].items()}
        ),
        vehicles_count=vehicles_count,
        obs_dim=vehicles_count * n_features,
        action_dim=2,
        max_steps=int(config["max_steps"]),
        finish_position=tuple(float(v) for v in config["finish_position"]),
        ego_feature_indices=tuple(range(n_features)),
        position_feature_indices=tuple(features.index(f) for f in position_features),
        matching_scale=float(matching_scale),
        dt=1.0 / config["policy_frequency"],
        family="driving",
        expert="torchrl_csirl.tasks.driving.expert_driver:make_expert_driver",
        observation_layout=MappingProxyType(
            {"ego": (0, n_features), "others": (n_features, vehicles_count * n_features)}
        ),
        description=description,
        config=MappingProxyType(config),
    )


SCENARIOS: dict[str, ScenarioSpec] = {
    spec.name: spec
    for spec in (
        _spec(
            "highway-fast",
            CSIRLHighwayEnv,
            "highway-fast-v0",
            ("x",),
            700.0,
            "3-lane highway, 20 vehicles; ego at 35 m/s overtakes traffic limited to 25 m/s",
        ),
        _spec(
            "merge",
            CSIRLMergeEnv,
            "merge-v0",
            ("x",),
            500.0,
            "highway with an on-ramp merging vehicle; ends past x = 370 m",
        ),
        _spec(
            "roundabout",
            CSIRLRoundaboutEnv,
            "roundabout-v0",
            ("x", "y"),
            100.0,
            "4-lane roundabout, 6 vehicles; ego enters from the south and exits north",
        ),
        _spec(
            "intersection",
            CSIRLIntersectionEnv,
            "intersection-v0",
            ("x", "y"),
            100.0,
            "4-way intersection, 2 lanes per approach, dense traffic; ego turns left",
        ),
    )
}
"""The four driving scenarios by name: ``"highway-fast"``, ``"merge"``, ``"roundabout"``, ``"intersection"``."""


TASKS: dict[str, TaskSpec] = {**SCENARIOS, **ROBOTICS_TASKS, ANT_GOAL_SPEC.name: ANT_GOAL_SPEC, **LOCOMOTION_TASKS}
"""Every task by name: the driving :data:`SCENARIOS`, the robotics tasks (``"antmaze-umaze"``,
``"relocate"``) and ``"ant-goal"`` (the AntMaze expert's training task,
:class:`~torchrl_csirl.tasks.robotics.AntGoalEnv`), all described by a
:class:`~torchrl_csirl.tasks.spec.TaskSpec`."""


def register_scenarios() -> None:
    """Register the ``csirl/<name>-v0`` gymnasium ids of every task (idempotent)."""
    for spec in TASKS.values():
        if spec.gym_id and spec.entry_point and spec.gym_id not in gym.registry:
            gym.register(
                id=spec.gym_id,
                entry_point=spec.entry_point,
                max_episode_steps=None,
                disable_env_checker=True,
                order_enforce=False,
            )


def resolve_scenario(name: str | TaskSpec) -> TaskSpec:
    """The spec of a task name, gym id or spec (ValueError if unknown).

    Driving scenarios give a :class:`ScenarioSpec`, robotics tasks a
    :class:`~torchrl_csirl.tasks.robotics.RoboticsTaskSpec`.

    Examples:
        >>> resolve_scenario("csirl/relocate-v0").name
        'relocate'
    """
    if isinstance(name, TaskSpec):
        return name
    if name in TASKS:
        return TASKS[name]
    for spec in TASKS.values():
        if name == spec.gym_id:
            return spec
    raise ValueError(f"Unknown scenario {name!r}; expected one of {sorted(TASKS)}.")


def make_gym_env(name: str, render_mode: str | None = None, **config_overrides) -> gym.Env:
    """Create a CSIRL task (driving scenario or robotics task) as a gymnasium environment.

    Args:
        name: task name (key of :data:`TASKS`) or its gym id.
        render_mode: ``None`` or ``"rgb_array"`` (headless pictures: driving sets
            ``offscreen_rendering=True``, the robotics tasks MuJoCo's EGL backend).
        **config_overrides: driving: highway-env config entries replacing the scenario's
            (top-level keys; nested dicts such as "observation" are merged one level deep so
            that a partial dict does not drop the other entries; ``fast=False`` selects the
            stock pandas observation and stock trajectory prediction). Robotics: the
            environment's constructor keywords (``RoboticsTaskSpec.env_options``).

    Returns:
        the unwrapped environment (episode limit implemented as truncation inside).

    Examples:
        >>> from torchrl_csirl.tasks import make_gym_env
        >>> env = make_gym_env("merge")
        >>> obs, info = env.reset(seed=0)
        >>> obs.shape, round(info["distance_to_finish"], 1)
        ((25,), 370.0)
    """
    spec = resolve_scenario(name)
    register_scenarios()
    env = gym.make(spec.gym_id, **spec.gym_make_kwargs(render_mode, **config_overrides))
    return env.unwrapped


def make_scenario_env(
    name: str | TaskSpec,
    seed: int | None = None,
    device: torch.device | str = "cpu",
    info_keys=INFO_KEYS,
    **overrides,
) -> EnvBase:
    """A task of :data:`TASKS` that has a ``csirl/<name>-v0`` gymnasium id (the driving scenarios, the
    robotics tasks, ``ant-goal``) as a TorchRL :class:`~torchrl.envs.libs.gym.GymEnv`, its info entries
    read into the TensorDict with fixed specs (:func:`~torchrl_csirl.tasks.info.info_spec`).

    The factory of these tasks (:func:`~torchrl_csirl.tasks.registry.env_factory`), what
    :func:`~torchrl_csirl.tasks.make_env` builds for them; the arguments are :func:`~torchrl_csirl.tasks.make_env`'s.

    Examples:
        >>> make_scenario_env("merge", seed=0).rollout(2, break_when_any_done=False)["next", "distance_to_finish"].shape
        torch.Size([2])
    """
    spec = resolve_scenario(name)
    register_scenarios()
    env = GymEnv(spec.gym_id, device=device, **spec.gym_make_kwargs(**overrides))
    env.set_info_dict_reader(ScenarioInfoReader(list(info_keys), spec=info_spec(info_keys)))
    if seed is not None:
        env.set_seed(seed)
    return env


def scenario_config_overrides(name: str | ScenarioSpec, **config_overrides) -> dict:
    """Turn keyword overrides into a highway-env ``config=`` dict that is safe to pass.

    highway-env's ``configure`` updates the config shallowly, so a partial nested dict (e.g.
    ``observation={"see_behind": True}``) would drop the scenario's other observation entries;
    nested dicts are therefore merged one level deep with the scenario's defaults.

    Examples:
        >>> cfg = scenario_config_overrides("merge", observation={"see_behind": True})
        >>> cfg["observation"]["see_behind"], cfg["observation"]["vehicles_count"]
        (True, 5)
    """
    spec = resolve_scenario(name)
    if not isinstance(spec, ScenarioSpec):
        raise ValueError(f"{spec.name!r} is not a driving scenario: it has no highway-env config.")
    config = {}
    for key, value in config_overrides.items():
        base = spec.config.get(key)
        if isinstance(value, Mapping) and isinstance(base, Mapping):
            merged = copy.deepcopy(dict(base))
            merged.update(copy.deepcopy(dict(value)))
            value = merged
        config[key] = value
    return config


def sample_lane_centres(scenario: str, spacing: float = LANE_SAMPLE_SPACING) -> np.ndarray:
    """Points along every lane centre line of a driving scenario's road, within its observed x, y ranges.

    Returns:
        array ``(P, 4)``: x [m], y [m], heading [rad], half width [m] of each point.

    Examples:
        >>> points = sample_lane_centres("roundabout")
        >>> points.shape[1], bool((points[:, 3] == 2.0).all())
        (4, True)
    """
    spec = SCENARIOS[scenario]
    (x_low, x_high), (y_low, y_high) = spec.features_range["x"], spec.features_range["y"]
    env = make_gym_env(scenario)
    try:
        env.reset(seed=0)
        network = env.unwrapped.road.network
        rows = []
        for start in network.graph:
            for end in network.graph[start]:
                for lane in network.graph[start][end]:
                    for s in np.arange(0.0, lane.length + spacing / 2, spacing):
                        x, y = lane.position(float(s), 0.0)
                        if x_low <= x <= x_high and y_low <= y <= y_high:
                            rows.append((x, y, lane.heading_at(float(s)), lane.width_at(float(s)) / 2))
    finally:
        env.close()
    return np.asarray(rows, dtype=np.float32)
