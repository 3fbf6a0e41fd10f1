"""A run from start to end: a new run's directory or a resumed run's checkpoint, training (signals, a dead
worker, divergence: a checkpoint and one line), the finish, and a recipe's whole command line (:func:`run_recipe`)."""
from __future__ import annotations

import contextlib
import json
import os
import shutil
import sys
import time
from typing import TYPE_CHECKING, Any, Callable

from omegaconf import DictConfig, OmegaConf

from torchrl_csirl.run.assembly import Run
from torchrl_csirl.run.collection import use_main_threads
from torchrl_csirl.run.config import CommandLine, flatten_config
from torchrl_csirl.run.provenance import record_resume_provenance, write_provenance
from torchrl_csirl.run.run import (
    default_run_name,
    make_run_dir,
    resolve_resume,
    resume_command,
    stop_with_checkpoint,
)
from torchrl_csirl.trainers import CollectorWorkerError, shutdown_collector

if TYPE_CHECKING:
    from torchrl_csirl.run.recipes import Recipe


# ---------------------------------------------------------------------------------------- starting and resuming
def start_run(cfg: DictConfig, method: str, build: Callable[[DictConfig, str], Any]) -> Any:
    """A new run: its directory (``logger.*``) with ``config.yaml`` and ``provenance.json`` (the code, packages and
    machine it runs on, :mod:`torchrl_csirl.run.provenance`), then ``build(cfg, run_dir)``.

    If ``build`` fails (e.g. a bad expert file) the new directory, which holds no run, is removed.
    """
    run_dir = make_run_dir(cfg.logger.output_dir, cfg.logger.exp_name,
                           default_run_name(cfg.env.task, method, cfg.seed), cfg.logger.overwrite)
    OmegaConf.save(cfg, os.path.join(run_dir, "config.yaml"))
    write_provenance(run_dir)
    try:
        return build(cfg, run_dir)
    except BaseException:
        shutil.rmtree(run_dir, ignore_errors=True)
        raise


def resume_run(cfg: DictConfig, run_dir: str, checkpoint: str, make_trainer: Callable[..., Run]) -> Run:
    """A killed run continued: ``make_trainer(cfg, run_dir, frames_done=, resume_frames=)`` with the
    checkpoint's counters, then the checkpoint (and the online buffer, if saved) restored; the resuming process's
    provenance is appended to the run's ``provenance.json``."""
    from torchrl_csirl.trainers import load_checkpoint, read_checkpoint_state

    counters = read_checkpoint_state(checkpoint)["counters"]  # an unreadable file: one CheckpointError line
    run = make_trainer(cfg, run_dir, frames_done=counters["frames"], resume_frames=counters["frames"])
    try:
        load_checkpoint(run.trainer, checkpoint, run.online_buffer if cfg.checkpoint.save_buffer else None)
    except BaseException:
        run.close()
        raise
    print(f"resumed {run_dir} at {counters['frames']} frames, {counters['updates']} updates", file=sys.stderr)
    record_resumed_settings(cfg, run_dir, counters["frames"])
    record_resume_provenance(run_dir, counters["frames"])
    return run


def record_resumed_settings(cfg: DictConfig, run_dir: str, frames: int) -> dict[str, list[Any]]:
    """A resume that changes settings (``key=value`` beside ``checkpoint.resume``) writes them into the run's
    ``config.yaml``, so the next resume keeps them and the file says what the run ran with, and appends
    ``{"frames", "changed": {key: [before, after]}}`` to ``<run dir>/resumes.jsonl``, so the settings of
    the frames before stay on record. Keys the saved file lacks (settings its schema did not have) hold
    their defaults and are no change. Returns the changes (empty: nothing written).

    Examples:
        >>> import tempfile, os
        >>> run_dir = tempfile.mkdtemp()
        >>> OmegaConf.save(OmegaConf.create({"seed": 0, "collector": {"total_frames": 1000}}),
        ...                os.path.join(run_dir, "config.yaml"))
        >>> cfg = OmegaConf.create({"seed": 0, "collector": {"total_frames": 5000}})
        >>> record_resumed_settings(cfg, run_dir, frames=1000)
        {'collector.total_frames': [1000, 5000]}
        >>> OmegaConf.load(os.path.join(run_dir, "config.yaml")).collector.total_frames
        5000
        >>> record_resumed_settings(OmegaConf.merge(cfg, {"eval": {"keep_best": False}}), run_dir, frames=5000)
        {}
    """
    path = os.path.join(run_dir, "config.yaml")
    saved = OmegaConf.load(path)
    effective = cfg.copy()
    if "checkpoint" in effective and "resume" in effective.checkpoint:
        effective.checkpoint.resume = None
    before, after = flatten_config(saved), flatten_config(effective)
    changed = {key: [before[key], value] for key, value in after.items()
               if key != "checkpoint.resume" and key in before and before[key] != value}
    if changed:
        tmp = f"{path}.tmp"
        OmegaConf.save(effective, tmp)
        os.replace(tmp, path)
        with open(os.path.join(run_dir, "resumes.jsonl"), "a") as f:
            f.write(json.dumps({"frames": int(frames), "changed": changed}) + "\n")
    return changed


def open_configured_run(cfg: DictConfig, method: Callable[[DictConfig], str], make_trainer: Callable[..., Run]) -> Run:
    """A new run (:func:`start_run`, its directory named by ``method(cfg)``), or the run of
    ``cfg.checkpoint.resume`` with its checkpoint restored (:func:`resume_run`); ``collector.main_threads`` holds
    from the first step (:func:`~torchrl_csirl.run.collection.use_main_threads`)."""
    if "collector" in cfg:
        use_main_threads(cfg.collector)
    if cfg.checkpoint.resume is None:
        return start_run(cfg, method(cfg), make_trainer)
    return resume_run(cfg, *resolve_resume(cfg.checkpoint.resume), make_trainer)


# ---------------------------------------------------------------------------------------- training and summary
def train(run: Run) -> None:
    """``run.trainer.train()``; on any exit the collector is shut down and the logs are kept.

    SIGTERM or Ctrl-C stops at the end of the current batch, writes a checkpoint there and exits
    (130 / 143) with the command that resumes the run (:func:`torchrl_csirl.run.run.stop_with_checkpoint`).
    A collector worker that dies (an exception in its environment, a killed process) stops the run at
    once: the other workers are stopped, the last checkpoint is kept, and one line names the worker's error.

    Raises:
        TrainingDivergedError: with where the last good checkpoint is and how to resume.
        CollectorWorkerError: a worker died; with its error, the last checkpoint and how to resume.
    """
    from torchrl_csirl.trainers import StopOnSignals, TrainingDivergedError, TrainingInterrupted

    try:
        with StopOnSignals(run.trainer) as stop:
            run.trainer.train()
    except TrainingInterrupted:  # SIGTERM / Ctrl-C, at a batch boundary: checkpoint, say how to resume
        run.logger.close()
        stop_with_checkpoint(run.checkpoint.save(run.trainer), run.run_dir, stop.signum)
    except TrainingDivergedError as err:
        run.logger.close()
        raise TrainingDivergedError(
            f"{err}. Training stopped; {_last_checkpoint(run)} (resume with checkpoint.resume={run.run_dir}, "
            "e.g. with a smaller optim.lr)."
        ) from None
    except Exception as err:  # a dead collector worker: one line; anything else as it is
        run.logger.close()
        failure = run.worker_errors.describe(run.collector, err) if run.worker_errors is not None else None
        if failure is None:
            raise
        raise CollectorWorkerError(f"{failure}. Training stopped; {_last_checkpoint(run)}; "
                                   f"resume with: {resume_command(run.run_dir)}") from None
    except BaseException:  # Ctrl-C, SIGTERM: keep the logs (checkpoints are already on disk)
        run.logger.close()
        raise
    finally:
        with contextlib.suppress(Exception):  # a collector whose workers died may fail to shut down cleanly
            shutdown_collector(run.collector)
        if run.worker_errors is not None:
            run.worker_errors.close()


def _last_checkpoint(run: Run) -> str:
    """Where the run's last checkpoint is kept, in words."""
    if os.path.exists(run.checkpoint.path):
        return f"the last checkpoint is kept at {run.checkpoint.path}"
    return "no checkpoint was written yet"


def train_and_finish(run: Run, finish: Callable[[Run], dict[str, Any]]) -> dict[str, Any]:
    """:func:`train`, then ``finish(run)`` (final evaluation, policy, plots, summary); the logger and
    the evaluation environment are closed whatever happens."""
    train(run)
    try:
        return finish(run)
    finally:
        run.logger.close()
        run.eval_env.close()


def timed_summary(produce: Callable[[], dict[str, Any]]) -> dict[str, Any]:
    """``produce()``'s summary with ``total_wall_s``: this process's wall time (start-up, training, final
    evaluation, plots) plus a resumed run's earlier processes' (up to their checkpoint, ``earlier_wall_s``).

    Examples:
        >>> timed_summary(lambda: {"earlier_wall_s": 60.0})["total_wall_s"] >= 60.0
        True
    """
    start = time.perf_counter()
    summary = produce()
    summary["total_wall_s"] = round(time.perf_counter() - start + summary.get("earlier_wall_s", 0.0), 1)
    return summary


def run_recipe(recipe: Recipe, argv: list[str] | CommandLine, *, default_task: str | None = None) -> dict[str, Any]:
    """A whole run from a command line (``key=value`` strings, or parsed once:
    :func:`~torchrl_csirl.run.config.parse_command_line`): the recipe's configuration (:meth:`Recipe.configure`:
    new, or resumed with ``checkpoint.resume=``),
    its trainer, training and finish (or, for a configuration that trains nothing, its evaluation), timed
    (:func:`timed_summary`)."""

    def produce() -> dict[str, Any]:
        cfg = recipe.configure(argv, default_task=default_task)
        evaluate = recipe.untrained(cfg)
        if evaluate is not None:
            return start_run(cfg, recipe.method_of(cfg), evaluate)
        return train_and_finish(open_configured_run(cfg, recipe.method_of, recipe.trainer), recipe.finish)

    return timed_summary(produce)
