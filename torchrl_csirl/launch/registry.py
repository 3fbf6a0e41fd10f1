"""Which recipe trained a method: the registry that run-level tools (``tools/summarize_runs.py``,
the sweep) use to read a run's configuration against its own recipe's defaults.

A recipe registers its method names with the function that loads its configuration; the tools
import the recipes they know (:data:`RECIPE_MODULES`) and look a method up by name.

Examples:
    >>> load_config_for("csirl")(["seed=3"]).seed
    3
    >>> load_config_for("gibberish")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    KeyError: "unknown method 'gibberish'; known: bc, csirl, csirl-b, ..."
"""
from __future__ import annotations

import importlib
from collections.abc import Callable, Iterable

from omegaconf import DictConfig

__all__ = ["RECIPE_MODULES", "known_methods", "load_config_for", "register_recipe"]

#: the glue modules (importable with recipes/ on sys.path) that register their recipes' methods
RECIPE_MODULES = ("torchrl_csirl.launch.csirl", "torchrl_csirl.launch.imitation")

_LOADERS: dict[str, Callable[[list[str]], DictConfig]] = {}


def register_recipe(methods: Iterable[str], load_config: Callable[[list[str]], DictConfig]) -> None:
    """Registers ``load_config(overrides)`` as the configuration loader of ``methods``."""
    for method in methods:
        _LOADERS[method] = load_config


def _import_recipes() -> None:
    for module in RECIPE_MODULES:
        importlib.import_module(module)


def known_methods() -> list[str]:
    """Every registered method name."""
    _import_recipes()
    return sorted(_LOADERS)


def load_config_for(method: str) -> Callable[[list[str]], DictConfig]:
    """The configuration loader of the recipe that trains ``method``."""
    _import_recipes()
    if method not in _LOADERS:
        raise KeyError(f"unknown method {method!r}; known: {', '.join(sorted(_LOADERS))}")
    return _LOADERS[method]
