"""Two sets of finished runs side by side, per scenario: mean ± std over seeds, Welch's t-test and the verdict rule,
and every difference of configuration and code between and within the two sets.

For a change that should not move the results (``optim.precision=bf16`` against float32, a refactor)
or that should (an ablation, another method): each side's runs are grouped by scenario, and each
metric is compared seed set against seed set (second - first) with the rule of ``torchrl_csirl.analysis.verdicts``:
"beyond seed noise" when Holm's correction across the metric's comparisons (``--comparisons``: the study section's
count, when it holds more) leaves p < 0.05, else "no difference detected" with the smallest difference the test
could have detected. Below the table, every configuration key (``config.yaml``) whose values differ between the two
sides or within one, and every difference of code (``provenance.json``: commit, dirty tree and its diff's hash,
package versions; the machine's CPU and threads beside them); runs without ``provenance.json`` (records made before
runs wrote it) are ``provenance: unknown``.

``--one-change KEY`` asks for a comparison of one change: it is refused, in one line and exit status 2, when anything
but ``KEY`` differs (a configuration key between or within the sides, the code, or a run's unknown provenance), or
when ``KEY`` itself does not. The seed, ``logger.*`` and ``checkpoint.*`` never count (:data:`NOT_A_CHANGE`);
``--ignore`` adds keys (the command line then says which were set aside). Prints a Markdown table and the
differences (to stderr) and, last, one JSON line.

Usage::

    torchrl-csirl compare docs/runs/csirl/merge-csirl-s* --against docs/runs/precision/merge-csirl-bf16-s*
    torchrl-csirl compare docs/runs/csirl --against docs/runs/precision --labels fp32 bf16
    torchrl-csirl compare runs/a-s* --against runs/b-s* --one-change csirl.fixed_alpha

Examples:
    >>> rows = compare([{"scenario": "merge", "method": "csirl", "normalized_accomplish_rate": v} for v in (0.9, 0.92)],
    ...                [{"scenario": "merge", "method": "bc", "normalized_accomplish_rate": v} for v in (0.8, 0.9)])
    >>> rows[0]["scenario"], rows[0]["methods"], rows[0]["metric"], rows[0]["n"], rows[0]["test"]["verdict"]
    ('merge', ['csirl', 'bc'], 'normalized_accomplish_rate', [2, 2], 'no difference detected')
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from collections import defaultdict
from typing import Any

from omegaconf import OmegaConf

from torchrl_csirl.analysis.summaries import find_summaries, mean_std
from torchrl_csirl.analysis.verdicts import compare_family, compare_seeds, describe
from torchrl_csirl.run.config import flatten_config
from torchrl_csirl.run.provenance import code_fields, machine_fields, read_provenance

__all__ = ["compare", "differences", "main", "markdown", "one_change_refusal", "run_fields", "what_differs"]

PROG = "torchrl-csirl compare"
#: what is compared by default: the paper's metric, normalised, and the run's cost
METRICS = ("normalized_accomplish_rate", "success_rate", "crash_rate", "total_wall_s")
#: configuration keys that are no change between runs: the seed (runs of one side differ in it) and where a run
#: logs and checkpoints (a prefix with its dot)
NOT_A_CHANGE = ("seed", "logger.", "checkpoint.")
#: a value's stand-in where a run has none: the key is not in its configuration, or the run has no provenance
ABSENT, UNKNOWN = "<absent>", "<unknown>"


def _grouped(summaries: list[dict]) -> dict[str, list[dict]]:
    groups: dict[str, list[dict]] = defaultdict(list)
    for summary in summaries:
        groups[summary["scenario"]].append(summary)
    return groups


def _methods(summaries: list[dict]) -> str:
    return "+".join(sorted({s["method"] for s in summaries}))


def compare(first: list[dict], second: list[dict], metrics: tuple[str, ...] = METRICS,
            by_scenario: bool = True, comparisons: int | None = None) -> list[dict]:
    """One row per (scenario, metric) both sides have: each side's methods, mean and std; the test of second - first
    (``test``: :class:`~torchrl_csirl.analysis.verdicts.SeedComparison`'s fields, None with fewer than two seeds on a
    side), Holm's correction across the metric's rows, or, with ``comparisons`` larger than their number (the
    section's count), Holm's first step at that count.

    With ``by_scenario=False`` each side is one group whatever its tasks (a task against its variant, e.g. a maze
    with a random goal against the same maze with a fixed one), named ``<first's tasks> / <second's tasks>``.
    """
    if by_scenario:
        a, b = _grouped(first), _grouped(second)
    else:
        key = " / ".join("+".join(sorted({s["scenario"] for s in side})) for side in (first, second))
        a, b = {key: first}, {key: second}
    rows = []
    for metric in metrics:
        pairs, found = [], []
        for key in sorted(set(a) & set(b)):
            va = [s[metric] for s in a[key] if s.get(metric) is not None]
            vb = [s[metric] for s in b[key] if s.get(metric) is not None]
            if va and vb:
                pairs.append((vb, va))
                found.append({"scenario": key, "methods": [_methods(a[key]), _methods(b[key])], "metric": metric,
                              "n": [len(va), len(vb)], "first": mean_std(va), "second": mean_std(vb)})
        if comparisons is not None and comparisons > len(pairs):
            tests = [compare_seeds(vb, va, comparisons=comparisons) for vb, va in pairs]
        else:
            tests = compare_family(pairs)
        rows += [{**row, "test": None if test is None else test.as_dict()} for row, test in zip(found, tests)]
    return sorted(rows, key=lambda r: (r["scenario"], metrics.index(r["metric"])))


def _cell(stats: dict[str, float]) -> str:
    return f"{stats['mean']:.3g} ± {stats['std']:.2g}"


def _verdict(test: dict | None) -> str:
    """The row's test in the pages' words (:func:`~torchrl_csirl.analysis.verdicts.describe`), ``—`` without one."""
    if test is None:
        return "— (fewer than 2 seeds on a side)"
    from torchrl_csirl.analysis.verdicts import SeedComparison

    fields = {k: test[k] for k in ("difference", "t", "dof", "p", "p_holm", "comparisons", "detectable")}
    return describe(SeedComparison(**fields, n=tuple(test["n"])), fmt="+.3g")


def markdown(rows: list[dict], labels: tuple[str, str]) -> str:
    """The rows as a Markdown table (difference = second - first; Welch's t, p, Holm's p and the verdict)."""
    lines = [f"| scenario | metric | {labels[0]} | {labels[1]} | difference (Welch t, p): verdict |", "|---|---|---|---|---|"]
    for row in rows:
        test = row["test"]
        verdict = _verdict(test) if test is not None else (
            f"{row['second']['mean'] - row['first']['mean']:+.3g} {_verdict(None)}")
        lines.append(f"| {row['scenario']} | {row['metric']} | {_cell(row['first'])} | {_cell(row['second'])} | {verdict} |")
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------- what differs
def run_fields(run_dir: str, ignore: tuple[str, ...] = ()) -> dict[str, dict[str, Any] | None]:
    """A run's ``configuration`` (flat ``config.yaml``, :data:`NOT_A_CHANGE` and ``ignore`` left out), ``code``
    (:func:`~torchrl_csirl.run.provenance.code_fields`) and ``machine``; None where the run has no such file."""
    skip = (*NOT_A_CHANGE, *ignore)
    config_path = os.path.join(run_dir, "config.yaml")
    configuration = None
    if os.path.isfile(config_path):
        configuration = {k: v for k, v in flatten_config(OmegaConf.load(config_path)).items()
                         if not any(k == s or (s.endswith(".") and k.startswith(s)) for s in skip)}
    provenance = read_provenance(run_dir)
    return {"configuration": configuration,
            "code": None if provenance is None else code_fields(provenance),
            "machine": None if provenance is None else machine_fields(provenance)}


def _values(runs: list[dict[str, Any] | None], key: str) -> dict[str, int]:
    """``value -> how many runs`` of ``key`` over one side's runs (JSON text, :data:`ABSENT` / :data:`UNKNOWN`)."""
    counts: dict[str, int] = defaultdict(int)
    for fields in runs:
        value = UNKNOWN if fields is None else json.dumps(fields[key]) if key in fields else ABSENT
        counts[value] += 1
    return dict(counts)


def differences(first: list[dict[str, Any] | None], second: list[dict[str, Any] | None]) -> dict[str, dict]:
    """``key -> {"first": {value: runs}, "second": {value: runs}, "between": bool, "within": [sides]}`` for every key
    whose values differ between the two sides (``between``) or within one (``within``), over each side's flat
    fields (None: a run without them).

    Examples:
        >>> d = differences([{"a": 1, "b": 2}, {"a": 1, "b": 3}], [{"a": 2, "b": 2}])
        >>> d["a"]["between"], d["b"]["within"], d["a"]["first"]
        (True, ['first'], {'1': 2})
    """
    keys = dict.fromkeys(k for side in (first, second) for fields in side if fields for k in fields)
    found = {}
    for key in keys:
        a, b = _values(first, key), _values(second, key)
        within = [name for name, counts in (("first", a), ("second", b)) if len(counts) > 1]
        between = set(a) != set(b)
        if between or within:
            found[key] = {"first": a, "second": b, "between": between, "within": within}
    return found


def _unknown(runs: list[dict], part: str) -> int:
    return sum(r[part] is None for r in runs)


def what_differs(first_dirs: list[str], second_dirs: list[str], ignore: tuple[str, ...] = ()) -> dict[str, Any]:
    """The configuration, code and machine differences of the two sides' runs, and how many runs have no
    ``provenance.json`` (``provenance_unknown``) or no ``config.yaml`` (``configuration_unknown``)."""
    first = [run_fields(d, ignore) for d in first_dirs]
    second = [run_fields(d, ignore) for d in second_dirs]
    return {part: differences([r[part] for r in first], [r[part] for r in second])
            for part in ("configuration", "code", "machine")} | {
        "runs": len(first) + len(second), "provenance_unknown": _unknown(first + second, "code"),
        "configuration_unknown": _unknown(first + second, "configuration")}


def _counts(counts: dict[str, int]) -> str:
    return ", ".join(f"{value} ({n} run{'s' if n > 1 else ''})" for value, n in counts.items())


def describe_differences(found: dict[str, Any], labels: tuple[str, str]) -> list[str]:
    """The differences in lines, for stderr."""
    lines = []
    for part, title in (("configuration", "configuration"), ("code", "code"),
                        ("machine", "machine (speed, not a change of what ran)")):
        if not found[part]:
            unknown = found["configuration_unknown" if part == "configuration" else "provenance_unknown"]
            lines.append(f"{title}: unknown" if unknown == found["runs"] else f"{title}: no difference" + (
                f" among the {_runs(found['runs'] - unknown)} that record it" if unknown else ""))
            continue
        lines.append(f"{title}:")
        for key, d in found[part].items():
            where = "between the sides" if d["between"] else ""
            if d["within"]:
                where += (" and " if where else "") + "within " + " and ".join(labels[s == "second"] for s in d["within"])
            lines.append(f"  {key} ({where}): {labels[0]} {_counts(d['first'])}; {labels[1]} {_counts(d['second'])}")
    for part, file in (("provenance_unknown", "provenance.json"), ("configuration_unknown", "config.yaml")):
        if found[part]:
            lines.append(f"{part.replace('_', ': ', 1)} for {_runs(found[part])} (no {file}: recorded before runs wrote it)"
                         if part == "provenance_unknown" else f"configuration: unknown for {_runs(found[part])} (no {file})")
    return lines


def _runs(n: int) -> str:
    return f"{n} run{'s' if n != 1 else ''}"


def one_change_refusal(found: dict[str, Any], key: str) -> str | None:
    """Why the comparison is not one of ``key`` alone (one line), or None when it is.

    Examples:
        >>> found = {"configuration": {"a": {"between": True, "within": []}}, "code": {}, "machine": {},
        ...          "runs": 2, "provenance_unknown": 0, "configuration_unknown": 0}
        >>> one_change_refusal(found, "a") is None, one_change_refusal(found, "b")
        (True, '--one-change b refused: b does not differ between the sides; a differs between the sides')
    """
    reasons = []
    if found["provenance_unknown"]:
        reasons.append(f"provenance unknown for {_runs(found['provenance_unknown'])}: cannot show a one-change comparison")
    if found["configuration_unknown"]:
        reasons.append(f"configuration unknown for {_runs(found['configuration_unknown'])} (no config.yaml)")
    changed = found["configuration"].get(key)
    if changed is None or not changed["between"]:
        reasons.append(f"{key} does not differ between the sides")
    elif changed["within"]:
        reasons.append(f"{key} differs within {' and '.join(changed['within'])}")
    for part in ("configuration", "code"):
        for other, d in found[part].items():
            if other != key:
                where = "between the sides" if d["between"] else f"within {' and '.join(d['within'])}"
                reasons.append(f"{other} differs {where}")
    return f"--one-change {key} refused: " + "; ".join(reasons) if reasons else None


# ---------------------------------------------------------------------------------------- command line
def _load(paths: list[str]) -> tuple[list[dict], list[str]]:
    summaries, dirs = [], []
    for path in find_summaries(paths):
        with open(path) as f:
            summaries.append(json.load(f))
        dirs.append(os.path.dirname(path))
    return summaries, dirs


def main(argv: list[str] | None = None) -> dict:
    """Compares the two sides (``argv``: the command line, ``None`` for ``sys.argv[1:]``); returns the JSON line's object.

    Raises:
        SystemExit: status 2, one line on stderr, for a refused ``--one-change`` or sides that share no scenario.
    """
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n")[0])
    parser.add_argument("runs", nargs="+", help="run directories (or folders of runs): the first side")
    parser.add_argument("--against", nargs="+", required=True, help="run directories (or folders): the second side")
    parser.add_argument("--labels", nargs=2, default=("first", "second"), help="the two columns' names")
    parser.add_argument("--metrics", nargs="+", default=list(METRICS), help="summary.json fields to compare")
    parser.add_argument("--across-scenarios", action="store_true",
                        help="each side as one group whatever its tasks (a task against its variant)")
    parser.add_argument("--comparisons", type=int, default=None,
                        help="the study section's number of comparisons, for Holm's correction (default: the rows "
                             "of each metric)")
    parser.add_argument("--one-change", metavar="KEY", default=None,
                        help="refuse (exit status 2) unless KEY is the only difference of configuration and code")
    parser.add_argument("--ignore", nargs="+", default=[], metavar="KEY",
                        help="configuration keys (or prefixes ending in '.') that are no change here")
    args = parser.parse_args(argv)
    (first, first_dirs), (second, second_dirs) = _load(args.runs), _load(args.against)
    found = what_differs(first_dirs, second_dirs, tuple(args.ignore))
    if args.one_change is not None:
        refusal = one_change_refusal(found, args.one_change)
        if refusal is not None:
            print(f"{PROG}: {refusal}", file=sys.stderr)
            raise SystemExit(2)
    rows = compare(first, second, tuple(args.metrics), by_scenario=not args.across_scenarios,
                   comparisons=args.comparisons)
    if not rows:
        parser.error("the two sides share no scenario with the metrics asked for")
    labels = tuple(args.labels)
    print(markdown(rows, labels), file=sys.stderr)
    print("\n".join(["", *describe_differences(found, labels)]), file=sys.stderr)
    if args.ignore:
        print(f"set aside (--ignore): {' '.join(args.ignore)}", file=sys.stderr)
    result = {"labels": list(labels), "rows": rows, "differences": found, "one_change": args.one_change,
              "ignored": args.ignore}
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    main()
