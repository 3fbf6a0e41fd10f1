"""Shared plumbing: stateless matplotlib figures (no pyplot, no global backend) saved as PNG."""
from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any, Mapping

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

__all__ = ["as_int", "empty_message", "finite_array", "new_figure", "require_keys", "save_png"]


def new_figure(width_px: float, height_px: float, dpi: int = 100) -> Figure:
    """A ``Figure`` of ``width_px x height_px`` pixels with its own Agg canvas (pyplot untouched)."""
    fig = Figure(figsize=(width_px / dpi, height_px / dpi), dpi=dpi)
    FigureCanvasAgg(fig)
    return fig


def save_png(fig: Figure, path: str | os.PathLike) -> Path:
    """Writes ``fig`` to ``path`` as PNG (parent folders created) and returns the path."""
    path = Path(path)
    if path.suffix.lower() != ".png":
        raise ValueError(f"expected a .png path, got {str(path)!r}.")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, format="png", dpi=fig.dpi)
    return path


def finite_array(values: Any, name: str) -> np.ndarray:
    """``values`` (list, numpy array or tensor) as a 1-D float64 array (NaN/inf kept)."""
    if hasattr(values, "detach"):
        values = values.detach().cpu().numpy()
    try:
        return np.asarray(values, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError) as err:
        raise TypeError(f"{name} must be a sequence of numbers, got {values!r}.") from err


def require_keys(record: Mapping[str, Any], keys: tuple[str, ...], what: str, index: int) -> None:
    """Raises ``KeyError`` naming the record when one of ``keys`` is missing."""
    if not isinstance(record, Mapping):
        raise TypeError(f"{what}[{index}] must be a mapping, got {type(record).__name__}.")
    missing = [k for k in keys if k not in record]
    if missing:
        raise KeyError(f"{what}[{index}] lacks {missing}; it has {sorted(record)}.")


def empty_message(ax, text: str) -> None:
    """Writes ``text`` in the middle of an axes that has nothing to show."""
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes, fontsize=13, color="0.35")
    ax.set_xticks([])
    ax.set_yticks([])


def as_int(value: Any, name: str) -> int:
    """An int from a Python/numpy/one-element-tensor integer (TypeError otherwise)."""
    if hasattr(value, "item") and getattr(value, "ndim", None) == 0:
        value = value.item()  # numpy scalars, 0-d arrays and tensors
    elif hasattr(value, "numel") and value.numel() == 1:
        value = value.item()
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        if isinstance(value, float) and math.isfinite(value) and value == int(value):
            return int(value)
        raise TypeError(f"{name} must be an integer, got {value!r}.")
    return int(value)
