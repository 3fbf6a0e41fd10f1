"""How firmly the actor's cloning term held, round by round, in recorded runs with ``csirl.actor_bc_coef`` > 0.

The term's weight is ``coef * |L_actor|`` by default (``csirl.actor_bc_scale=actor_loss``): the batch mean of the
actor's objective, which cancels where the batch's values are of both signs. Per record (its ``rounds.csv``): the
Spearman correlation of ``|loss_actor|`` with the actor's distance to the demonstrations' actions (``actor_bc_mse``),
that distance in the rounds with ``|loss_actor|`` under ``--threshold`` and in the others, and the first round's
pair. A Markdown table goes to stderr; the last line printed is JSON.

Usage::

    python docs/studies/scripts/anchor_records.py docs/runs/antmaze-warmstart-bc/* docs/runs/antmaze-bc-path/*

Examples:
    >>> spearman([1.0, 2.0, 3.0, 4.0], [0.4, 0.3, 0.2, 0.1])
    -1.0
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from statistics import mean

from torchrl_csirl.scripts.record import read_rounds


def _ranks(values: list[float]) -> list[float]:
    order = sorted(range(len(values)), key=values.__getitem__)
    ranks = [0.0] * len(values)
    for rank, index in enumerate(order):
        ranks[index] = float(rank)
    return ranks


def spearman(x: list[float], y: list[float]) -> float:
    """Spearman's rank correlation of two equally long series (no tie correction)."""
    n = len(x)
    if n < 2 or n != len(y):
        raise ValueError(f"two series of the same length >= 2 are needed, got {len(x)} and {len(y)}")
    return 1.0 - 6.0 * sum((a - b) ** 2 for a, b in zip(_ranks(x), _ranks(y))) / (n * (n * n - 1))


def anchor_rounds(run_dir: str) -> list[tuple[float, float]]:
    """``(|loss_actor|, actor_bc_mse)`` of each round of a record that logged the cloning term."""
    rows = [r for r in read_rounds(run_dir) if r.get("actor_bc_mse")]
    if not rows:
        raise SystemExit(f"{run_dir}: no round logged actor_bc_mse (a run without csirl.actor_bc_coef?)")
    return [(abs(float(r["loss_actor"])), float(r["actor_bc_mse"])) for r in rows]


def summarize(run_dir: str, threshold: float) -> dict:
    """The anchor's figures of one record."""
    pairs = anchor_rounds(run_dir)
    weak = [mse for scale, mse in pairs if scale < threshold]
    firm = [mse for scale, mse in pairs if scale >= threshold]
    return {"run": run_dir, "rounds": len(pairs),
            "spearman": spearman([p[0] for p in pairs], [p[1] for p in pairs]) if len(pairs) > 1 else None,
            "mse_weak": mean(weak) if weak else None, "rounds_weak": len(weak),
            "mse_firm": mean(firm) if firm else None, "rounds_firm": len(firm),
            "first_abs_loss_actor": pairs[0][0], "first_mse": pairs[0][1]}


def _cell(value: float | None, digits: str = ".4f") -> str:
    return "-" if value is None else format(value, digits)


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="+", help="record directories (each with a rounds.csv)")
    parser.add_argument("--threshold", type=float, default=20.0, help="|loss_actor| under it: a weak anchor")
    args = parser.parse_args(argv)
    rows = [summarize(run_dir, args.threshold) for run_dir in args.runs]
    print(f"| record | rounds | Spearman (|L_actor|, mse) | mse, |L_actor| < {args.threshold:g} (rounds) | "
          f"mse, the others (rounds) | first round: |L_actor|, mse |", file=sys.stderr)
    print("|---|---|---|---|---|---|", file=sys.stderr)
    for r in rows:
        print(f"| `{os.path.relpath(r['run'])}` | {r['rounds']} | {_cell(r['spearman'], '.2f')} | "
              f"{_cell(r['mse_weak'])} ({r['rounds_weak']}) | {_cell(r['mse_firm'])} ({r['rounds_firm']}) | "
              f"{r['first_abs_loss_actor']:.1f}, {r['first_mse']:.4f} |", file=sys.stderr)
    result = {"threshold": args.threshold, "rows": rows}
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    sys.exit(main() and 0)
