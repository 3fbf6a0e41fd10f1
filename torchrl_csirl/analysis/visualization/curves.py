"""Training curves: evaluation accomplish rate and the curricular subgoal selections."""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
from matplotlib import cm, colormaps
from matplotlib.colors import Normalize
from matplotlib.ticker import EngFormatter, MaxNLocator

from torchrl_csirl.analysis.visualization._figure import (
    as_int,
    empty_message,
    finite_array,
    new_figure,
    require_keys,
    save_png,
)

__all__ = ["plot_learning_curve", "plot_method_curves", "plot_subgoal_curriculum"]

#: profiles drawn at most in the uncertainty panel (evenly subsampled, first and last kept)
MAX_PROFILES = 40


def _column(records: Sequence[Mapping[str, Any]], key: str) -> np.ndarray:
    """``record[key]`` for every record as floats, NaN where the key is absent or None."""
    values = [record.get(key) for record in records]
    return np.asarray([np.nan if v is None else float(v) for v in values], dtype=np.float64)


def plot_learning_curve(
    evaluations: Sequence[Mapping[str, Any]],
    path: str | os.PathLike,
    *,
    title: str | None = None,
    expert_accomplish_rate: float | None = None,
) -> Path:
    """Plots the evaluation accomplish rate (and success rate) against environment frames.

    Args:
        evaluations: one mapping per evaluation with ``"frames"`` (int) and
            ``"accomplish_rate"`` (float in ``[0, 1]``); optional ``"success_rate"`` and
            ``"accomplish_rate_std"`` (a shaded ``mean +- std`` band). Records are sorted by
            frames; an empty sequence gives a figure saying "no evaluation yet".
        path: where to write the PNG (parent folders are created).

    Keyword Args:
        title (str, optional): figure title. Defaults to ``"Evaluation"``.
        expert_accomplish_rate (float, optional): the expert's accomplish rate, drawn as a
            horizontal dashed line.

    Returns:
        Path: ``path`` (a 600 x 400 px PNG).

    Examples:
        >>> import tempfile, pathlib
        >>> out = pathlib.Path(tempfile.mkdtemp()) / "curve.png"
        >>> evals = [{"frames": 0, "accomplish_rate": 0.1}, {"frames": 5000, "accomplish_rate": 0.6}]
        >>> plot_learning_curve(evals, out, expert_accomplish_rate=0.95) == out, out.stat().st_size > 0
        (True, True)
    """
    records = list(evaluations)
    for i, record in enumerate(records):
        require_keys(record, ("frames", "accomplish_rate"), "evaluations", i)
    records.sort(key=lambda r: as_int(r["frames"], "frames"))
    fig = new_figure(600, 400)
    ax = fig.add_subplot(1, 1, 1)
    ax.set_title(title if title is not None else "Evaluation")
    if not records:
        empty_message(ax, "no evaluation yet")
    else:
        _draw_rates(ax, records)
    if expert_accomplish_rate is not None:
        ax.axhline(
            float(expert_accomplish_rate), color="0.25", linestyle="--", linewidth=1.2,
            label=f"expert accomplish rate ({float(expert_accomplish_rate):.2f})",
        )
    if records or expert_accomplish_rate is not None:
        _rate_axes(ax, "rate", legend_loc="lower right", fontsize=9)
    fig.tight_layout()
    return save_png(fig, path)


def _rate_axes(ax, ylabel: str, legend_loc: str, fontsize: int, rate: bool = True) -> None:
    """A rate in [0, 1] (or, ``rate=False``, any value: limits from the data) against environment frames:
    limits, labels, grid, legend (``legend_loc="outside"``: right of the axes, clear of the data)."""
    if rate:
        ax.set_ylim(-0.02, 1.05)
    ax.set_ylabel(ylabel)
    ax.set_xlabel("environment frames")
    ax.xaxis.set_major_formatter(EngFormatter(sep=""))
    ax.grid(True, alpha=0.3)
    if legend_loc == "outside":
        ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, fontsize=fontsize)
    else:
        ax.legend(loc=legend_loc, fontsize=fontsize)


def _draw_rates(ax, records: list[Mapping[str, Any]]) -> None:
    frames = np.asarray([as_int(r["frames"], "frames") for r in records], dtype=np.float64)
    accomplish = _column(records, "accomplish_rate")
    ax.plot(frames, accomplish, "o-", color="tab:blue", markersize=4, label="accomplish rate")
    std = _column(records, "accomplish_rate_std")
    if np.isfinite(std).any():
        std = np.nan_to_num(std, nan=0.0)
        ax.fill_between(frames, accomplish - std, accomplish + std, color="tab:blue", alpha=0.2,
                        linewidth=0, label="accomplish rate +- std")
    success = _column(records, "success_rate")
    known = np.isfinite(success)
    if known.any():
        ax.plot(frames[known], success[known], "s--", color="tab:orange", markersize=4,
                label="success rate")
    if frames.size == 1:  # a single point: give the x axis some room around it
        ax.set_xlim(frames[0] - max(1.0, 0.1 * frames[0]), frames[0] + max(1.0, 0.1 * frames[0]))


def plot_method_curves(
    curves: Mapping[str, Sequence[tuple[Sequence[float], Sequence[float]]]],
    path: str | os.PathLike,
    *,
    references: Mapping[str, float] | None = None,
    title: str | None = None,
    ylabel: str = "test accomplish rate",
    rate: bool = True,
    method_order: Sequence[str] | None = None,
) -> Path:
    """Learning curves of several methods (the paper's Figures 6 and 7): mean +- std over seeds per method.

    Each method's runs are evaluated on the same schedule; a method's curve is drawn at the
    frames all of its runs reached (the shortest run), its band is the standard deviation over
    runs (zero for one run). Reference methods (no training) are horizontal dashed lines.

    Args:
        curves: method -> one ``(frames, rates)`` pair per run (seed).
        path: where to write the PNG (parent folders are created).

    Keyword Args:
        references: method -> a constant rate (e.g. the expert's and random actions').
        title (str, optional): figure title.
        ylabel (str): the y axis label.
        rate (bool): the values are rates, drawn on [0, 1]; ``False`` (e.g. returns): the axis follows the data.
        method_order (sequence of str, optional): every method that may be drawn, in one fixed order: a method keeps
            its colour (its place in this order) and its place in the legend from figure to figure; others follow.
            Default: the drawn methods sorted.

    Returns:
        Path: ``path`` (an 860 x 450 px PNG, the legend right of the curves).

    Examples:
        >>> import tempfile, pathlib
        >>> out = pathlib.Path(tempfile.mkdtemp()) / "merge.png"
        >>> runs = [([0, 500, 1000], [0.1, 0.4, 0.6]), ([0, 500, 1000], [0.2, 0.5, 0.8])]
        >>> plot_method_curves({"csirl": runs}, out, references={"expert": 0.95}) == out
        True
    """
    fig = new_figure(860, 450)
    ax = fig.add_subplot(1, 1, 1)
    ax.set_title(title if title is not None else "Learning curves")
    palette = [*colormaps["tab10"].colors, *colormaps["Dark2"].colors]  # 18 colours before one repeats
    order = list(method_order or []) + sorted(m for m in curves if m not in (method_order or []))
    curves_drawn = False
    for method in sorted(curves, key=order.index):  # the legend in ``method_order``
        k, runs = order.index(method), curves[method]
        runs = [(finite_array(f, "frames"), finite_array(r, "rates")) for f, r in runs]
        runs = [(f, r) for f, r in runs if f.size and f.size == r.size]
        if not runs:
            continue
        length = min(f.size for f, _ in runs)
        frames = runs[0][0][:length]
        rates = np.stack([r[:length] for _, r in runs])
        mean, std = rates.mean(0), rates.std(0, ddof=1) if len(runs) > 1 else np.zeros(length)
        color = palette[k % len(palette)]
        ax.plot(frames, mean, "o-", color=color, markersize=3, label=f"{method} ({len(runs)} run{'s' * (len(runs) > 1)})")
        ax.fill_between(frames, mean - std, mean + std, color=color, alpha=0.2, linewidth=0)
        curves_drawn = True
    for k, (method, level) in enumerate(sorted((references or {}).items())):
        ax.axhline(float(level), color=str(0.15 + 0.3 * (k % 3)), linestyle="--", linewidth=1.2,
                   label=f"{method} ({float(level):.2f})")
    if not (curves_drawn or references):
        empty_message(ax, "no finished run")
    else:
        _rate_axes(ax, ylabel, legend_loc="outside", fontsize=8, rate=rate)
        if not curves_drawn:  # reference lines only: no frame axis to show
            ax.set_xticks([])
            ax.set_xlabel("no evaluation curve recorded")
    fig.tight_layout()
    return save_png(fig, path)


def plot_subgoal_curriculum(
    selections: Sequence[Mapping[str, Any]],
    path: str | os.PathLike,
    *,
    curriculum_length: int,
    delta: float | None = None,
) -> Path:
    """Plots the subgoal index over training and the critics' uncertainty profiles.

    Top panel: subgoal index after each selection against environment frames (a step plot,
    y in ``[0, curriculum_length - 1]``). Bottom panel: the uncertainty profile ``U_i`` over the
    curriculum states at every selection (colour = selection order, a star at the selected
    subgoal; log scale when the positive values span more than two decades; at most
    :data:`MAX_PROFILES` evenly spaced profiles are drawn). When some selection carries
    ``"ratios"``, a third panel shows the scan ratios ``U_p / U^avg`` with the threshold
    ``delta`` as a dashed line.

    Args:
        selections: one mapping per selection with ``"frames"`` (int), ``"subgoal"`` (int, the
            subgoal after the selection), ``"profile"`` (``curriculum_length`` floats) and
            optionally ``"ratios"``. Ratios are best given with ``curriculum_length`` entries,
            NaN where not scanned (``SubgoalSelection.ratios.tolist()``); a shorter list is
            taken as the scanned run ending at the new subgoal when its last ratio exceeds
            ``delta`` (or, without ``delta``, when the subgoal moved), else at the last state.
            An empty sequence gives a figure saying "no subgoal selection yet".
        path: where to write the PNG (parent folders are created).

    Keyword Args:
        curriculum_length (int): number of curriculum states ``L``.
        delta (float, optional): the selection threshold on the ratios.

    Returns:
        Path: ``path`` (a 700 x 600 px PNG, 700 x 800 with the ratio panel).

    Examples:
        >>> import tempfile, pathlib
        >>> out = pathlib.Path(tempfile.mkdtemp()) / "subgoals.png"
        >>> sels = [{"frames": 1000, "subgoal": 3, "profile": [1.0, 1.0, 1.2, 9.0, 2.0]},
        ...         {"frames": 2000, "subgoal": 4, "profile": [0.5, 0.5, 0.6, 0.7, 8.0]}]
        >>> plot_subgoal_curriculum(sels, out, curriculum_length=5, delta=5.0) == out
        True
    """
    length = as_int(curriculum_length, "curriculum_length")
    if length < 1:
        raise ValueError(f"curriculum_length must be >= 1, got {length}.")
    records = _check_selections(selections, length)
    ratio_rows = _ratio_rows(records, length, delta)
    with_ratios = any(np.isfinite(row).any() for row in ratio_rows)
    fig = new_figure(700, 800 if with_ratios else 600)
    n_panels = 3 if with_ratios else 2
    ax_goal = fig.add_subplot(n_panels, 1, 1)
    ax_profile = fig.add_subplot(n_panels, 1, 2)
    title = "Curricular subgoals" + (f" (delta = {float(delta):g})" if delta is not None else "")
    ax_goal.set_title(title)
    if not records:
        empty_message(ax_goal, "no subgoal selection yet")
        empty_message(ax_profile, "no uncertainty profile yet")
    else:
        colors = _order_colors(len(records))
        _draw_subgoal_steps(ax_goal, records, length)
        _draw_profiles(ax_profile, records, colors, length)
        if with_ratios:
            _draw_ratios(fig.add_subplot(n_panels, 1, 3), ratio_rows, colors, length, delta)
    fig.subplots_adjust(left=0.1, right=0.87 if records else 0.97, top=0.95, bottom=0.07, hspace=0.45)
    if records:
        _order_colorbar(fig, fig.axes[1:], len(records))
    return save_png(fig, path)


def _order_colorbar(fig, axes: list, count: int) -> None:
    """A colour bar (selection order) to the right of ``axes``, in its own axes."""
    boxes = [ax.get_position() for ax in axes]
    bottom, top = min(b.y0 for b in boxes), max(b.y1 for b in boxes)
    cax = fig.add_axes((0.89, bottom, 0.02, top - bottom))
    mappable = cm.ScalarMappable(norm=Normalize(1, max(count, 2)), cmap="viridis")
    fig.colorbar(mappable, cax=cax, label="selection (order)", ticks=MaxNLocator(integer=True))


def _check_selections(selections: Sequence[Mapping[str, Any]], length: int) -> list[dict]:
    records = []
    for i, record in enumerate(selections):
        require_keys(record, ("frames", "subgoal", "profile"), "selections", i)
        subgoal = as_int(record["subgoal"], f"selections[{i}]['subgoal']")
        if not 0 <= subgoal < length:
            raise ValueError(f"selections[{i}]['subgoal'] = {subgoal} is outside [0, {length - 1}].")
        profile = finite_array(record["profile"], f"selections[{i}]['profile']")
        if profile.size != length:
            raise ValueError(
                f"selections[{i}]['profile'] has {profile.size} values, expected curriculum_length={length}."
            )
        ratios = record.get("ratios")
        records.append(
            {
                "frames": as_int(record["frames"], f"selections[{i}]['frames']"),
                "subgoal": subgoal,
                "profile": profile,
                "ratios": None if ratios is None else finite_array(ratios, f"selections[{i}]['ratios']"),
            }
        )
    return records


def _ratio_rows(records: list[dict], length: int, delta: float | None) -> list[np.ndarray]:
    """Every selection's ratios as a length-``L`` row (NaN where not scanned)."""
    rows = []
    previous = None
    for record in records:
        row = np.full(length, np.nan)
        ratios = record["ratios"]
        if ratios is not None and ratios.size == length:
            row = ratios.copy()
        elif ratios is not None and 0 < ratios.size < length:
            if delta is not None:
                ends_at_subgoal = bool(ratios[-1] > delta)
            else:
                ends_at_subgoal = previous is not None and record["subgoal"] != previous
            end = record["subgoal"] if ends_at_subgoal else length - 1
            start = max(end - ratios.size + 1, 0)
            row[start : end + 1] = ratios[ratios.size - (end + 1 - start) :]
        elif ratios is not None and ratios.size > length:
            raise ValueError(f"ratios have {ratios.size} values, more than curriculum_length={length}.")
        rows.append(row)
        previous = record["subgoal"]
    return rows


def _order_colors(count: int) -> np.ndarray:
    return colormaps["viridis"](np.linspace(0.0, 1.0, count) if count > 1 else [0.0])


def _shown_indices(count: int) -> np.ndarray:
    if count <= MAX_PROFILES:
        return np.arange(count)
    return np.unique(np.linspace(0, count - 1, MAX_PROFILES).round().astype(int))


def _draw_subgoal_steps(ax, records: list[dict], length: int) -> None:
    frames = np.asarray([r["frames"] for r in records], dtype=np.float64)
    subgoals = np.asarray([r["subgoal"] for r in records], dtype=np.float64)
    ax.step(frames, subgoals, where="post", color="tab:green", linewidth=1.5)
    ax.plot(frames, subgoals, "o", color="tab:green", markersize=3)
    ax.set_ylim(-0.5, length - 0.5)
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax.xaxis.set_major_formatter(EngFormatter(sep=""))
    ax.set_xlabel("environment frames")
    ax.set_ylabel("subgoal index")
    ax.grid(True, alpha=0.3)
    if frames.size == 1:
        ax.set_xlim(frames[0] - max(1.0, 0.1 * frames[0]), frames[0] + max(1.0, 0.1 * frames[0]))


def _log_scale_needed(rows: list[np.ndarray]) -> bool:
    values = np.concatenate(rows) if rows else np.zeros(0)
    positive = values[np.isfinite(values) & (values > 0)]
    return positive.size > 1 and positive.max() / positive.min() > 100.0


def _draw_profiles(ax, records: list[dict], colors: np.ndarray, length: int) -> None:
    index = np.arange(length)
    shown = _shown_indices(len(records))
    for k in shown:
        profile = records[k]["profile"]
        ax.plot(index, profile, "-", color=colors[k], linewidth=1.0, alpha=0.85)
        goal = records[k]["subgoal"]
        if np.isfinite(profile[goal]):
            ax.plot([goal], [profile[goal]], "*", color=colors[k], markersize=11,
                    markeredgecolor="black", markeredgewidth=0.6)
    if _log_scale_needed([records[k]["profile"] for k in shown]):
        ax.set_yscale("log")
    ax.set_xlim(-0.5, length - 0.5)
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("curriculum state i")
    ax.set_ylabel("uncertainty U_i")
    ax.grid(True, alpha=0.3)
    ax.set_title(f"uncertainty profiles (star: selected subgoal; {len(shown)} of {len(records)} shown)",
                 fontsize=9)


def _draw_ratios(ax, rows: list[np.ndarray], colors: np.ndarray, length: int, delta: float | None) -> None:
    index = np.arange(length)
    for k in _shown_indices(len(rows)):
        row = np.where(np.isinf(rows[k]), np.nan, rows[k])
        if np.isfinite(row).any():
            ax.plot(index, row, ".-", color=colors[k], linewidth=0.8, markersize=4, alpha=0.85)
    if delta is not None:
        ax.axhline(float(delta), color="tab:red", linestyle="--", linewidth=1.2, label=f"delta = {float(delta):g}")
        ax.legend(loc="upper left", fontsize=8)
    if _log_scale_needed(rows + ([np.asarray([float(delta)])] if delta is not None else [])):
        ax.set_yscale("log")
    ax.set_xlim(-0.5, length - 0.5)
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("curriculum state p")
    ax.set_ylabel("U_p / U_avg")
    ax.grid(True, alpha=0.3)
    ax.set_title("scan ratios", fontsize=9)
