"""Any gymnasium environment with flat ``Box`` spaces as a CSIRL task, without code.

:func:`make_gymnasium_task` reads the environment's spaces and episode limit, writes a
:class:`~torchrl_csirl.tasks.TaskSpec` and registers it (:func:`~torchrl_csirl.tasks.register_task`)
under the gymnasium id, with :func:`make_gymnasium_env` as its factory
(:mod:`torchrl_csirl.tasks.gymnasium_env`, also importable from here). The environment seen by
the learner:

* actions in ``[-1, 1]``, rescaled to the environment's bounds (gymnasium's ``RescaleAction``);
* float32 observations, as the environment gives them (a policy sees nothing more);
* ``"success"`` (evaluation's flag): a termination that is not a truncation
  (``success="termination"``), an info entry the configuration names (``success="<key>"``), or
  never (``success="none"``, e.g. a task without a goal: compare returns).

Such a task has no finish position: its accomplish rate is its success rate, and the return is
reported beside it (docs/own-task.md).

An id gymnasium does not know is looked for in the installed providers (``gymnasium_robotics``,
:func:`~torchrl_csirl.tasks.gym_ids.import_gym_provider`). A goal-conditioned task (a ``Dict`` observation
with ``achieved_goal`` and ``desired_goal``, gymnasium-robotics' PointMaze, AntMaze, Fetch ...) is
flattened (``observation``, ``achieved_goal``, ``desired_goal``: the spec's ``observation_layout``), its
matching features default to ``achieved_goal``, its success to the env's ``info["success"]``, and an
environment with a ``continuing_task`` setting is built with ``continuing_task=False`` (reaching the goal
ends the episode). An environment class of :data:`GYM_EXPERTS` gets its expert (PointMaze's waypoint
controller).
"""
from __future__ import annotations

from dataclasses import replace
from functools import partial
from types import MappingProxyType

import gymnasium as gym

from torchrl_csirl.tasks.catalog import TASKS
from torchrl_csirl.tasks.gym_ids import import_gym_provider
from torchrl_csirl.tasks.gymnasium_env import (
    SUCCESS_RULES,
    GymnasiumTaskWrapper,
    check_flat_box_spaces,
    is_goal_space,
    make_gymnasium_env,
    observation_layout,
    remove_maze_xml,
)
from torchrl_csirl.tasks.registry import import_task_module, register_task
from torchrl_csirl.tasks.spec import TaskSpec

__all__ = ["GYM_EXPERTS", "GymnasiumTaskWrapper", "make_gymnasium_env", "make_gymnasium_task", "parse_feature_indices"]

#: environment class (a gymnasium id's ``entry_point``) -> its expert (a :attr:`~torchrl_csirl.tasks.TaskSpec.expert`)
GYM_EXPERTS: dict[str, str] = {
    "gymnasium_robotics.envs.maze.point_maze:PointMazeEnv": "torchrl_csirl.tasks.robotics.point_maze_expert:make_point_maze_expert",
}


def parse_feature_indices(features: str | None, obs_dim: int, spec: TaskSpec | None = None,
                          key: str = "env.features") -> tuple[int, ...]:
    """Observation indices from ``"0,2"`` (indices) or names of the spec's layout (``None``: all).

    Raises:
        ValueError: one line naming the entry that is not an index in ``[0, obs_dim)`` or a name.

    Examples:
        >>> parse_feature_indices("0", 2), parse_feature_indices(None, 3)
        ((0,), (0, 1, 2))
        >>> parse_feature_indices("5", 2)
        Traceback (most recent call last):
        ...
        ValueError: env.features=5: index 5 is outside the observation (size 2: indices 0-1)
    """
    if features is None or str(features).strip() in ("", "all"):
        return tuple(range(obs_dim))
    names = {spec.feature_name(i): i for i in range(obs_dim)} if spec is not None else {}
    indices = []
    for item in (part.strip() for part in str(features).split(",")):
        if item.lstrip("-").isdigit():
            index = int(item)
            if not 0 <= index < obs_dim:
                raise ValueError(f"{key}={features}: index {index} is outside the observation "
                                 f"(size {obs_dim}: indices 0-{obs_dim - 1})")
        elif item in names:
            index = names[item]
        else:
            known = f"; names: {', '.join(names)}" if names else ""
            raise ValueError(f"{key}={features}: {item!r} is neither an observation index (0-{obs_dim - 1}) "
                             f"nor a feature name{known}")
        if index in indices:
            raise ValueError(f"{key}={features}: {item!r} is listed twice")
        indices.append(index)
    return tuple(indices)


def make_gymnasium_task(gym_id: str, features: str | None = None, success: str | None = None,
                        matching_scale: float = 100.0, max_steps: int | None = None) -> TaskSpec:
    """Registers the gymnasium id ``gym_id`` as a task (named ``gym_id``) and returns its spec.

    Registering the same id again with the same settings returns the spec registered before.

    Args:
        gym_id: a gymnasium id with flat ``Box`` spaces (``MountainCarContinuous-v0``, ``Pendulum-v1``,
            ``Hopper-v5``, ...) or a ``Dict`` of flat ``Box`` observations (``PointMaze_UMaze-v3``, flattened).
        features: the matching features ``h(s)``: observation indices ``"0,1"`` or names of the layout
            (``"achieved_goal[0]"``); ``None``: ``achieved_goal`` for a goal-conditioned task, else all.
        success: evaluation's success flag, as :class:`GymnasiumTaskWrapper` (``None``: ``"success"``, the
            env's info entry, for a goal-conditioned task, else ``"termination"``).
        matching_scale: the matching reward's scale (default: the robotics tasks' 100; pick it so that an expert
            episode earns some hundreds, docs/own-task.md).
        max_steps: the episode limit (``None``: the id's ``max_episode_steps``).

    Raises:
        ValueError: one line: an unknown id, spaces that are not flat ``Box``, no episode limit,
            bad feature indices.

    Examples:
        >>> spec = make_gymnasium_task("MountainCarContinuous-v0", features="0")
        >>> spec.name, spec.obs_dim, spec.action_dim, spec.max_steps, spec.position_feature_indices
        ('MountainCarContinuous-v0', 2, 1, 999, (0,))
        >>> maze = make_gymnasium_task("PointMaze_UMaze-v3")  # gymnasium-robotics', found without env.module
        >>> dict(maze.observation_layout), maze.matching_features
        ({'observation': (0, 4), 'achieved_goal': (4, 6), 'desired_goal': (6, 8)}, ('achieved_goal[0]', 'achieved_goal[1]'))
    """
    _find_gym_id(gym_id)
    if success is not None and success not in SUCCESS_RULES and not success:
        raise ValueError(f"env.success={success!r}: termination, none or the name of an info entry")
    probe = gym.make(gym_id)
    remove_maze_xml(probe)
    try:
        check_flat_box_spaces(probe, gym_id)
        layout = observation_layout(probe.observation_space)
        goal = is_goal_space(probe.observation_space)
        obs_dim = max((stop for _, stop in layout.values()), default=0) or int(probe.observation_space.shape[0])
        action_dim = int(probe.action_space.shape[0])
        limit = max_steps or (probe.spec.max_episode_steps if probe.spec is not None else None)
        episodic = {"continuing_task": False} if hasattr(probe.unwrapped, "continuing_task") else {}
    finally:
        probe.close()
    if not limit:
        raise ValueError(f"env.gym_id={gym_id}: the id has no episode limit; set env.max_steps")
    success = success or ("success" if goal else "termination")
    spec = TaskSpec(
        name=gym_id, obs_dim=obs_dim, action_dim=action_dim, max_steps=int(limit), finish_position=None,
        ego_feature_indices=tuple(range(obs_dim)),
        position_feature_indices=tuple(range(*layout["achieved_goal"])) if goal else tuple(range(obs_dim)),
        matching_scale=float(matching_scale), family="gymnasium", dt=1.0, episode_ends_at_goal=success != "none",
        expert=GYM_EXPERTS.get(str(gym.spec(gym_id).entry_point), ""), observation_layout=MappingProxyType(layout),
        description=f"gymnasium {gym_id} (success: {success}{', continuing_task=False' if episodic else ''})",
    )
    if features is not None:
        spec = replace(spec, position_feature_indices=parse_feature_indices(features, obs_dim, spec))
    previous = TASKS.get(gym_id)
    if previous is not None and previous == spec:
        return previous
    return register_task(spec, partial(make_gymnasium_env, gym_id, success, **episodic), replace=previous is not None)


def _find_gym_id(gym_id: str) -> None:
    """``gym_id`` registered, by an installed provider if needed (then imported in worker processes too,
    as ``env.module`` is); one ``ValueError`` line otherwise."""
    provider = import_gym_provider(gym_id)
    if provider is not None:
        import_task_module(provider)
    if gym_id not in gym.registry:
        close = [name for name in gym.registry if gym_id.lower().split("-")[0] in name.lower()][:5]
        hint = f" (did you mean {', '.join(close)}?)" if close else ""
        raise ValueError(f"env.gym_id={gym_id}: not a registered gymnasium id{hint}")
