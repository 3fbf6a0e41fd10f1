"""CSIRL on any task, end to end: ``python recipes/csirl_highway.py [key=value ...]`` (``torchrl-csirl train``).

Trains the ensemble-SAC learner with the matching reward toward curricular subgoals and the
meta-learned intrinsic reward, from the expert demonstrations, and reports the paper's test
accomplish rate. The task: a driving scene (``env.task=merge``, the default, ``roundabout``, ...),
a robotics or locomotion task (``env.task=relocate``, ``env.task=hopper``), any gymnasium id with flat
``Box`` spaces (``env.gym_id=MountainCarContinuous-v0 expert.path=<.npz or minari:<id>>``, with
``env.features`` and ``env.success``), or one of your own (``env.module=<module> env.task=<name>``,
docs/own-task.md). The task's family picks the configuration schema: the driving scenes' (presets,
ego-relative inputs) or every other task's (``expert.curriculum=expert``, ``model.ego_relative_features=false``,
``collector.frames_per_batch=1400``). ``--help`` lists every key (with a task named, that task's schema),
e.g. ``env.task=roundabout seed=1 csirl.intrinsic=false``; ``preset=paper`` is the published procedure
on the driving scenes. See docs/recipes.md.

The run directory (``logger.output_dir``/<name>) receives ``config.yaml``, ``metrics.jsonl``,
``metrics.csv``, ``checkpoints/last``, ``policy.pt``, the plots and ``summary.json``; the last
printed line is a JSON summary. ``checkpoint.resume=<run dir>`` continues a killed run; an
existing run is never replaced unless ``logger.overwrite=true``.
"""
from __future__ import annotations

import sys

from torchrl_csirl.methods.csirl import CSIRL_RECIPE, CSIRLHighwayConfig  # noqa: F401 - the schema, for the docs
from torchrl_csirl.run.config import help_requested, parse_command_line
from torchrl_csirl.run.lifecycle import run_recipe
from torchrl_csirl.run.run import run_script, write_summary

__all__ = ["main"]


def main(argv: list[str] | None = None, *, default_task: str | None = None) -> dict[str, object]:
    """Configure, build, train, finish; ``default_task``: the task when the command line names none."""
    command = parse_command_line(sys.argv[1:] if argv is None else argv)  # the one parse of the command line
    if command.help and help_requested(command, __doc__, CSIRL_RECIPE.help_schema(command, default_task=default_task)):
        return {}
    summary = run_recipe(CSIRL_RECIPE, command, default_task=default_task)
    print(
        f"{summary['scenario']}: accomplish rate {summary['accomplish_rate']:.3f} "
        f"(success {summary['success_rate']:.2f}) after {summary['frames']} frames / {summary['updates']} updates; "
        f"{summary['frames_per_s']:.1f} frames/s, {summary['updates_per_s']:.1f} updates/s",
        file=sys.stderr,
    )
    return write_summary(summary, summary["run_dir"])


if __name__ == "__main__":
    run_script(main)
