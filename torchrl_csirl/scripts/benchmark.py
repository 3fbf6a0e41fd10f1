"""The paper's comparison: methods x scenarios x seeds as Ray Tune trials, and its table and curves.

Run the sweep (local Ray by default, one trial at a time: sized for a 2-core machine)::

    python recipes/benchmark.py --methods csirl bc sac --scenarios merge roundabout --seeds 0 1 2 \\
        --output-dir runs/benchmark [key=value ...] [method:key=value ...]

Each cell (method, scenario, seed) is one run of its recipe (``recipes/csirl_highway.py`` for
``csirl`` and ``csirl-b``, ``recipes/imitation_highway.py method=<name>`` for the others; on the
robotics tasks ``--scenarios relocate antmaze-umaze``, ``recipes/csirl_robotics.py`` and
``recipes/imitation_robotics.py``) in its own
process, in ``<output-dir>/<scenario>-<method>-s<seed>``, its output in ``<output-dir>/logs``. The
``expert`` row runs for the first seed only (the expert driver is deterministic). The
sweep is resumable: a cell whose ``summary.json`` exists is not run again, a cell with a checkpoint
continues from it (``checkpoint.resume``), any other leftover is replaced. ``key=value`` overrides
go to every cell; ``<method>:key=value`` or ``<recipe>:key=value`` (``csirl_highway``,
``imitation_highway``, ``csirl_robotics``, ``imitation_robotics``) to that method's or that
recipe's cells only. ``--address`` joins an
existing Ray cluster (``ray start --head`` on it first); ``--max-concurrent`` and
``--cpus-per-trial`` size the trials. Ctrl-C or SIGTERM to the sweep (its pid: ``<output-dir>/logs/sweep.pid``)
stops it without losing work: each running cell gets SIGTERM (it checkpoints at its next batch boundary) and the
sweep exits (status 130, 143) once they have, naming the command that continues it: the same one (local Ray, Linux:
:mod:`torchrl_csirl.run.processes`).

Write the table (method rows x scenario columns, expert-normalised accomplish rate mean +- std over
seeds, the paper's Table I beside it; on the robotics tasks the test return, the paper's metric
there; Markdown and CSV) and one learning-curve figure per scenario or task (the paper's
Figures 6 and 7)::

    python recipes/benchmark.py report runs/benchmark [more folders or run dirs] [--out runs/benchmark/report]

See docs/benchmark.md. The parts, one concern a module, are :mod:`torchrl_csirl.sweep`'s (published numbers,
plan, runner, results, report, curves); this module is the command line and keeps their names importable from here.
"""
from __future__ import annotations

import argparse
import json
import os
import sys

from torchrl_csirl.run.processes import SweepBusyError
from torchrl_csirl.sweep.curves import LEARNER_ORDER, curve_kinds, evaluation_schedule, learning_curve_figures
from torchrl_csirl.sweep.plan import (
    ABLATIONS,
    CSIRL_METHODS,
    CSIRL_RECIPE,
    CSIRL_ROBOTICS_RECIPE,
    IMITATION_RECIPE,
    IMITATION_ROBOTICS_RECIPE,
    LOCOMOTION_ORDER,
    LOCOMOTION_TITLES,
    METHOD_ORDER,
    PAPER_ROBOTICS_METHODS,
    RECIPES,
    REFERENCE_METHODS,
    ROBOTICS_ORDER,
    SCENARIO_ORDER,
    SEED_FREE_METHODS,
    TABLE_BUDGETS,
    TASK_OVERRIDES,
    BenchmarkError,
    Cell,
    has_checkpoint,
    is_gymnasium_id,
    is_robotics,
    known_methods,
    make_cell,
    plan_cells,
    recipe_of,
    return_task_order,
    score_key,
    split_overrides,
    table_overrides,
)
from torchrl_csirl.sweep.published import (
    PAPER_TABLE,
    PUBLISHED_EXPERTS,
    PUBLISHED_GAP,
    PUBLISHED_LOCOMOTION,
    published_gap,
)
from torchrl_csirl.sweep.report import (
    budget_caption,
    driving_tables,
    locomotion_tables,
    markdown_table,
    published_table,
    robotics_tables,
    write_csv,
)
from torchrl_csirl.sweep.results import (
    add_comparison_to_csirl,
    add_normalized_returns,
    best_evaluation,
    cell_method,
    eval_curve,
    off_budget,
    read_runs,
    table_rows,
)
from torchrl_csirl.sweep.runner import run_cell, run_sweep, sweep_command

#: the script's own functions, then the names of :mod:`torchrl_csirl.sweep` it re-exports (tests, tools and
#: docs import them from here)
__all__ = [
    "main", "report_main", "sweep_main",
    # plan
    "ABLATIONS", "CSIRL_METHODS", "CSIRL_RECIPE", "CSIRL_ROBOTICS_RECIPE", "IMITATION_RECIPE", "IMITATION_ROBOTICS_RECIPE",
    "LOCOMOTION_ORDER", "LOCOMOTION_TITLES", "METHOD_ORDER", "PAPER_ROBOTICS_METHODS", "RECIPES", "REFERENCE_METHODS",
    "ROBOTICS_ORDER", "SCENARIO_ORDER", "SEED_FREE_METHODS", "TABLE_BUDGETS", "TASK_OVERRIDES", "BenchmarkError", "Cell",
    "has_checkpoint", "is_gymnasium_id", "is_robotics", "known_methods", "make_cell", "plan_cells", "recipe_of",
    "return_task_order", "score_key", "split_overrides", "table_overrides",
    # published
    "PAPER_TABLE", "PUBLISHED_EXPERTS", "PUBLISHED_GAP", "PUBLISHED_LOCOMOTION", "published_gap",
    # runner
    "run_cell", "run_sweep", "sweep_command",
    # results
    "add_comparison_to_csirl", "add_normalized_returns", "best_evaluation", "cell_method", "eval_curve", "off_budget",
    "read_runs", "table_rows",
    # report
    "budget_caption", "driving_tables", "locomotion_tables", "markdown_table", "published_table", "robotics_tables",
    "write_csv",
    # curves
    "LEARNER_ORDER", "curve_kinds", "evaluation_schedule", "learning_curve_figures",
]


def sweep_main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="benchmark.py", description="methods x scenarios x seeds as Ray Tune trials")
    available = [m for m in METHOD_ORDER if m in known_methods()]
    parser.add_argument("--methods", nargs="+", default=available, metavar="METHOD",
                        help=f"default: the paper's rows ({' '.join(available)}); CSIRL's ablations and variants: "
                             f"{' '.join(ABLATIONS)}")
    parser.add_argument("--scenarios", nargs="+", default=list(SCENARIO_ORDER), metavar="SCENARIO")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    parser.add_argument("--output-dir", default="runs/benchmark")
    parser.add_argument("--address", default=None, help="an existing Ray cluster (default: local Ray)")
    parser.add_argument("--max-concurrent", type=int, default=1, help="trials at once (default 1: a 2-core machine)")
    parser.add_argument("--cpus-per-trial", type=float, default=2.0, help="CPUs Ray reserves per trial")
    parser.add_argument("--dry-run", action="store_true", help="print the cells' commands, run nothing")
    parser.add_argument("overrides", nargs="*", help="key=value (every cell) or <method|recipe>:key=value")
    args = parser.parse_args(argv)
    output_dir = os.path.abspath(args.output_dir)
    cells, done = plan_cells(args.methods, args.scenarios, args.seeds, output_dir, args.overrides)
    print(f"{len(cells)} cells to run, {len(done)} already done ({output_dir})", file=sys.stderr)
    if args.dry_run:
        for cell in cells:
            print(" ".join(cell.command[1:]))
        return 0
    failed = run_sweep(cells, output_dir, address=args.address, max_concurrent=args.max_concurrent,
                       cpus_per_trial=args.cpus_per_trial, command=sweep_command(argv)) if cells else []
    print(json.dumps({"output_dir": output_dir, "ran": len(cells), "already_done": len(done), "failed": failed}))
    return 1 if failed else 0



def report_main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="benchmark.py report", description="the table and curves of finished runs")
    parser.add_argument("paths", nargs="+", help="sweep output folders or run directories")
    parser.add_argument("--out", default=None, help="where to write (default: <first path>/report)")
    args = parser.parse_args(argv)
    runs = read_runs(args.paths)
    out_dir = os.path.abspath(args.out or os.path.join(args.paths[0], "report"))
    os.makedirs(out_dir, exist_ok=True)
    rows = table_rows(runs)
    table = markdown_table(rows)
    with open(os.path.join(out_dir, "table.md"), "w") as f:
        f.write(table + "\n")
    files = {"markdown": os.path.join(out_dir, "table.md"), "csv": write_csv(rows, os.path.join(out_dir, "table.csv")),
             "figures": learning_curve_figures(runs, out_dir)}
    print(table, file=sys.stderr)
    print(json.dumps({"runs": len(runs), **files}))
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        if argv[:1] == ["report"]:
            return report_main(argv[1:])
        return sweep_main(argv)
    except (BenchmarkError, FileNotFoundError, SweepBusyError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
