"""The benchmark's learning-curve figures (the paper's Figures 6 and 7): per scenario or task, every trained
method's evaluation curve (mean ± std over seeds) with the reference rows as lines, titled with how the
points were evaluated.

Examples:
    >>> [kind[0] for kind in curve_kinds("hopper")], LEARNER_ORDER[:3]
    (['curves'], ('sac', 'bc', 'gail'))
"""
from __future__ import annotations

import os
import textwrap
from collections import defaultdict
from typing import Any

from omegaconf import OmegaConf

from torchrl_csirl.run.config import EvalConfig
from torchrl_csirl.sweep.plan import (
    ABLATIONS,
    LOCOMOTION_ORDER,
    METHOD_ORDER,
    REFERENCE_METHODS,
    SCENARIO_ORDER,
    is_robotics,
    return_task_order,
)
from torchrl_csirl.sweep.results import eval_curve

__all__ = ["LEARNER_ORDER", "curve_kinds", "evaluation_schedule", "learning_curve_figures"]


def evaluation_schedule(run_dirs: list[str]) -> str:
    """How the curves' points of ``run_dirs`` were evaluated (their ``config.yaml``), for a figure's title.

    The periodic evaluations play ``eval.episodes`` episodes from ``eval.validation_seed`` (a range
    apart from the test episodes) or, in runs recorded before that key or with it null, the first
    test episodes.

    Examples:
        >>> evaluation_schedule([])
        ''
    """
    kinds = set()
    for run_dir in run_dirs:
        path = os.path.join(run_dir, "config.yaml")
        if not os.path.isfile(path):
            continue
        evaluation = OmegaConf.load(path).get("eval", {})
        where = "validation" if evaluation.get("validation_seed") is not None else "test"
        kinds.add(f"{evaluation.get('episodes', EvalConfig.episodes)} {where} episodes per point")
    if len(kinds) > 1:
        return "points of differing evaluations (" + "; ".join(sorted(kinds)) + ")"
    return next(iter(kinds), "")


def curve_kinds(scenario: str) -> list[tuple[str, str, str, str, bool]]:
    """The evaluation curves drawn for ``scenario``: ``(file prefix, summary key, curve key, y label, rate)``.

    The driving scenarios get the accomplish rate (the paper's Figure 6); the robotics tasks the return
    (its Figure 7) and, since AntMaze's return is the goal indicator (flat at 0 for most methods), the
    progress too; the locomotion tasks the return alone.

    Examples:
        >>> [kind[0] for kind in curve_kinds("merge")], [kind[0] for kind in curve_kinds("antmaze-umaze")]
        (['curves'], ['curves', 'progress'])
    """
    rate = ("accomplish_rate", "eval_accomplish_rate")
    if not is_robotics(scenario):
        return [("curves", *rate, "evaluation accomplish rate (raw)", True)]
    if scenario in LOCOMOTION_ORDER:  # no goal, no progress: the return alone
        return [("curves", "return", "eval_env_return", "evaluation return", False)]
    return [("curves", "return", "eval_env_return", "evaluation return", False),
            ("progress", *rate, "evaluation progress", True)]


#: the trained rows and CSIRL's variants, in the table's order: each keeps its colour in every figure
LEARNER_ORDER = tuple(m for m in (*METHOD_ORDER, *ABLATIONS) if m not in REFERENCE_METHODS)


def learning_curve_figures(runs: list[dict[str, Any]], out_dir: str) -> list[str]:
    """PNGs per scenario (``curve_kinds``): every trained method's evaluation curve (mean ± std over seeds),
    the reference rows as lines."""
    from torchrl_csirl.analysis.visualization import plot_method_curves

    paths = []
    order = (*SCENARIO_ORDER, *return_task_order([r["scenario"] for r in runs]))
    for scenario in [s for s in order if any(r["scenario"] == s for r in runs)]:
        schedule = evaluation_schedule([r["run_dir"] for r in runs if r["scenario"] == scenario
                                        and r["method"] not in REFERENCE_METHODS])
        for prefix, summary_key, curve_key, label, rate in curve_kinds(scenario):
            curves: dict[str, list] = defaultdict(list)
            references: dict[str, list[float]] = defaultdict(list)
            for run in (r for r in runs if r["scenario"] == scenario):
                if run["method"] in REFERENCE_METHODS:
                    if run.get(summary_key) is not None:
                        references[run["method"]].append(float(run[summary_key]))
                else:
                    curves[run["method"]].append(eval_curve(run["run_dir"], curve_key))
            path = plot_method_curves(curves, os.path.join(out_dir, f"{prefix}_{scenario}.png"),
                                      references={m: sum(v) / len(v) for m, v in references.items()},
                                      title=f"{scenario}: {label}" + (f"\n{textwrap.fill(schedule, 72)}" if schedule else ""),
                                      ylabel=label,
                                      rate=rate, method_order=LEARNER_ORDER)
            paths.append(os.fspath(path))
    return paths

