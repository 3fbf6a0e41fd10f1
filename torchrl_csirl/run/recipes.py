"""One registry of recipes: what each training script is, in one record (:class:`Recipe`).

A recipe names the methods it trains, its configuration schema (one for the driving scenes, one for
every other task: the task's :attr:`~torchrl_csirl.tasks.TaskSpec.family` picks it), its presets, the
checks a loaded configuration must pass, its trainer and its finish. Loading is the same for every
recipe (:meth:`Recipe.configure`): the command line parsed once
(:func:`~torchrl_csirl.run.config.parse_command_line`), the task it names registered
(``env.module``, ``env.gym_id``, :func:`~torchrl_csirl.run.task_schemas.name_task`), its family choosing the
schema, one merge (new: defaults, the task's, the preset, the line; resumed: the saved run's, the line), then the
validation and the checks. The run-level commands (``torchrl-csirl summarize``, the sweep, ``torchrl-csirl train``)
look a recipe up by method name (:func:`recipe_for`).

Examples:
    >>> recipe_for("csirl").name, recipe_for("gail").name
    ('csirl', 'imitation')
    >>> cfg = recipe_for("csirl").load_config(["env.gym_id=MountainCarContinuous-v0"])
    >>> cfg.env.task, type(cfg.expert.curriculum).__name__
    ('MountainCarContinuous-v0', 'str')
    >>> recipe_for("gibberish")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    KeyError: "unknown method 'gibberish'; known: bc, csirl, csirl-b, ..."
"""
from __future__ import annotations

import importlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from omegaconf import DictConfig

from torchrl_csirl.run import config as config_lib
from torchrl_csirl.run.config import CommandLine, ConfigError, parse_command_line
from torchrl_csirl.run.run import resolve_resume
from torchrl_csirl.run.task_schemas import check_task_sections, name_task, schema_family

__all__ = ["RECIPE_MODULES", "Recipe", "known_methods", "load_config_for", "recipe_for", "recipe_schemas", "registered_recipes",
           "register_recipe"]

#: the run-layer modules that declare the recipes (imported on the first look-up)
RECIPE_MODULES = ("torchrl_csirl.methods.csirl", "torchrl_csirl.methods.baselines", "torchrl_csirl.methods.expert")

_RECIPES: dict[str, Recipe] = {}


@dataclass(frozen=True)
class Recipe:
    """A training script's configuration, checks, trainer and finish.

    Attributes:
        name: the recipe's name (``csirl``, ``imitation``, ``expert``, ``ant_expert``).
        script: the module whose ``main`` runs it (``torchrl_csirl.scripts.<name>``).
        methods: the method names it trains (a run's ``summary.json`` ``method``).
        schema: the configuration schema of the driving scenes (or of every task when ``task_schema`` is None).
        task_schema: the schema of every other task (None: ``schema`` for every task).
        config_dir: the folder of ``schema``'s presets and per-scene defaults (None: ``preset=default`` only).
        task_config_dir: the folder of ``task_schema``'s per-task defaults (``scene/<task>.yaml``; None: none).
        checks: ``check(cfg)`` for each configuration loaded (several keys at once, the device, ...);
            each raises :class:`~torchrl_csirl.run.config.ConfigError`.
        command_check: ``check(command, resuming)`` on the parsed command line
            (:class:`~torchrl_csirl.run.config.CommandLine`) before loading (e.g. a method named).
        method_overrides: ``method -> key=value strings`` that select a method of this recipe.
        trainer: ``trainer(cfg, run_dir, frames_done=, resume_frames=) -> Run``.
        finish: ``finish(run) -> summary`` (final evaluation, policy, plots).
        method_of: ``method_of(cfg) -> str``, the method a configuration trains.
        untrained: ``untrained(cfg)``: for a configuration that trains nothing (a reference row), its
            ``evaluate(cfg, run_dir) -> summary``; else None.
    """

    name: str
    script: str
    methods: tuple[str, ...]
    schema: type
    task_schema: type | None = None
    config_dir: str | None = None
    task_config_dir: str | None = None
    checks: Sequence[Callable[[DictConfig], Any]] = ()
    command_check: Callable[[CommandLine, bool], None] | None = None
    method_overrides: Callable[[str], list[str]] = field(default=lambda method: [])
    trainer: Callable[..., Any] | None = None
    finish: Callable[[Any], dict[str, Any]] | None = None
    method_of: Callable[[DictConfig], str] = field(default=lambda cfg: cfg.method)
    untrained: Callable[[DictConfig], Callable[[DictConfig, str], dict[str, Any]] | None] = field(default=lambda cfg: None)

    def schema_for(self, task: str | None) -> type:
        """The schema of ``task`` (None: the schema's own default task)."""
        if self.task_schema is None or task is None or schema_family(task) == "driving":
            return self.schema
        return self.task_schema

    def _config_dir(self, schema: type) -> str | None:
        return self.config_dir if schema is self.schema else self.task_config_dir

    def configure(self, argv: list[str] | CommandLine | None = None, *, default_task: str | None = None,
                  run_dir: str | None = None) -> DictConfig:
        """The configuration a command line asks for: argv parsed once, the task, its schema, one merge, the
        validation and the recipe's checks.

        A new run: the schema's defaults, the task's (``scene/<task>.yaml``), the preset, the command line. With
        ``checkpoint.resume=`` (or ``run_dir``): the run's saved ``config.yaml`` updated by the rest of the line
        (e.g. a larger ``collector.total_frames``), ``checkpoint.resume`` kept.

        Args:
            argv: the command line (``key=value`` strings, or :func:`~torchrl_csirl.run.config.parse_command_line`'s).
            default_task: a new run's task when the command line names none (None: the schema's default).
            run_dir: a run directory to resume (instead of ``checkpoint.resume``).

        Raises:
            ConfigError: one line naming the bad key or value.
        """
        command = parse_command_line(argv)
        resume = command.get("checkpoint.resume")
        if run_dir is None and resume is not None:
            run_dir = resolve_resume(resume)[0]
        command = command.without("checkpoint.resume")
        if self.command_check is not None:
            self.command_check(command, run_dir is not None)
        command, task = name_task(command, run_dir, default_task)
        schema = self.schema_for(task)
        if run_dir is None:
            cfg = config_lib.load_config(schema, command, self._config_dir(schema))
        else:
            cfg = config_lib.load_run_config(schema, run_dir, command)
            cfg.checkpoint.resume = resume
        check_task_sections(cfg)
        for check in self.checks:
            check(cfg)
        return cfg

    def load_config(self, overrides: list[str] | CommandLine | None = None, *,
                    default_task: str | None = None) -> DictConfig:
        """A new run's configuration (:meth:`configure` without ``checkpoint.resume``)."""
        return self.configure(parse_command_line(overrides).without("checkpoint.resume"), default_task=default_task)

    def load_run_config(self, run_dir: str, overrides: list[str] | CommandLine | None = None) -> DictConfig:
        """The configuration saved in ``run_dir/config.yaml``, updated by ``overrides`` (resume), checked."""
        return self.configure(overrides, run_dir=run_dir)

    def requested_config(self, argv: list[str] | CommandLine, *, default_task: str | None = None) -> DictConfig:
        """:meth:`configure` (the name the run-level tools call)."""
        return self.configure(argv, default_task=default_task)

    def help_schema(self, argv: list[str] | CommandLine, *, default_task: str | None = None) -> type:
        """The schema ``--help`` describes: the one of the task the command line names."""
        try:
            command = parse_command_line(argv if isinstance(argv, CommandLine) else [a for a in argv if "=" in a])
            return self.schema_for(name_task(command, None, default_task)[1])
        except ConfigError:
            return self.schema


def recipe_schemas() -> list[str]:
    """Every registered recipe's schemas, as ``module:class`` (the docs' configuration reference lists each)."""
    found = []
    for recipe in registered_recipes().values():
        for schema in (recipe.schema, recipe.task_schema):
            if schema is not None:
                found.append(f"{schema.__module__}:{schema.__qualname__}")
    return found


def register_recipe(recipe: Recipe) -> Recipe:
    """Adds ``recipe`` to the registry (its methods must not belong to another recipe)."""
    taken = {m: r.name for r in _RECIPES.values() if r.name != recipe.name for m in r.methods}
    clash = [m for m in recipe.methods if m in taken]
    if clash:
        raise ValueError(f"register_recipe({recipe.name!r}): {', '.join(clash)} already trained by {taken[clash[0]]!r}")
    _RECIPES[recipe.name] = recipe
    return recipe


def _import_recipes() -> None:
    for module in RECIPE_MODULES:
        importlib.import_module(module)


def registered_recipes() -> dict[str, Recipe]:
    """Every registered recipe, by name."""
    _import_recipes()
    return dict(_RECIPES)


def known_methods() -> list[str]:
    """Every method name a registered recipe trains."""
    return sorted(m for r in registered_recipes().values() for m in r.methods)


def recipe_for(method: str) -> Recipe:
    """The recipe that trains ``method`` (or the recipe named ``method``: ``expert``, ``ant_expert``).

    Raises:
        KeyError: an unknown method, with the known ones.
    """
    found = registered_recipes()
    for recipe in found.values():
        if method in recipe.methods:
            return recipe
    if method in found:
        return found[method]
    raise KeyError(f"unknown method {method!r}; known: {', '.join(known_methods())}")


def load_config_for(method: str) -> Callable[[list[str]], DictConfig]:
    """``overrides -> configuration`` of ``method`` (its recipe's loader with the method selected).

    Examples:
        >>> load_config_for("csirl-b")(["seed=3"]).csirl.intrinsic
        False
    """
    recipe = recipe_for(method)

    def load(overrides: list[str] | None = None) -> DictConfig:
        return recipe.load_config([*recipe.method_overrides(method), *(overrides or [])])

    return load

