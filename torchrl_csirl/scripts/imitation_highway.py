"""One baseline on a driving scenario: ``python recipes/imitation_highway.py method=<name> [key=value ...]``.

Trains (or, for the reference rows, evaluates) one of the methods CSIRL is compared with, under
the CSIRL recipe's budget, networks, input features, demonstrations and evaluation, with the same
outputs. Methods: ``sac`` (SAC on the true distance reward), ``bc`` (behavioural cloning),
``random`` and ``expert`` (reference rows, no training); CSIRL itself is
``recipes/csirl_highway.py``. Configuration: the typed schema in ``torchrl_csirl/launch/imitation.py``
(``python recipes/imitation_highway.py --help`` lists every key). See docs/benchmark.md.

The run directory (``logger.output_dir``/<name>) receives ``config.yaml``, ``metrics.jsonl``,
``metrics.csv``, ``summary.json`` and, for a trained method, ``checkpoints/last``, ``policy.pt``
and ``learning_curve.png``; the last printed line is a JSON summary. ``checkpoint.resume=<run dir>``
continues a killed run; an existing run is never replaced unless ``logger.overwrite=true``.
"""
from __future__ import annotations

import sys
import time

from torchrl_csirl.launch.builders import (
    final_summary,
    open_configured_run,
    requested_config,
    start_run,
    train_and_finish,
)
from torchrl_csirl.launch.config import help_requested
from torchrl_csirl.launch.imitation import (
    REFERENCE_METHODS,
    ImitationHighwayConfig,
    evaluate_reference,
    load_config,
    load_run_config,
    make_trainer,
)
from torchrl_csirl.launch.run import run_script, write_summary


def summarize(run) -> dict[str, object]:
    """The final evaluation, policy, curve and summary of a trained method."""
    return final_summary(run, run.cfg.method, title=f"{run.cfg.method} on {run.spec.name}")


def main(argv: list[str] | None = None, *, schema: type = ImitationHighwayConfig, doc: str | None = None,
         load=load_config, load_run=load_run_config) -> dict[str, object]:
    """Train (or evaluate) one baseline; ``schema``, ``doc``, ``load`` and ``load_run`` are another
    recipe's when it reuses this one (imitation_robotics.py)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if help_requested(argv, doc or __doc__, schema):
        return {}
    start = time.perf_counter()
    cfg = requested_config(argv, load, load_run)  # a resumed run keeps its method
    if cfg.method in REFERENCE_METHODS:
        summary = start_run(cfg, cfg.method, evaluate_reference)
    else:
        run = open_configured_run(cfg, lambda cfg: cfg.method, make_trainer)
        summary = train_and_finish(run, summarize)
    # a resumed run's earlier processes count too (up to their checkpoint)
    summary["total_wall_s"] = round(time.perf_counter() - start + summary.get("earlier_wall_s", 0.0), 1)
    print(f"{summary['scenario']} / {summary['method']}: accomplish rate {summary['accomplish_rate']:.3f} "
          f"(success {summary['success_rate']:.2f}) after {summary['frames']} frames / {summary['updates']} updates",
          file=sys.stderr)
    return write_summary(summary, summary["run_dir"])


if __name__ == "__main__":
    run_script(main)
