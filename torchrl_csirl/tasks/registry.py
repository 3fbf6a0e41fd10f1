"""Your own task, by name: :func:`register_task` adds a :class:`~torchrl_csirl.tasks.TaskSpec` and the
function that builds its TorchRL environment to :data:`~torchrl_csirl.tasks.TASKS`, so that
:func:`~torchrl_csirl.tasks.make_env`, the run layer (:mod:`torchrl_csirl.run`), every script and
the benchmark take it by name, as they take ``"merge"``.

Worker processes (collectors, ``ParallelEnv``) are started with the spawn method and do not see
this process's registry: they receive the environment factory itself (:func:`env_factory`), so the
factory must be picklable, a top-level function of an importable module or a ``functools.partial``
of one, as for any TorchRL ``ParallelEnv``. From the command line, ``env.module=<module>`` imports
a module that registers tasks (:func:`import_task_module`) before the configuration is checked: from
the working directory (as ``python -m`` would, also under ``python script.py``) or ``PYTHONPATH``.
Such a module may register gymnasium ids rather than tasks (``gymnasium.register``): the factories
:func:`env_factory` hands to workers import it again there, before they build an environment.
"""
from __future__ import annotations

import importlib
import inspect
import os
import sys
from collections.abc import Callable
from functools import partial

import torch
from torchrl.envs import EnvBase

from torchrl_csirl.tasks.catalog import TASKS, make_scenario_env, resolve_scenario
from torchrl_csirl.tasks.info import INFO_KEYS
from torchrl_csirl.tasks.locomotion import locomotion_factories
from torchrl_csirl.tasks.spec import TaskSpec

__all__ = ["build_env", "env_factory", "import_task_module", "register_task", "registered_factory", "task_names"]

#: the paper's tasks, ``ant-goal`` and the locomotion tasks: never replaced by :func:`register_task`
BUILTIN_TASKS: frozenset[str] = frozenset(TASKS)

#: every task's environment factory, by name (the built-in ones and those of :func:`register_task`)
_FACTORIES: dict[str, Callable[..., EnvBase]] = {}

#: the modules :func:`import_task_module` imported, in order, and the folders it searched them in
_TASK_MODULES: dict[str, str] = {}


def register_task(spec: TaskSpec, make_env: Callable[..., EnvBase], *, replace: bool = False) -> TaskSpec:
    """Makes ``spec.name`` a task every recipe, script and the benchmark can run.

    Args:
        spec: the task's description: observation and action sizes (actions in ``[-1, 1]``), episode
            limit, matching features (``position_feature_indices``), nearest-state features
            (``ego_feature_indices``), matching scale; ``family`` defaults to ``"custom"``.
        make_env: ``make_env(**overrides) -> EnvBase``, a picklable factory of the task's TorchRL
            environment (``"observation"`` of size ``obs_dim``, actions of size ``action_dim``,
            ``"terminated"`` / ``"truncated"``). It may write ``"success"`` (evaluation's success
            flag; otherwise a termination counts as success) and ``"distance_to_finish"`` (the
            accomplish rate; otherwise the accomplish rate is the success rate).
        replace: allow replacing a task registered earlier under the same name.

    Returns:
        the registered spec.

    Raises:
        ValueError: a built-in task's name, a name registered before (``replace=False``), or a
            factory that is not callable.

    Examples:
        >>> from functools import partial
        >>> from torchrl.envs import GymEnv
        >>> spec = TaskSpec(name="doc-pendulum", obs_dim=3, action_dim=1, max_steps=200,
        ...                 finish_position=None, ego_feature_indices=(0, 1, 2),
        ...                 position_feature_indices=(0, 1), matching_scale=1.0)
        >>> _ = register_task(spec, partial(GymEnv, "Pendulum-v1"))
        >>> from torchrl_csirl.tasks import make_env, resolve_scenario
        >>> resolve_scenario("doc-pendulum").family, make_env("doc-pendulum", seed=0).rollout(3)["observation"].shape
        ('custom', torch.Size([3, 3]))
    """
    if not isinstance(spec, TaskSpec):
        raise ValueError(f"register_task: spec must be a TaskSpec, got {type(spec).__name__}.")
    if not callable(make_env):
        raise ValueError(f"register_task({spec.name!r}): make_env must be callable, got {type(make_env).__name__}.")
    if spec.name in BUILTIN_TASKS:
        raise ValueError(f"register_task: {spec.name!r} is a built-in task; give yours another name.")
    if spec.name in TASKS and not replace:
        raise ValueError(f"register_task: {spec.name!r} is already registered (replace=True to replace it).")
    _register(spec, make_env)
    return spec


def _register(spec: TaskSpec, make_env: Callable[..., EnvBase]) -> None:
    """The one registration, of the built-in tasks and of :func:`register_task`'s: the spec and its factory."""
    TASKS[spec.name] = spec
    _FACTORIES[spec.name] = make_env


def _register_builtin_tasks() -> None:
    """The built-in tasks with their factories: the locomotion tasks' own (:func:`~torchrl_csirl.tasks.locomotion.locomotion_factories`),
    the others' ``partial(make_scenario_env, name)`` (their ``csirl/<name>-v0`` gymnasium id as a ``GymEnv``)."""
    locomotion = locomotion_factories()
    for spec in tuple(TASKS.values()):
        _register(spec, locomotion.get(spec.name) or partial(make_scenario_env, spec.name))


_register_builtin_tasks()


def registered_factory(name: str) -> Callable[..., EnvBase] | None:
    """The environment factory of the task ``name`` (built-in or :func:`register_task`'s); None for an unknown name.

    Examples:
        >>> registered_factory("merge").func.__name__, registered_factory("hopper").func.__name__
        ('make_scenario_env', 'make_locomotion_env')
    """
    return _FACTORIES.get(name)


def build_env(
    factory: Callable[..., EnvBase],
    seed: int | None = None,
    device: torch.device | str | None = "cpu",
    info_keys=INFO_KEYS,
    **overrides,
) -> EnvBase:
    """The one way a task's environment is built from its factory (what :func:`~torchrl_csirl.tasks.make_env` does).

    ``factory(**overrides)``, also given ``device`` and ``info_keys`` when it names them among its
    parameters; then moved to ``device`` when it is elsewhere (``None``: left where the factory put
    it) and seeded with ``env.set_seed(seed)`` (None: unseeded).

    Examples:
        >>> env = build_env(registered_factory("hopper"), seed=0, device="cpu")
        >>> env.device, env.rollout(2)["observation"].shape
        (device(type='cpu'), torch.Size([2, 12]))
    """
    parameters = _named_parameters(factory)
    kwargs = dict(overrides)
    if "device" in parameters and device is not None:
        kwargs["device"] = device
    if "info_keys" in parameters:
        kwargs["info_keys"] = info_keys
    env = factory(**kwargs)
    if device is not None and env.device != torch.device(device):
        env = env.to(device)
    if seed is not None:
        env.set_seed(seed)
    return env


def _named_parameters(factory: Callable[..., EnvBase]) -> set[str]:
    """The keyword parameters a factory names (not those a ``**kwargs`` would swallow)."""
    try:
        parameters = inspect.signature(factory).parameters.values()
    except (TypeError, ValueError):  # a callable without a signature
        return set()
    return {p.name for p in parameters if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)}


def env_factory(name: str | TaskSpec, **overrides) -> Callable[[], EnvBase]:
    """A picklable zero-argument factory of the task's TorchRL environment, for worker processes.

    ``partial(build_env, factory, **overrides)`` (:func:`build_env`, the path of
    :func:`~torchrl_csirl.tasks.make_env`) with the task's own factory: the built-in tasks' resolve by
    name in the worker, registered ones are their own function, so a spawned worker needs no
    registry. ``overrides`` are :func:`~torchrl_csirl.tasks.make_env`'s keywords. After
    :func:`import_task_module`, the factory imports those modules first in the worker (a module that
    registers a gymnasium id must have run there before ``gymnasium.make`` finds the id).

    Examples:
        >>> env_factory("merge")().batch_size
        torch.Size([])
    """
    spec = resolve_scenario(name)
    if spec.name not in _FACTORIES:
        raise ValueError(f"{spec.name!r} is not a registered task (register_task registers it with its factory).")
    factory = partial(build_env, _FACTORIES[spec.name], **overrides)
    if not _TASK_MODULES:
        return factory
    return partial(_build_after_importing, dict(_TASK_MODULES), factory)


def _build_after_importing(modules: dict[str, str], factory: Callable[[], EnvBase]) -> EnvBase:
    """In a worker process: the task modules imported (from the folders they were found in), then the env."""
    for module, folder in modules.items():
        _search_in(folder)
        importlib.import_module(module)
    return factory()


def _search_in(folder: str) -> None:
    """``folder`` on ``sys.path`` (after the script's own folder, before the installed packages)."""
    if folder not in (os.path.abspath(p or os.curdir) for p in sys.path):
        sys.path.insert(1 if sys.path else 0, folder)


def task_names(*, driving: bool | None = None, family: str | None = None) -> tuple[str, ...]:
    """Every task name, sorted: the one list of the tasks (and of the driving scenes) to read.

    Args:
        driving: only the driving scenes (True) / only the others (False).
        family: only the tasks of this :attr:`~torchrl_csirl.tasks.TaskSpec.family` (``"driving"``,
            ``"robotics"``, ``"locomotion"``, ``"gymnasium"``, ``"custom"``).

    Examples:
        >>> task_names(driving=True)
        ('highway-fast', 'intersection', 'merge', 'roundabout')
        >>> task_names(family="locomotion")
        ('halfcheetah', 'hopper')
    """
    return tuple(sorted(name for name, spec in TASKS.items()
                        if (driving is None or (spec.family == "driving") == driving)
                        and (family is None or spec.family == family)))


def import_task_module(module: str) -> None:
    """Imports ``module`` (a dotted name) for the tasks or gymnasium ids it registers.

    The module is looked for in the working directory first, then on ``sys.path`` (``PYTHONPATH``,
    the installed packages): ``python recipes/<script>.py env.module=my_tasks`` run from the folder
    holding ``my_tasks.py`` finds it, as ``python -m`` would. Worker processes started afterwards
    find and import it too (:func:`env_factory`).

    Raises:
        ValueError: one line naming the module when it cannot be imported.

    Examples:
        >>> import_task_module("no_such_task_module")  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        ValueError: env.module=no_such_task_module: cannot import it (ModuleNotFoundError: ...
    """
    folder = os.getcwd()
    _search_in(folder)
    try:
        importlib.import_module(module)
    except Exception as err:  # noqa: BLE001 - any import failure is the user's module's
        raise ValueError(f"env.module={module}: cannot import it ({type(err).__name__}: {err}); "
                         f"it must be importable from the working directory ({folder}) or PYTHONPATH") from None
    _TASK_MODULES.setdefault(module, folder)
