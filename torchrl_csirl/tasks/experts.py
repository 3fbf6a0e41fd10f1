"""Every task's expert, by name: the factory named by its spec's :attr:`~torchrl_csirl.tasks.TaskSpec.expert`.

Each task family names its expert where it declares its specs (``"module:function"``, imported on
use): the driving scenarios :func:`~torchrl_csirl.tasks.driving.expert_driver.make_expert_driver`, AntMaze
:func:`~torchrl_csirl.tasks.robotics.ant_goal.make_waypoint_ant_expert`, Relocate
:func:`~torchrl_csirl.tasks.robotics.expert.make_relocate_expert`, the locomotion tasks
:class:`~torchrl_csirl.tasks.locomotion.LocomotionExpert`. A task of your own
(:func:`~torchrl_csirl.tasks.register_task`) gets an expert the same way.
"""
from __future__ import annotations

import importlib
import inspect
from typing import Any, Callable

from torchrl_csirl.tasks.catalog import TASKS

__all__ = ["expert_factory", "expert_tasks", "make_expert"]


def expert_tasks() -> tuple[str, ...]:
    """The tasks with an expert (a non-empty :attr:`~torchrl_csirl.tasks.TaskSpec.expert`), in
    :data:`~torchrl_csirl.tasks.TASKS`' order: the four driving scenarios, AntMaze (the waypoint-driven
    ant), Relocate (the DAPG policy), the locomotion tasks (their shipped SAC experts), then any
    registered task that names one.

    Examples:
        >>> expert_tasks()[4:6], "halfcheetah" in expert_tasks()
        (('antmaze-umaze', 'relocate'), True)
    """
    return tuple(name for name, spec in TASKS.items() if spec.expert)


def expert_factory(name: str) -> Callable[..., Any]:
    """The function its spec's ``expert`` names (``"module:function"``), imported.

    Raises:
        ValueError: an unknown task, or a task without an expert.

    Examples:
        >>> expert_factory("merge").__name__
        'make_expert_driver'
    """
    spec = TASKS.get(name)
    if spec is None or not spec.expert:
        what = "Unknown scenario" if spec is None else "No expert for the task"
        raise ValueError(f"{what} {name!r}; expected one of {sorted(expert_tasks())}.")
    module, _, attribute = spec.expert.partition(":")
    factory: Any = importlib.import_module(module)
    for part in attribute.split("."):
        factory = getattr(factory, part)
    return factory


def make_expert(name: str, **options: Any) -> Any:
    """Build the expert of a task: ``factory(name, **options)`` of :func:`expert_factory`.

    The options are the factory's: a driving scenario's are fields of its
    :class:`~torchrl_csirl.tasks.driving.expert_config.ExpertConfig`; ``"antmaze-umaze"`` takes ``policy=<policy.pt
    or run directory of recipes/train_ant_expert.py>``, ``lookahead=`` and ``action_gain=``
    (:class:`~torchrl_csirl.tasks.robotics.WaypointAntExpert`); ``"hopper"``, ``"halfcheetah"`` take
    ``policy=`` (default: the shipped SAC policy, :class:`~torchrl_csirl.tasks.locomotion.LocomotionExpert`);
    ``"relocate"`` (the DAPG expert) takes none.

    Every expert has ``reset(env)`` and ``act(env) -> action``.

    Raises:
        ValueError: an unknown task, a task without an expert, or options its factory does not take.

    Examples:
        >>> expert = make_expert("roundabout", horizon=10)
        >>> expert.config.horizon
        10
        >>> type(make_expert("relocate")).__name__
        'DAPGRelocateExpert'
    """
    factory = expert_factory(name)
    try:
        inspect.signature(factory).bind(name, **options)
    except TypeError:
        raise ValueError(f"The {name!r} expert takes {_options_of(factory)}, got {sorted(options)}.") from None
    return factory(name, **options)


def _options_of(factory: Callable[..., Any]) -> str:
    """``"only policy=, lookahead="`` (the keywords after the task name), or ``"no options"``."""
    parameters = list(inspect.signature(factory).parameters.values())[1:]
    names = [f"{p.name}=" for p in parameters if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]
    return f"only {', '.join(names)}" if names else "no options"
