"""One baseline on any task: ``python recipes/imitation_highway.py method=<name> [key=value ...]``
(``torchrl-csirl train method=<name>``).

Trains (or, for the reference rows, evaluates) one of the methods CSIRL is compared with, under
the CSIRL recipe's budget, networks, input features, demonstrations and evaluation, with the same
outputs. Methods: ``sac`` (SAC on the true reward: the driving scenes' distance reward, another task's
own reward), ``bc`` (behavioural cloning), ``gail``, ``dac``, ``valuedice``, ``sqil``, ``iqlearn``, and
``random`` and ``expert`` (reference rows, no training); CSIRL itself is ``recipes/csirl_highway.py``.
The task is named as for CSIRL (``env.task``, ``env.gym_id``, ``env.module``) and its
family picks the schema (:class:`~torchrl_csirl.methods.baselines.ImitationTaskConfig` for every task but
the driving scenes). ``--help`` lists every key. See docs/benchmark.md.

The run directory (``logger.output_dir``/<name>) receives ``config.yaml``, ``metrics.jsonl``,
``metrics.csv``, ``summary.json`` and, for a trained method, ``checkpoints/last``, ``policy.pt``
and ``learning_curve.png``; the last printed line is a JSON summary. ``checkpoint.resume=<run dir>``
continues a killed run; an existing run is never replaced unless ``logger.overwrite=true``.

Example (BC on Relocate)::

    python recipes/imitation_highway.py method=bc env.task=relocate seed=0 collector.main_threads=1
"""
from __future__ import annotations

import sys

from torchrl_csirl.methods.baselines import IMITATION_RECIPE, ImitationHighwayConfig  # noqa: F401 - the schema, for the docs
from torchrl_csirl.run.config import help_requested, parse_command_line
from torchrl_csirl.run.lifecycle import run_recipe
from torchrl_csirl.run.run import run_script, write_summary

__all__ = ["main"]


def main(argv: list[str] | None = None, *, default_task: str | None = None) -> dict[str, object]:
    """Train (or evaluate) one baseline; ``default_task``: the task when the command line names none."""
    command = parse_command_line(sys.argv[1:] if argv is None else argv)  # the one parse of the command line
    if command.help and help_requested(command, __doc__, IMITATION_RECIPE.help_schema(command, default_task=default_task)):
        return {}
    summary = run_recipe(IMITATION_RECIPE, command, default_task=default_task)
    print(f"{summary['scenario']} / {summary['method']}: accomplish rate {summary['accomplish_rate']:.3f} "
          f"(success {summary['success_rate']:.2f}) after {summary['frames']} frames / {summary['updates']} updates",
          file=sys.stderr)
    return write_summary(summary, summary["run_dir"])


if __name__ == "__main__":
    run_script(main)
