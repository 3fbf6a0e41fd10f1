"""CSIRL on a driving scenario, end to end: ``python recipes/csirl_highway.py [key=value ...]``.

Trains the ensemble-SAC learner with the matching reward toward curricular subgoals and the
meta-learned intrinsic reward, from the shipped expert demonstrations, and reports the paper's
test accomplish rate. Configuration: the typed schema in ``torchrl_csirl/launch/csirl.py``
(``python recipes/csirl_highway.py --help`` lists every key, its default and what it accepts;
e.g. ``env.scenario=roundabout seed=1 csirl.intrinsic=false``); ``preset=paper`` is the published
procedure. See docs/recipes.md.

The run directory (``logger.output_dir``/<name>) receives ``config.yaml``, ``metrics.jsonl``,
``metrics.csv``, ``checkpoints/last``, ``policy.pt``, the plots and ``summary.json``; the last
printed line is a JSON summary. ``checkpoint.resume=<run dir>`` continues a killed run; an
existing run is never replaced unless ``logger.overwrite=true``.
"""
from __future__ import annotations

import os
import sys
import time

from torchrl_csirl.launch.builders import Run, final_summary, open_run, train_and_finish
from torchrl_csirl.launch.config import help_requested
from torchrl_csirl.launch.csirl import (
    CSIRLHighwayConfig,
    load_config,
    load_run_config,
    make_trainer,
    method_name,
)
from torchrl_csirl.launch.run import run_script, write_summary


def build(argv: list[str], load=load_config, load_run=load_run_config) -> Run:
    """Configuration, run directory and all the pieces; restores the checkpoint when resuming.

    ``load`` / ``load_run`` read the configuration (another recipe's schema, e.g. csirl_robotics.py).
    """
    return open_run(argv, method_name, make_trainer, load, load_run)


def curriculum_plots(run: Run, picture=None) -> list[str]:
    """The subgoal curriculum with its uncertainty profiles, and the task with the selected subgoals.

    ``picture(spec, curriculum_observations, subgoals, path)`` draws the task (default: the driving
    scene, :func:`~torchrl_csirl.visualization.render_curriculum`).
    """
    from torchrl_csirl.visualization import plot_subgoal_curriculum, render_curriculum

    history = run.selection.history
    picture = picture or render_curriculum
    paths = [
        plot_subgoal_curriculum(history, os.path.join(run.run_dir, "subgoals.png"),
                                curriculum_length=run.curriculum.length, delta=run.curriculum.delta),
        picture(run.spec, run.curriculum.expert_observations.cpu(),
                sorted({h["subgoal"] for h in history} | {run.curriculum.subgoal}),
                os.path.join(run.run_dir, "curriculum.png")),
    ]
    return [os.fspath(p) for p in paths]


def finish(run: Run, picture=None) -> dict[str, object]:
    """Final evaluation, checkpoint, policy, plots and the summary (``picture``: see :func:`curriculum_plots`)."""
    summary = final_summary(run, method_name(run.cfg), title=f"CSIRL on {run.spec.name}")
    summary.update(final_subgoal=run.curriculum.subgoal, curriculum_length=run.curriculum.length)
    summary["plots"] += curriculum_plots(run, picture)
    return summary


def main(argv: list[str] | None = None, *, schema: type = CSIRLHighwayConfig, doc: str | None = None,
         build_run=build, finish_run=finish) -> dict[str, object]:
    """Build, train, finish; ``schema``, ``doc``, ``build_run`` and ``finish_run`` are another recipe's
    when it reuses this one (csirl_robotics.py)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if help_requested(argv, doc or __doc__, schema):
        return {}
    start = time.perf_counter()
    summary = train_and_finish(build_run(argv), finish_run)
    # with start-up, final evaluation and plots, and a resumed run's earlier processes (up to their checkpoint)
    summary["total_wall_s"] = round(time.perf_counter() - start + summary.get("earlier_wall_s", 0.0), 1)
    print(
        f"{summary['scenario']}: accomplish rate {summary['accomplish_rate']:.3f} "
        f"(success {summary['success_rate']:.2f}) after {summary['frames']} frames / {summary['updates']} updates; "
        f"{summary['frames_per_s']:.1f} frames/s, {summary['updates_per_s']:.1f} updates/s",
        file=sys.stderr,
    )
    return write_summary(summary, summary["run_dir"])


if __name__ == "__main__":
    run_script(main)
