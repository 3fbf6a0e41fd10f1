"""A run's health in one picture (``health.png``, :func:`plot_health`): four panels that show why a run failed.

1. The training reward against the task: the matching reward per step the learner collects (and its total
   training reward) over frames, beside the test success rate and the environment's return.
2. The critics against the Monte Carlo return of the learner's own reward, on the expert's states and on the
   policy's own (a point per state; the diagonal is a calibrated critic).
3. The curriculum and the exploration: the subgoal over frames; alpha and the policy's entropy.
4. Where the policy's episodes end along the demonstration (the share of the path covered), against the
   curriculum's subgoal.

Flagged checks are listed under the title.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from torchrl_csirl.analysis.visualization._figure import empty_message, new_figure, save_png

__all__ = ["plot_health"]


def _legend(ax, loc: str) -> None:
    """A legend, when something was drawn with a label."""
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc=loc, fontsize=7)


def _series(rows: list[dict[str, Any]], key: str) -> tuple[list[float], list[float]]:
    pairs = [(r["frames"], r[key]) for r in rows if r.get(key) is not None and r.get("frames") is not None]
    return [p[0] for p in pairs], [p[1] for p in pairs]


def _reward_panel(ax, rows: list[dict[str, Any]]) -> None:
    ax.set_title("training reward vs the task", fontsize=10)
    if not rows:
        empty_message(ax, "no round logged")
        return
    for key, label, color in (("matching_reward_mean", "matching reward / step", "C0"),
                              ("reward_mean", "training reward / step", "C1")):
        x, y = _series(rows, key)
        if x:
            ax.plot(x, y, color=color, label=label)
    ax.set_xlabel("environment frames")
    _legend(ax, "upper left")
    twin = ax.twinx()
    x, y = _series(rows, "eval_success_rate")
    if x:
        twin.plot(x, y, color="C2", linestyle="--", label="test success")
    x, y = _series(rows, "eval_accomplish_rate")
    if x:
        twin.plot(x, y, color="C3", linestyle=":", label="accomplish rate")
    twin.set_ylim(-0.02, 1.05)
    _legend(twin, "lower right")


def _critic_panel(ax, probe) -> None:
    ax.set_title("critics vs returns (learner's reward + entropy bonus)", fontsize=10)
    if probe is None:
        empty_message(ax, "not probed")
        return
    lows, highs = [], []
    for values, returns, label, color in ((probe.expert_values, probe.expert_returns, "expert's states", "C0"),
                                          (probe.policy_values, probe.policy_returns, "policy's states", "C1")):
        if returns.numel():
            q = values.mean(0) if values.ndim > 1 else values
            ax.scatter(returns.numpy(), q.numpy(), s=4, alpha=0.4, color=color, label=label)
            lows += [float(returns.min()), float(q.min())]
            highs += [float(returns.max()), float(q.max())]
    if lows:
        ax.plot([min(lows), max(highs)], [min(lows), max(highs)], color="0.3", linewidth=1, label="calibrated")
        _legend(ax, "upper left")
    ax.set_xlabel("Monte Carlo return")
    ax.set_ylabel("mean critic value")


def _curriculum_panel(ax, rows: list[dict[str, Any]]) -> None:
    ax.set_title("subgoal, alpha and entropy", fontsize=10)
    x, y = _series(rows, "subgoal")
    if not x:
        empty_message(ax, "no curriculum logged")
    else:
        ax.step(x, y, where="post", color="C4", label="subgoal")
        ax.set_ylabel("subgoal")
        _legend(ax, "upper left")
    ax.set_xlabel("environment frames")
    twin = ax.twinx()
    for key, color in (("alpha", "C5"), ("entropy", "C6")):
        x, y = _series(rows, key)
        if x:
            twin.plot(x, y, color=color, linestyle="--", label=key)
    _legend(twin, "lower right")


def _ends_panel(ax, report) -> None:
    ax.set_title("where the episodes end", fontsize=10)
    check = next((c for c in report.checks if c.name == "where_episodes_end" and c.ok is not None), None)
    if check is None:
        empty_message(ax, "not probed")
        return
    progress = check.figures["progress"]
    ax.hist(progress, bins=20, range=(0, 1), color="C1", alpha=0.8, label="policy's episodes")
    subgoals = [r["subgoal"] for r in report.rows if r.get("subgoal") is not None]
    if subgoals and report.probe is not None and report.probe.path_features.shape[0] > 1:
        ax.axvline(subgoals[-1] / (report.probe.path_features.shape[0] - 1), color="C4", linestyle="--",
                   label="last subgoal")
    ax.set_xlim(0, 1)
    ax.set_xlabel("share of the demonstration's path covered")
    ax.set_ylabel("episodes")
    _legend(ax, "upper left")


def plot_health(report, path: str | os.PathLike) -> Path:
    """The four panels of a :class:`~torchrl_csirl.analysis.diagnostics.HealthReport`, its flagged checks in the title.

    Examples:
        >>> import tempfile, pathlib
        >>> from torchrl_csirl.analysis.diagnostics import HealthReport
        >>> out = pathlib.Path(tempfile.mkdtemp()) / "health.png"
        >>> plot_health(HealthReport("runs/x", "merge", "csirl"), out) == out
        True
    """
    fig = new_figure(1100, 800)
    flagged = ", ".join(c.name for c in report.flagged) or "none"
    fig.suptitle(f"{report.method} on {report.task}: health (flagged: {flagged})", fontsize=11)
    axes = [fig.add_subplot(2, 2, i) for i in range(1, 5)]
    _reward_panel(axes[0], report.rows)
    _critic_panel(axes[1], report.probe)
    _curriculum_panel(axes[2], report.rows)
    _ends_panel(axes[3], report)
    fig.tight_layout(rect=(0, 0, 1, 0.96))
    return save_png(fig, path)
