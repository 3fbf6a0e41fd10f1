"""Evaluation curves of several groups of recorded runs in one figure: mean ± std over each group's seeds.

A study's one-change runs side by side (e.g. each AntMaze intervention at 3 seeds), from their records'
``metrics.jsonl``. Each group is ``LABEL=RUN_DIR [RUN_DIR ...]`` (a shell glob expands to the seeds); its curve is
drawn at the frames every one of its runs evaluated, so a seed that carries a frame-0 evaluation and one that does
not are still compared point by point. Constant levels (e.g. BC's test figure) are drawn as dashed lines. The last
line printed is one JSON object: per group, its runs and the mean of the metric at its last common frame.

Usage::

    torchrl-csirl curves --metric eval_accomplish_rate --reference "bc (test)=0.64" \
        --output docs/figures/antmaze_one_changes.png \
        --group "anchored, path" docs/runs/antmaze-bc-path/* \
        --group "anchored, path, fixed alpha" docs/runs/antmaze-bc-path-fixed-alpha/*

Examples:
    >>> common_frames([([0.0, 10.0, 20.0], [0.1, 0.2, 0.3]), ([10.0, 20.0], [0.4, 0.5])])
    ([10.0, 20.0], [[0.2, 0.3], [0.4, 0.5]])
"""
from __future__ import annotations

import argparse
import json
import sys

from torchrl_csirl.analysis.visualization import plot_method_curves
from torchrl_csirl.sweep.results import eval_curve

__all__ = ["common_frames", "group_curves", "main", "parse_reference"]


def common_frames(runs: list[tuple[list[float], list[float]]]) -> tuple[list[float], list[list[float]]]:
    """The frames every run evaluated, and each run's values there."""
    shared = sorted(set.intersection(*(set(frames) for frames, _ in runs))) if runs else []
    by_frame = [dict(zip(frames, values)) for frames, values in runs]
    return shared, [[run[f] for f in shared] for run in by_frame]


def group_curves(run_dirs: list[str], metric: str) -> tuple[list[float], list[list[float]]]:
    """``metric`` of each run in ``run_dirs`` at the frames all of them evaluated; runs without it are an error."""
    runs = [eval_curve(run_dir, metric) for run_dir in run_dirs]
    missing = [run_dir for run_dir, (frames, _) in zip(run_dirs, runs) if not frames]
    if missing:
        raise SystemExit(f"no {metric!r} in the metrics.jsonl of: {', '.join(missing)}")
    return common_frames(runs)


def parse_reference(text: str) -> tuple[str, float]:
    """``"LABEL=VALUE"`` -> ``(LABEL, VALUE)``."""
    label, _, value = text.rpartition("=")
    try:
        level = float(value)
    except ValueError:
        level = None
    if not label or level is None:
        raise argparse.ArgumentTypeError(f"a reference is LABEL=NUMBER, got {text!r}")
    return label, level


def main(argv: list[str] | None = None) -> dict:
    """Draws the figure (``argv``: the command line, ``None`` for ``sys.argv[1:]``); returns the JSON line's object."""
    parser = argparse.ArgumentParser(prog="torchrl-csirl curves", description=__doc__.split("\n\n")[0])
    parser.add_argument("--group", nargs="+", action="append", required=True, metavar=("LABEL", "RUN_DIR"),
                        help="a label, then its run directories (one per seed)")
    parser.add_argument("--metric", default="eval_accomplish_rate", help="a metrics.jsonl key (default: %(default)s)")
    parser.add_argument("--reference", action="append", type=parse_reference, default=[], metavar="LABEL=VALUE",
                        help="a constant level drawn as a dashed line (repeatable)")
    parser.add_argument("--title", default=None)
    parser.add_argument("--ylabel", default=None, help="default: the metric")
    parser.add_argument("--not-rate", action="store_true", help="the metric is not in [0, 1] (e.g. a return)")
    parser.add_argument("--output", required=True, help="the PNG to write")
    args = parser.parse_args(argv)
    if any(len(group) < 2 for group in args.group):
        parser.error("each --group is a label followed by at least one run directory")
    curves, last = {}, {}
    for label, *run_dirs in args.group:
        frames, values = group_curves(run_dirs, args.metric)
        curves[label] = [(frames, run_values) for run_values in values]
        last[label] = {"runs": len(run_dirs), "frames": frames[-1] if frames else None,
                       "mean": sum(v[-1] for v in values) / len(values) if frames else None}
    path = plot_method_curves(curves, args.output, references=dict(args.reference), title=args.title,
                              ylabel=args.ylabel or args.metric, rate=not args.not_rate,
                              method_order=[label for label, *_ in args.group])
    result = {"output": str(path), "metric": args.metric, "last": last}
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    sys.exit(main() and 0)
