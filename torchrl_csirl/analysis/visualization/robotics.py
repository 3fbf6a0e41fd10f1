"""The curriculum of a robotics task, drawn from its spec: the maze from above, or the matching features.

The picture reads the task's :class:`~torchrl_csirl.tasks.spec.TaskSpec` only:

* a task with a maze (``spec.maze_map``, AntMaze) is drawn from above: walls, the curriculum
  trajectory's matching features (the ant's x, y), its start, the goal and the subgoals;
* otherwise (Relocate) the matching features are drawn along the curriculum trajectory, one
  curve per named group of ``spec.observation_layout`` (the norm of the palm-object and of the
  object-target vector), with the subgoals marked: the states carry relative vectors only, so
  there is no absolute scene to draw them in.
"""
from __future__ import annotations

import os
from collections import defaultdict
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from torchrl_csirl.analysis.visualization._figure import as_int, new_figure, save_png
from torchrl_csirl.tasks.spec import TaskSpec

__all__ = ["plot_robotics_curriculum"]


def _observations(values: Any, spec: TaskSpec) -> np.ndarray:
    if hasattr(values, "detach"):
        values = values.detach().cpu().numpy()
    obs = np.asarray(values, dtype=np.float64)
    if obs.ndim != 2 or obs.shape[1] != spec.obs_dim or obs.shape[0] == 0:
        raise ValueError(f"curriculum observations must have shape [L, {spec.obs_dim}], got {obs.shape}.")
    return obs


def _feature_groups(spec: TaskSpec) -> dict[str, list[int]]:
    """Matching-feature indices grouped by the layout slice they belong to."""
    groups: dict[str, list[int]] = defaultdict(list)
    for index in spec.position_feature_indices:
        groups[spec.feature_name(index).split("[")[0]].append(index)
    return dict(groups)


def _draw_maze(ax, spec: TaskSpec) -> None:
    rows, cols, size = len(spec.maze_map), len(spec.maze_map[0]), spec.maze_cell_size
    for r, row in enumerate(spec.maze_map):
        for c, cell in enumerate(row):
            if cell == 1:
                x0, y0 = c * size - cols * size / 2, rows * size / 2 - (r + 1) * size
                ax.add_patch(_rectangle((x0, y0), size, size))
    ax.set_xlim(-cols * size / 2, cols * size / 2)
    ax.set_ylim(-rows * size / 2, rows * size / 2)
    ax.set_aspect("equal")


def _rectangle(corner, width, height):
    from matplotlib.patches import Rectangle

    return Rectangle(corner, width, height, facecolor="0.55", edgecolor="0.35")


def plot_robotics_curriculum(
    spec: TaskSpec,
    curriculum_observations: Any,
    subgoals: Sequence[int],
    path: str | os.PathLike,
    *,
    title: str | None = None,
) -> Path:
    """Draws a robotics task's curriculum trajectory with the selected subgoals (see the module doc).

    Args:
        spec: the task's spec (``resolve_scenario("antmaze-umaze")``, ...).
        curriculum_observations: ``[L, obs_dim]`` states of the curriculum trajectory.
        subgoals: selected curriculum indices in selection order (may be empty).
        path: where to write the PNG.

    Keyword Args:
        title (str, optional): figure title. Defaults to the task and counts.

    Returns:
        Path: ``path``.

    Examples:
        >>> import tempfile, torch
        >>> from torchrl_csirl.tasks import resolve_scenario
        >>> spec = resolve_scenario("relocate")
        >>> out = plot_robotics_curriculum(spec, torch.rand(50, 39), [10, 30], tempfile.mkdtemp() + "/c.png")
        >>> out.suffix
        '.png'
    """
    obs = _observations(curriculum_observations, spec)
    picks = [as_int(g, "subgoal") for g in subgoals]
    bad = [g for g in picks if not 0 <= g < len(obs)]
    if bad:
        raise ValueError(f"subgoals {bad} are outside the curriculum trajectory [0, {len(obs)}).")
    title = title or f"{spec.name}: curriculum ({len(obs)} states), {len(picks)} subgoal selections"
    if spec_has_maze(spec):
        fig = new_figure(700, 720)
        ax = fig.add_subplot(1, 1, 1)
        _draw_maze(ax, spec)
        x, y = obs[:, spec.position_feature_indices[0]], obs[:, spec.position_feature_indices[1]]
        ax.plot(x, y, "-", color="tab:blue", lw=1.5, label="curriculum trajectory")
        ax.plot(x[0], y[0], "o", color="tab:green", ms=10, label="start")
        if spec.finish_position is not None:
            ax.plot(*spec.finish_position, "X", color="tab:red", ms=12, label="goal")
        for order, g in enumerate(picks, start=1):
            ax.plot(x[g], y[g], "*", color="gold", mec="k", ms=16)
            ax.annotate(str(order), (x[g], y[g]), textcoords="offset points", xytext=(6, 6), fontsize=9)
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
    else:
        fig = new_figure(900, 480)
        ax = fig.add_subplot(1, 1, 1)
        steps = np.arange(len(obs))
        for name, indices in _feature_groups(spec).items():
            ax.plot(steps, np.linalg.norm(obs[:, indices], axis=1), lw=1.5, label=f"|{name}|")
        for order, g in enumerate(picks, start=1):
            ax.axvline(g, color="gold", lw=2, alpha=0.8)
            ax.annotate(str(order), (g, ax.get_ylim()[1]), textcoords="offset points", xytext=(3, -12), fontsize=9)
        ax.set_xlabel("curriculum state")
        ax.set_ylabel("matching feature norm")
    ax.set_title(title)
    ax.legend(loc="best", fontsize=9)
    fig.tight_layout()
    return save_png(fig, path)


def spec_has_maze(spec: TaskSpec) -> bool:
    """Whether the task is drawn as a maze from above (``spec.maze_map`` and 2 matching features)."""
    return getattr(spec, "maze_map", None) is not None and len(spec.position_feature_indices) == 2
