"""The benchmark's tables in Markdown and CSV: method rows x scenario columns, one set of tables per family of
tasks (driving: the expert-normalised accomplish rate beside the paper's Table I; robotics: the test return;
locomotion: the expert-normalised return beside the published results), each with outcomes, cost and the
difference from ``csirl``.

The rows come from :func:`torchrl_csirl.sweep.results.table_rows`.

Examples:
    >>> row = {"method": "csirl", "scenario": "merge", "runs": 2, "frames": "60000", "vs_csirl": None,
    ...        "normalized_accomplish_rate_mean": 0.85, "normalized_accomplish_rate_std": 0.05,
    ...        "success_rate_mean": None, "total_wall_s_mean": None}
    >>> print(markdown_table([row]).splitlines()[4])
    | csirl | 0.85 ± 0.05 (n=2) [0.92] |
"""
from __future__ import annotations

import csv
from collections.abc import Callable
from typing import Any

from torchrl_csirl.analysis.verdicts import ALPHA, BEYOND_NOISE, NO_DIFFERENCE, POWER
from torchrl_csirl.sweep.plan import (
    LOCOMOTION_ORDER,
    LOCOMOTION_TITLES,
    METHOD_ORDER,
    PAPER_ROBOTICS_METHODS,
    ROBOTICS_ORDER,
    SCENARIO_ORDER,
    TABLE_BUDGETS,
    return_task_order,
)
from torchrl_csirl.sweep.published import PAPER_TABLE, PUBLISHED_EXPERTS, PUBLISHED_GAP, PUBLISHED_LOCOMOTION, published_gap
from torchrl_csirl.sweep.results import off_budget

__all__ = ["budget_caption", "driving_tables", "locomotion_tables", "markdown_table", "published_table",
           "robotics_tables", "write_csv"]


def budget_caption(scenarios: list[str]) -> str:
    """The budget of ``scenarios``' columns (:data:`TABLE_BUDGETS`), for a table's caption.

    Examples:
        >>> budget_caption(["merge", "roundabout"])
        'every row at 60 000 frames per run (benchmark.py TABLE_BUDGETS; a cell run at another budget says so)'
    """
    budgets = {s: f"{TABLE_BUDGETS[s]:,}".replace(",", " ") for s in scenarios if s in TABLE_BUDGETS}
    if not budgets:  # tasks outside the paper's tables: the sweep's own collector.total_frames
        return "every row at the budget its runs record (their summaries' frames)"
    if len(set(budgets.values())) == 1:
        text = f"{next(iter(budgets.values()))} frames per run"
    else:
        text = ", ".join(f"{s} {b}" for s, b in budgets.items()) + " frames per run"
    return f"every row at {text} (benchmark.py TABLE_BUDGETS; a cell run at another budget says so)"





def _has(row: dict[str, Any] | None, field: str) -> bool:
    """Whether a table row has a mean of ``field`` (some of its runs measured it)."""
    return row is not None and row.get(f"{field}_mean") is not None


def _pm(mean: float | None, std: float | None, fmt: str = ".2f") -> str:
    return "n/a" if mean is None else f"{mean:{fmt}} ± {std:{fmt}}"


def _score(row: dict[str, Any] | None, paper: float | None, field: str = "normalized_accomplish_rate",
           fmt: str = ".2f") -> str:
    """``mean ± std (n=runs) [paper]`` of a table row's ``field`` (the expert-normalised accomplish rate)."""
    ours = "—" if row is None else f"{_pm(row[f'{field}_mean'], row[f'{field}_std'], fmt)} (n={row['runs']})"
    if row is not None and off_budget(row):
        ours += f" ({row['frames']} frames)"
    return ours + (f" [{paper:.2f}]" if paper is not None else "")


def _outcomes(row: dict[str, Any] | None, second: str = "crash_rate") -> str:
    """``success / crash`` (or ``success / <second>``) of a table row, ``—`` where a rate is missing."""
    if row is None or row["success_rate_mean"] is None:
        return "—"
    other = row[f"{second}_mean"]
    return f"{row['success_rate_mean']:.2f} / " + ("—" if other is None else f"{other:.2f}")


def _cost(row: dict[str, Any] | None) -> str:
    """``wall min, updates/s`` of a table row, ``—`` without a wall time."""
    if row is None or row["total_wall_s_mean"] is None:
        return "—"
    ups = row["updates_per_s_mean"]
    return f"{row['total_wall_s_mean'] / 60:.1f} min" + (f", {ups:.0f} upd/s" if ups else "")


def _difference(row: dict[str, Any] | None, fmt: str = "+.3f") -> str:
    """``+d (t x)`` against ``csirl``, in bold beyond seed noise (the verdict rule,
    :mod:`torchrl_csirl.analysis.verdicts`), else ``+d (t x; detectable m)`` with the minimum detectable difference;
    ``—`` without a comparison.

    Examples:
        >>> row = {"vs_csirl": -0.05, "vs_csirl_t": -1.39, "vs_csirl_beyond_noise": False, "vs_csirl_detectable": 0.193}
        >>> _difference(row), _difference(dict(row, vs_csirl_beyond_noise=True))
        ('-0.050 (t -1.4; detectable 0.193)', '**-0.050 (t -1.4)**')
    """
    if row is None or row.get("vs_csirl") is None:
        return "—"
    if row["vs_csirl_beyond_noise"]:
        return f"**{row['vs_csirl']:{fmt}} (t {row['vs_csirl_t']:.1f})**"
    return f"{row['vs_csirl']:{fmt}} (t {row['vs_csirl_t']:.1f}; detectable {row['vs_csirl_detectable']:{fmt.lstrip('+')}})"


def _method_table(caption: str, methods: list[str], scenarios: list[str],
                  entry: Callable[[str, str], str]) -> list[str]:
    """A caption, then method rows x scenario columns with ``entry(method, scenario)`` in each cell."""
    lines = [caption, "", "| method | " + " | ".join(scenarios) + " |", "|---" * (len(scenarios) + 1) + "|"]
    return lines + [f"| {m} | " + " | ".join(entry(m, s) for s in scenarios) + " |" for m in methods]


def _columns(rows: list[dict[str, Any]], order: tuple[str, ...]) -> tuple[list[str], list[str], dict]:
    """(scenario columns in ``order``, method rows, ``(method, scenario) -> row``) of the rows on those scenarios."""
    rows = [r for r in rows if r["scenario"] in order]
    scenarios = [s for s in order if any(r["scenario"] == s for r in rows)]
    return scenarios, list(dict.fromkeys(r["method"] for r in rows)), {(r["method"], r["scenario"]): r for r in rows}


def _comparison_table(rows: list[dict[str, Any]], scenarios: list[str], cell: dict, what: str,
                      fmt: str) -> list[str]:
    """The rows' difference from ``csirl`` (``what``), if any row has one."""
    compared = [r for r in rows if r["vs_csirl"] is not None and r["scenario"] in scenarios]
    if not compared:
        return []
    return [""] + _method_table(
        f"Difference from csirl ({what}; Welch's t over seeds; **bold**: {BEYOND_NOISE}, Holm-adjusted two-sided p "
        f"< {ALPHA} across the table's {compared[0]['vs_csirl_comparisons']} comparisons; otherwise {NO_DIFFERENCE}, "
        f"with the smallest difference the test detects with power {POWER} at two-sided {ALPHA}).",
        list(dict.fromkeys(r["method"] for r in compared)), scenarios, lambda m, s: _difference(cell.get((m, s)), fmt))


def driving_tables(rows: list[dict[str, Any]]) -> list[str]:
    """The driving scenarios' tables: ``ours [paper]`` expert-normalised accomplish rate, success / crash, cost,
    difference from ``csirl`` (no lines without a driving row)."""
    scenarios, methods, cell = _columns(rows, SCENARIO_ORDER)
    if not scenarios:
        return []
    lines = _method_table("Expert-normalised test accomplish rate, mean ± std over seeds (the paper's Table I in brackets), "
                          f"{budget_caption(scenarios)}.",
                          methods, scenarios, lambda m, s: _score(cell.get((m, s)), PAPER_TABLE.get(m, {}).get(s)))
    lines += [""] + _method_table(
        "Success rate / crash rate of the test episodes, mean over seeds (an accomplish rate earned by "
        "driving far and then crashing or stalling is not expert-like).",
        methods, scenarios, lambda m, s: _outcomes(cell.get((m, s))))
    lines += [""] + _method_table(
        "Cost per run: wall time [min] (start-up and final evaluation included) and updates/s, mean over runs.",
        methods, scenarios, lambda m, s: _cost(cell.get((m, s))))
    return lines + _comparison_table(rows, scenarios, cell, "expert-normalised", "+.3f")


def _return_format(row: dict[str, Any] | None) -> str:
    """Whole numbers for Relocate-sized returns (thousands), two decimals for AntMaze's goal indicator."""
    return ".0f" if row is not None and row["return_mean"] is not None and abs(row["return_mean"]) >= 100 else ".2f"


def robotics_tables(rows: list[dict[str, Any]]) -> list[str]:
    """The robotics tasks' tables: test return (the paper's metric there), success / progress, cost,
    difference from ``csirl`` in return (no lines without a robotics row; the locomotion tasks have theirs)."""
    order = tuple(s for s in return_task_order([r["scenario"] for r in rows]) if s not in LOCOMOTION_ORDER)
    scenarios, methods, cell = _columns(rows, order)
    if not scenarios:
        return []
    if all(s in ROBOTICS_ORDER for s in scenarios):  # the paper's robotics tasks
        returns = ("Test return on the robotics tasks, mean ± std over seeds (the paper's metric there; its Figure 7 "
                   f"gives curves for {', '.join(PAPER_ROBOTICS_METHODS)}, no numbers: on Relocate only CSIRL's return "
                   f"is positive), {budget_caption(scenarios)}.")
        outcomes = ("Success rate (AntMaze: goal reached; Relocate: ball at the target) / progress (the accomplish "
                    "rate's analogue, docs/studies/robotics.md), mean over seeds.")
    else:
        returns = f"Test return (the environment's own reward), mean ± std over seeds, {budget_caption(scenarios)}."
        outcomes = ("Success rate / accomplish rate (the success rate where the task has no finish, "
                    "docs/own-task.md), mean over seeds.")
    lines = _method_table(returns, methods, scenarios,
                          lambda m, s: _score(cell.get((m, s)), None, "return", _return_format(cell.get((m, s)))))
    lines += [""] + _method_table(outcomes, methods, scenarios, lambda m, s: _outcomes(cell.get((m, s)), "accomplish_rate"))
    lines += [""] + _method_table(
        "Cost per run: wall time [min] (start-up and final evaluation included) and updates/s, mean over runs.",
        methods, scenarios, lambda m, s: _cost(cell.get((m, s))))
    return lines + _comparison_table(rows, scenarios, cell, "test return", "+.1f")


def _thousands(value: float, fmt: str = ".0f") -> str:
    """``3 252.5``: thousands apart by a space, a minus sign as on the pages."""
    return f"{value:,{fmt}}".replace(",", " ").replace("-", "−")


def _ours_against_published(method: str, task: str, ours: float | None) -> str:
    """``return (gap)`` of ours against the published figure, **bold** more than :data:`PUBLISHED_GAP` below."""
    gap = published_gap(method, task, ours)
    if gap is None:
        return "—"
    text = f"{gap:+.2f}".replace("-", "−")
    return f"{_thousands(ours)} ({f'**{text}**' if gap < -PUBLISHED_GAP else text})"


def published_table(rows: list[dict[str, Any]]) -> list[str]:
    """The published locomotion results (:data:`PUBLISHED_LOCOMOTION`, raw returns) beside ours, task by task:
    the paper's return, our final test return and our best evaluation (mean over seeds), each of ours with its
    gap to the paper as a fraction of the paper's expert's return (both sides divided by the same expert);
    **bold** more than :data:`PUBLISHED_GAP` below; ``—`` where we have no run. No lines without a locomotion row."""
    scenarios, _, cell = _columns(rows, LOCOMOTION_ORDER)
    if not scenarios:
        return []
    methods = [m for m in METHOD_ORDER if m in PUBLISHED_LOCOMOTION]
    header, rule = ["method"], ["---"]
    for task in scenarios:
        name = LOCOMOTION_TITLES.get(task, task)
        header += [f"{name}: paper (expert {_thousands(PUBLISHED_EXPERTS[task], '.1f')})", f"{name}: ours, final",
                   f"{name}: ours, best evaluation"]
        rule += ["---"] * 3
    lines = [f"| {' | '.join(header)} |", f"|{'|'.join(rule)}|"]
    for method in methods:
        cells = [method]
        for task in scenarios:
            row = cell.get((method, task))
            cells.append(_thousands(PUBLISHED_LOCOMOTION[method][task]["return"], ".1f"))
            final = _ours_against_published(method, task, None if row is None else row["return_mean"])
            cells.append(f"{final} (at {row['frames']} frames)" if row is not None and off_budget(row) else final)
            cells.append(_ours_against_published(method, task, None if row is None else row["best_eval_return_mean"]))
        lines.append(f"| {' | '.join(cells)} |")
    return lines


def locomotion_tables(rows: list[dict[str, Any]]) -> list[str]:
    """The locomotion tasks' tables: expert-normalised test return (the baselines' papers' metric) with the
    published figure beside it, the test return, cost, difference from ``csirl``; then the published results
    with their sources (no lines without a locomotion row)."""
    scenarios, methods, cell = _columns(rows, LOCOMOTION_ORDER)
    if not scenarios:
        return []
    lines = _method_table(
        "Expert-normalised test return R / R_expert, mean ± std over seeds, R_expert the expert row's mean on the "
        f"same 50 test episodes (ours: the papers' figures are compared in raw returns, below); "
        f"{budget_caption(scenarios)}.",
        methods, scenarios, lambda m, s: _score(cell.get((m, s)), None, "normalized_return"))
    lines += [""] + _method_table(
        "Test return (gymnasium's own reward), mean ± std over seeds.", methods, scenarios,
        lambda m, s: _score(cell.get((m, s)), None, "return", ".0f"))
    evaluated = [m for m in methods if any(_has(cell.get((m, s)), "normalized_best_eval_return") for s in scenarios)]
    if evaluated:
        lines += [""] + _method_table(
            "Best evaluation during training, R / R_expert, mean ± std over seeds: the highest of a run's periodic "
            "evaluations (validation episodes), the figure the published rows report; optimistic (a maximum over "
            "noisy evaluations, scored on the episodes that chose it).", evaluated, scenarios,
            lambda m, s: _score(cell[(m, s)], None, "normalized_best_eval_return")
            if _has(cell.get((m, s)), "normalized_best_eval_return") else "—")
    lines += [""] + _method_table(
        "Cost per run: wall time [min] (start-up and final evaluation included) and updates/s, mean over runs.",
        methods, scenarios, lambda m, s: _cost(cell.get((m, s))))
    lines += _comparison_table(rows, scenarios, cell, "test return", "+.0f")
    published = published_table(rows)
    if not published:
        return lines
    return lines + ["", "Published results in raw returns (IQ-Learn's Table 3: one expert trajectory, as ours; other "
                    "papers, settings and sources: docs/benchmark.md#published-results) beside ours, mean over seeds; "
                    "in brackets ours minus the paper's, divided by the paper's expert's return (**bold**: more than "
                    f"{PUBLISHED_GAP} below).", "", *published]


def markdown_table(rows: list[dict[str, Any]]) -> str:
    """Method rows x scenario columns: the driving scenarios' tables (:func:`driving_tables`), then the
    robotics tasks' (:func:`robotics_tables`), then the locomotion tasks' (:func:`locomotion_tables`)."""
    parts = [part for part in (driving_tables(rows), robotics_tables(rows), locomotion_tables(rows)) if part]
    return "\n\n".join("\n".join(part) for part in parts)


def write_csv(rows: list[dict[str, Any]], path: str) -> str:
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    return path

