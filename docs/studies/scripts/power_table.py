"""How many seeds each of the project's rested-on comparisons has, what it can detect, and what it would need.

``python docs/studies/scripts/power_table.py [--delta 0.05] [--root .]``

For each comparison of :data:`COMPARISONS` (two seed sets of recorded runs, ``docs/runs/<group>/<cell>``), the
table gives the seeds a side, the difference of means, the smallest difference Welch's test could detect at that
n and those spreads (two-sided 5 %, power 0.8: :func:`torchrl_csirl.analysis.verdicts.detectable_difference`) and
the seeds a side it would take to detect ``--delta`` of the expert with the spreads seen so far
(:func:`~torchrl_csirl.analysis.verdicts.seeds_needed`). Scores are expert-normalised: the driving scenes' accomplish
rate over the expert's, PointMaze's success rate (the share of test episodes reaching the goal), the HalfCheetah's
test return over its expert record's. The Markdown table goes to stdout (``docs/studies/power.md`` holds it, and
``tests/test_power_table.py`` checks that it is the current one); the last line is JSON.
"""
from __future__ import annotations

import argparse
import glob
import json
import os
import statistics
import sys
from dataclasses import dataclass

from torchrl_csirl.analysis.verdicts import compare_seeds, detectable_difference, seeds_needed
from torchrl_csirl.run.provenance import read_provenance

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
#: the difference of interest, a share of the expert's score
DELTA = 0.05
#: the HalfCheetah expert's record (its test return normalises the HalfCheetah's scores)
HALFCHEETAH_EXPERT = "docs/runs/mujoco/halfcheetah-expert-s0/summary.json"


@dataclass(frozen=True)
class Comparison:
    """Two seed sets: globs of record folders (relative to the repository), the score they are read by."""

    name: str
    a: tuple[str, ...]
    b: tuple[str, ...]
    metric: str
    note: str = ""


def _medium(method: str) -> tuple[str, ...]:
    return (f"docs/runs/pointmaze/PointMaze_Medium-v3-{method}-s*", f"docs/runs/power-pointmaze/PointMaze_Medium-v3-{method}-s*")


COMPARISONS = (
    Comparison("merge: CSIRL against CSIRL without the curriculum",
               ("docs/runs/csirl/merge-csirl-s*", "docs/runs/power-merge/merge-csirl-s*"),
               ("docs/runs/power-merge/merge-csirl-nocur-s*",), "normalized_accomplish_rate"),
    Comparison("merge: CSIRL against CSIRL-B",
               ("docs/runs/csirl/merge-csirl-s*", "docs/runs/power-merge/merge-csirl-s*"),
               ("docs/runs/csirl-b/merge-b-s*", "docs/runs/power-merge/merge-csirl-b-s*"), "normalized_accomplish_rate"),
    Comparison("PointMaze Medium: CSIRL against CSIRL without the curriculum", _medium("csirl"), _medium("csirl-nocur"),
               "success_rate"),
    Comparison("PointMaze Medium: CSIRL against CSIRL-B", _medium("csirl"), _medium("csirl-b"), "success_rate"),
    Comparison("PointMaze Medium: CSIRL against BC", _medium("csirl"), _medium("bc"), "success_rate"),
    Comparison("HalfCheetah, 300 000 frames: CSIRL without against with expert transitions",
               ("docs/runs/mujoco/halfcheetah-csirl-s*",),
               ("docs/runs/halfcheetah-expert-transitions/halfcheetah-csirl-s*",), "return",
               "provisional below 5 seeds a side"),
)


def _scale(metric: str, root: str) -> float:
    """What a record's ``metric`` is divided by: the HalfCheetah expert's test return for ``return``, else 1."""
    if metric != "return":
        return 1.0
    with open(os.path.join(root, HALFCHEETAH_EXPERT), encoding="utf-8") as f:
        return float(json.load(f)["return"])


def _summaries(globs: tuple[str, ...], root: str) -> list[str]:
    return sorted({p for g in globs for p in glob.glob(os.path.join(root, g, "summary.json"))})


def with_provenance(globs: tuple[str, ...], root: str = ROOT) -> int:
    """How many of the records matching ``globs`` hold the ``provenance.json`` a run writes (the code it ran)."""
    return sum(read_provenance(os.path.dirname(p)) is not None for p in _summaries(globs, root))


def seed_scores(globs: tuple[str, ...], metric: str, root: str = ROOT) -> list[float]:
    """The scores of every record matching ``globs`` (each record once, sorted by path)."""
    scale, scores = _scale(metric, root), []
    for path in _summaries(globs, root):
        with open(path, encoding="utf-8") as f:
            scores.append(float(json.load(f)[metric]) / scale)
    return scores


def power_row(comparison: Comparison, delta: float = DELTA, root: str = ROOT) -> dict:
    """One comparison's seeds, difference, detectable difference and seeds needed for ``delta`` (None where a side
    has fewer than two records).

    Examples:
        >>> row = power_row(COMPARISONS[1])
        >>> row["seeds"][1] >= 3, row["needed"] <= row["seeds"][0] or row["needed"] > 2
        (True, True)
    """
    a, b = seed_scores(comparison.a, comparison.metric, root), seed_scores(comparison.b, comparison.metric, root)
    row = {"comparison": comparison.name, "seeds": (len(a), len(b)), "difference": None, "detectable": None,
           "needed": None, "with_provenance": (with_provenance(comparison.a, root), with_provenance(comparison.b, root)),
           "note": comparison.note}
    if len(a) < 2 or len(b) < 2:
        return row
    sd_a, sd_b = statistics.stdev(a), statistics.stdev(b)
    row.update(difference=compare_seeds(a, b).difference,
               detectable=detectable_difference(sd_a, len(a), sd_b, len(b)),
               needed=seeds_needed(sd_a, sd_b, delta))
    return row


def _cell(value: float | None, fmt: str = "+.3f") -> str:
    return "no records yet" if value is None else format(value, fmt)


def power_table(delta: float = DELTA, root: str = ROOT) -> str:
    """The Markdown table of every comparison (see the module's docstring)."""
    lines = [f"| comparison | seeds a side | of them with provenance | difference | detectable now "
             f"| seeds a side to detect {delta:g} | note |", "|---|---|---|---|---|---|---|"]
    for comparison in COMPARISONS:
        row = power_row(comparison, delta, root)
        needed = "" if row["needed"] is None else str(row["needed"])
        lines.append(f"| {row['comparison']} | {row['seeds'][0]}, {row['seeds'][1]} | "
                     f"{row['with_provenance'][0]}, {row['with_provenance'][1]} | {_cell(row['difference'])} | "
                     f"{_cell(row['detectable'], '.3f')} | {needed} | {row['note']} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="power_table.py", description=__doc__.splitlines()[0])
    parser.add_argument("--delta", type=float, default=DELTA, help="the difference of interest (default %(default)s)")
    parser.add_argument("--root", default=ROOT, help="the repository holding docs/runs")
    args = parser.parse_args(argv)
    print(power_table(args.delta, args.root))
    print(json.dumps([power_row(c, args.delta, args.root) for c in COMPARISONS]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
