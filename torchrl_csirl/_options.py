"""A hyperparameter declared once: its default, the values it accepts and a one-line help.

:func:`option` is how a dataclass field of the configuration (:mod:`torchrl_csirl.run.config`)
or of a learner's hyperparameters (:mod:`torchrl_csirl.hyperparameters`) is declared. This module
imports nothing of the package, so that both can use it.
"""
from __future__ import annotations

from dataclasses import field
from typing import Any

__all__ = ["option"]


def option(default: Any, *, choices: tuple | None = None, minimum: float | None = None,
           above: float | None = None, below: float | None = None, help: str = "") -> Any:
    """A schema leaf: its default and what values :func:`~torchrl_csirl.run.config.validate` accepts.

    Args:
        default: the default value (its type comes from the field's annotation).
        choices: the allowed values, or a callable returning them when a value is checked (a
            registry that grows at run time).
        minimum: the smallest allowed value (inclusive).
        above: values must be strictly greater.
        below: values must be strictly smaller.
        help: one line shown by :func:`~torchrl_csirl.run.config.describe` (``--help``).

    Examples:
        >>> from dataclasses import dataclass, fields
        >>> @dataclass
        ... class C:
        ...     k: int = option(2, minimum=1, help="environments")
        >>> fields(C)[0].metadata["minimum"], C().k
        (1, 2)
    """
    metadata = {"choices": choices, "minimum": minimum, "above": above, "below": below, "help": help}
    return field(default=default, metadata=metadata)
