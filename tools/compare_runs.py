"""Two sets of finished runs side by side, per scenario: mean ± std over seeds and Welch's t-test.

For a change that should not move the results (``optim.precision=bf16`` against float32, a refactor)
or that should (an ablation, another method): each side's runs are grouped by scenario, and each
metric is compared seed set against seed set. Prints a Markdown table (to stderr) and, last, one JSON line.

Usage::

    python tools/compare_runs.py docs/runs/csirl/merge-csirl-s* --against docs/runs/precision/merge-csirl-bf16-s*
    python tools/compare_runs.py docs/runs/csirl --against docs/runs/precision --labels fp32 bf16

Examples:
    >>> from compare_runs import compare  # doctest: +SKIP
    >>> rows = compare([{"scenario": "merge", "method": "csirl", "normalized_accomplish_rate": v} for v in (0.9, 0.92)],
    ...                [{"scenario": "merge", "method": "bc", "normalized_accomplish_rate": v} for v in (0.8, 0.9)])
    >>> rows[0]["scenario"], rows[0]["methods"], rows[0]["metric"], rows[0]["n"]
    ('merge', ['csirl', 'bc'], 'normalized_accomplish_rate', [2, 2])
"""
from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict

from torchrl_csirl.launch.summaries import find_summaries, mean_std, welch_test

#: what is compared by default: the paper's metric, normalised, and the run's cost
METRICS = ("normalized_accomplish_rate", "success_rate", "crash_rate", "total_wall_s")


def _grouped(summaries: list[dict]) -> dict[str, list[dict]]:
    groups: dict[str, list[dict]] = defaultdict(list)
    for summary in summaries:
        groups[summary["scenario"]].append(summary)
    return groups


def _methods(summaries: list[dict]) -> str:
    return "+".join(sorted({s["method"] for s in summaries}))


def compare(first: list[dict], second: list[dict], metrics: tuple[str, ...] = METRICS,
            by_scenario: bool = True) -> list[dict]:
    """One row per (scenario, metric) both sides have: each side's methods, mean and std; Welch's test of second - first.

    With ``by_scenario=False`` each side is one group whatever its tasks (a task against its variant, e.g. a maze
    with a random goal against the same maze with a fixed one), named ``<first's tasks> / <second's tasks>``.
    """
    if by_scenario:
        a, b = _grouped(first), _grouped(second)
    else:
        key = " / ".join("+".join(sorted({s["scenario"] for s in side})) for side in (first, second))
        a, b = {key: first}, {key: second}
    rows = []
    for key in sorted(set(a) & set(b)):
        for metric in metrics:
            va = [s[metric] for s in a[key] if s.get(metric) is not None]
            vb = [s[metric] for s in b[key] if s.get(metric) is not None]
            if not va or not vb:
                continue
            rows.append({"scenario": key, "methods": [_methods(a[key]), _methods(b[key])], "metric": metric,
                         "n": [len(va), len(vb)],
                         "first": mean_std(va), "second": mean_std(vb), "test": welch_test(vb, va)})
    return rows


def _cell(stats: dict[str, float]) -> str:
    return f"{stats['mean']:.3g} ± {stats['std']:.2g}"


def markdown(rows: list[dict], labels: tuple[str, str]) -> str:
    """The rows as a Markdown table (difference = second - first; p of Welch's t-test)."""
    lines = [f"| scenario | metric | {labels[0]} | {labels[1]} | difference | Welch t (p) |", "|---|---|---|---|---|---|"]
    for row in rows:
        test = row["test"]
        verdict = "—" if test is None else f"{test['t']:.2f} ({test['p']:.2f})"
        difference = row["second"]["mean"] - row["first"]["mean"]
        lines.append(f"| {row['scenario']} | {row['metric']} | {_cell(row['first'])} | "
                     f"{_cell(row['second'])} | {difference:+.3g} | {verdict} |")
    return "\n".join(lines)


def _load(paths: list[str]) -> list[dict]:
    summaries = []
    for path in find_summaries(paths):
        with open(path) as f:
            summaries.append(json.load(f))
    return summaries


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("runs", nargs="+", help="run directories (or folders of runs): the first side")
    parser.add_argument("--against", nargs="+", required=True, help="run directories (or folders): the second side")
    parser.add_argument("--labels", nargs=2, default=("first", "second"), help="the two columns' names")
    parser.add_argument("--metrics", nargs="+", default=list(METRICS), help="summary.json fields to compare")
    parser.add_argument("--across-scenarios", action="store_true",
                        help="each side as one group whatever its tasks (a task against its variant)")
    args = parser.parse_args(argv)
    rows = compare(_load(args.runs), _load(args.against), tuple(args.metrics), by_scenario=not args.across_scenarios)
    if not rows:
        parser.error("the two sides share no scenario with the metrics asked for")
    print(markdown(rows, tuple(args.labels)), file=sys.stderr)
    result = {"labels": list(args.labels), "rows": rows}
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    main()
