"""One baseline on a driving scenario: ``python recipes/imitation_highway.py method=<name> [key=value ...]``.

Trains (or, for the reference rows, evaluates) one of the methods CSIRL is compared with, under
the CSIRL recipe's budget, networks, input features, demonstrations and evaluation, with the same
outputs. Methods: ``sac`` (SAC on the true distance reward), ``bc`` (behavioural cloning),
``random`` and ``expert`` (reference rows, no training); CSIRL itself is
``recipes/csirl_highway.py``. Configuration: the typed schema in ``recipes/imitation_utils.py``
(``python recipes/imitation_highway.py --help`` lists every key). See docs/BENCHMARK.md.

The run directory (``logger.output_dir``/<name>) receives ``config.yaml``, ``metrics.jsonl``,
``metrics.csv``, ``summary.json`` and, for a trained method, ``checkpoints/last``, ``policy.pt``
and ``learning_curve.png``; the last printed line is a JSON summary. ``checkpoint.resume=<run dir>``
continues a killed run; an existing run is never replaced unless ``logger.overwrite=true``.
"""
from __future__ import annotations

import os
import shutil
import sys
import time

import torch
from omegaconf import OmegaConf

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from common.builders import Run, final_summary, train  # noqa: E402
from common.config import describe  # noqa: E402
from common.run import default_run_name, make_run_dir, resolve_resume, run_script, write_summary  # noqa: E402
from imitation_utils import (  # noqa: E402
    REFERENCE_METHODS,
    ImitationHighwayConfig,
    evaluate_reference,
    load_config,
    load_run_config,
    make_trainer,
)

from torchrl_csirl.trainers import load_checkpoint  # noqa: E402


def new_run_dir(cfg) -> str:
    """The run directory of a new run, with its ``config.yaml``."""
    run_dir = make_run_dir(cfg.logger.output_dir, cfg.logger.exp_name,
                           default_run_name(cfg.env.scenario, cfg.method, cfg.seed), cfg.logger.overwrite)
    OmegaConf.save(cfg, os.path.join(run_dir, "config.yaml"))
    return run_dir


def build(cfg) -> Run:
    """The run's pieces (a new run, or a resumed one with its checkpoint restored)."""
    if cfg.checkpoint.resume is None:
        run_dir = new_run_dir(cfg)
        try:
            return make_trainer(cfg, run_dir)
        except BaseException:  # e.g. bad demonstrations: the new directory holds no run, remove it
            shutil.rmtree(run_dir, ignore_errors=True)
            raise
    run_dir, checkpoint = resolve_resume(cfg.checkpoint.resume)
    counters = torch.load(os.path.join(checkpoint, "state.pt"), weights_only=False, map_location="cpu")["counters"]
    run = make_trainer(cfg, run_dir, frames_done=counters["frames"], resume_frames=counters["frames"])
    try:
        load_checkpoint(run.trainer, checkpoint, run.online_buffer if cfg.checkpoint.save_buffer else None)
    except BaseException:
        run.close()
        raise
    print(f"resumed {run_dir} at {counters['frames']} frames, {counters['updates']} updates", file=sys.stderr)
    return run


def train_and_summarize(cfg) -> dict[str, object]:
    """A trained method: the training loop, then the final evaluation, policy, curve and summary."""
    run = build(cfg)
    train(run)
    try:
        return final_summary(run, run.cfg.method, title=f"{run.cfg.method} on {run.spec.name}")
    finally:
        run.logger.close()
        run.eval_env.close()


def reference_row(cfg) -> dict[str, object]:
    """A reference row (``random``, ``expert``): evaluated on the test episodes, no training."""
    run_dir = new_run_dir(cfg)
    try:
        return evaluate_reference(cfg, run_dir)
    except BaseException:
        shutil.rmtree(run_dir, ignore_errors=True)
        raise


def main(argv: list[str] | None = None) -> dict[str, object]:
    argv = sys.argv[1:] if argv is None else list(argv)
    if "--help" in argv or "-h" in argv:
        print(__doc__ + "\nKeys (key, default, what it accepts, meaning):\n  "
              + "\n  ".join(describe(ImitationHighwayConfig)))
        return {}
    start = time.perf_counter()
    resume = next((a.split("=", 1)[1] for a in argv if a.startswith("checkpoint.resume=")), None)
    if resume is not None and resume != "null":  # the saved run's configuration (and method), updated
        cfg = load_run_config(resolve_resume(resume)[0], [a for a in argv if not a.startswith("checkpoint.resume=")])
        cfg.checkpoint.resume = resume
    else:
        cfg = load_config(argv)
    if cfg.method in REFERENCE_METHODS:
        summary = reference_row(cfg)
    else:
        summary = train_and_summarize(cfg)
    summary["total_wall_s"] = round(time.perf_counter() - start, 1)
    print(f"{summary['scenario']} / {summary['method']}: accomplish rate {summary['accomplish_rate']:.3f} "
          f"(success {summary['success_rate']:.2f}) after {summary['frames']} frames / {summary['updates']} updates",
          file=sys.stderr)
    return write_summary(summary, summary["run_dir"])


if __name__ == "__main__":
    run_script(main)
