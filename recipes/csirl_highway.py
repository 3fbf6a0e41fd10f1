"""CSIRL on a driving scenario, end to end: ``python recipes/csirl_highway.py [key=value ...]``.

Trains the ensemble-SAC learner with the matching reward toward curricular subgoals and the
meta-learned intrinsic reward, from the shipped expert demonstrations, and reports the paper's
test accomplish rate. Configuration: ``recipes/config/csirl_highway.yaml`` (every key can be
overridden, e.g. ``env.scenario=roundabout seed=1 csirl.intrinsic=false``); ``preset=paper`` is
the published procedure. See docs/RECIPE.md.

The run directory (``logger.output_dir``/<name>) receives ``config.yaml``, ``metrics.jsonl``,
``metrics.csv``, ``checkpoints/last``, ``policy.pt``, the plots and ``summary.json``; the last
printed line is a JSON summary. ``checkpoint.resume=<run dir>`` continues a killed run.
"""
from __future__ import annotations

import json
import os
import signal
import sys
import time
import traceback

import torch
from omegaconf import OmegaConf

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from csirl_utils import (  # noqa: E402
    ConfigError,
    ExpertDataError,
    Run,
    load_config,
    load_run_config,
    make_run_dir,
    make_trainer,
)

from torchrl_csirl.envs import normalized_accomplish_rate  # noqa: E402
from torchrl_csirl.modules import save_policy  # noqa: E402
from torchrl_csirl.trainers import TrainingDivergedError, load_checkpoint, shutdown_collector  # noqa: E402
from torchrl_csirl.trainers.metrics_logger import _scalar  # noqa: E402


def _resolve_resume(path: str) -> tuple[str, str]:
    """(run directory, checkpoint directory) of ``checkpoint.resume``."""
    path = os.path.abspath(os.path.expanduser(path))
    if os.path.isfile(os.path.join(path, "state.pt")):
        checkpoint = path
        run_dir = os.path.dirname(os.path.dirname(path))
    else:
        run_dir = path
        checkpoint = os.path.join(path, "checkpoints", "last")
    if not os.path.isfile(os.path.join(checkpoint, "state.pt")):
        raise FileNotFoundError(f"checkpoint.resume: no checkpoint in {path!r} (looked for {checkpoint}/state.pt).")
    if not os.path.isfile(os.path.join(run_dir, "config.yaml")):
        raise FileNotFoundError(f"checkpoint.resume: {run_dir!r} has no config.yaml.")
    return run_dir, checkpoint


def build(argv: list[str]) -> Run:
    """Configuration, run directory and all the pieces; restores the checkpoint when resuming."""
    cfg = load_config(argv)
    if cfg.checkpoint.resume is None:
        run_dir = make_run_dir(cfg)
        OmegaConf.save(cfg, os.path.join(run_dir, "config.yaml"))
        return make_trainer(cfg, run_dir)
    run_dir, checkpoint = _resolve_resume(cfg.checkpoint.resume)
    # the saved configuration, updated by this command line (e.g. a larger total_frames)
    cfg = load_run_config(run_dir, argv)
    counters = torch.load(os.path.join(checkpoint, "state.pt"), weights_only=False)["counters"]
    run = make_trainer(cfg, run_dir, frames_done=counters["frames"], resume_frames=counters["frames"])
    try:
        load_checkpoint(run.trainer, checkpoint, run.online_buffer if cfg.checkpoint.save_buffer else None)
    except BaseException:
        run.close()
        raise
    print(f"resumed {run_dir} at {counters['frames']} frames, {counters['updates']} updates", file=sys.stderr)
    return run


def make_plots(run: Run) -> list[str]:
    """Learning curve, subgoal curriculum, and the scene with the curriculum and its subgoals."""
    from torchrl_csirl.visualization import plot_learning_curve, plot_subgoal_curriculum, render_curriculum

    paths = [
        plot_learning_curve(run.evaluation.history, os.path.join(run.run_dir, "learning_curve.png"),
                            title=f"CSIRL on {run.spec.name}"),
        plot_subgoal_curriculum(run.selection.history, os.path.join(run.run_dir, "subgoals.png"),
                                curriculum_length=run.curriculum.length, delta=run.curriculum.delta),
        render_curriculum(run.spec.name, run.curriculum.expert_observations,
                          sorted({h["subgoal"] for h in run.selection.history} | {run.curriculum.subgoal}),
                          os.path.join(run.run_dir, "curriculum.png")),
    ]
    return [os.fspath(p) for p in paths]


def expert_accomplish_rate(metadata: dict) -> float | None:
    """Mean accomplish rate of the demonstrations recorded in traffic (None if not recorded)."""
    episodes = [e for e in metadata.get("episodes", []) if isinstance(e, dict) and "accomplish_rate" in e]
    traffic = [e["accomplish_rate"] for e in episodes if not e.get("empty_road")]
    rates = traffic or [e["accomplish_rate"] for e in episodes]
    return sum(rates) / len(rates) if rates else None


def finish(run: Run) -> dict[str, object]:
    """Final evaluation, checkpoint, policy, plots and the summary."""
    trainer = run.trainer
    run.checkpoint.save(trainer)
    final = run.evaluate(int(run.cfg.eval.final_episodes))
    expert_rate = expert_accomplish_rate(run.demos.metadata)
    save_policy(run.modules.actor, os.path.join(run.run_dir, "policy.pt"), obs_dim=run.spec.obs_dim,
                action_dim=run.spec.action_dim, scenario=run.spec.name, frames=trainer.frames)
    throughput = trainer.throughput
    summary = {
        "scenario": run.spec.name,
        "method": "csirl" if run.cfg.csirl.intrinsic else "csirl-b",
        "preset": run.cfg.preset,
        "seed": int(run.cfg.seed),
        "accomplish_rate": final["accomplish_rate"],
        "accomplish_rate_std": final["accomplish_rate_std"],
        "success_rate": final["success_rate"],
        "crash_rate": final["crash_rate"],
        "normalized_accomplish_rate": (
            float(normalized_accomplish_rate(final["accomplish_rate"], expert_rate)) if expert_rate else None
        ),
        "auc": (sum(h["accomplish_rate"] for h in run.evaluation.history) / len(run.evaluation.history)
                if run.evaluation.history else None),
        "eval_episodes": int(run.cfg.eval.final_episodes),
        "final_subgoal": run.curriculum.subgoal,
        "curriculum_length": run.curriculum.length,
        "frames": trainer.frames,
        "updates": trainer.updates,
        "rounds": trainer.rounds,
        "frames_per_s": throughput["frames_per_s"],
        "collect_fps": throughput["collect_fps"],
        "updates_per_s": throughput["updates_per_s"],
        "wall_s": trainer.wall_time,
        "run_dir": run.run_dir,
    }
    run.logger.log({"frames": trainer.frames, "updates": trainer.updates,
                    **{f"test_{k}": v for k, v in final.items()}})
    summary["plots"] = make_plots(run)
    return summary


def main(argv: list[str] | None = None) -> dict[str, object]:
    argv = sys.argv[1:] if argv is None else list(argv)
    start = time.perf_counter()
    run = build(argv)
    try:
        run.trainer.train()
    except TrainingDivergedError as err:
        run.logger.close()
        last = run.checkpoint.path if os.path.exists(run.checkpoint.path) else "none yet"
        raise TrainingDivergedError(
            f"{err}. Training stopped; the last good checkpoint is kept at {last} "
            f"(resume with checkpoint.resume={run.run_dir}, e.g. with a smaller optim.lr)."
        ) from None
    except BaseException:  # Ctrl-C, SIGTERM, errors: keep the logs (checkpoints are already on disk)
        run.logger.close()
        raise
    finally:
        shutdown_collector(run.collector)
    try:
        summary = finish(run)
    finally:
        run.logger.close()
        run.eval_env.close()
    summary["wall_s"] = round(max(summary["wall_s"], 0.0), 1)
    summary["total_wall_s"] = round(time.perf_counter() - start, 1)  # with start-up, final eval and plots
    summary = {k: _scalar(v) for k, v in summary.items()}
    with open(os.path.join(summary["run_dir"], "summary.json"), "w") as f:
        json.dump(summary, f, indent=2)
    print(
        f"{summary['scenario']}: accomplish rate {summary['accomplish_rate']:.3f} "
        f"(success {summary['success_rate']:.2f}) after {summary['frames']} frames / {summary['updates']} updates; "
        f"{summary['frames_per_s']:.1f} frames/s, {summary['updates_per_s']:.1f} updates/s",
        file=sys.stderr,
    )
    print(json.dumps(summary))
    return summary


if __name__ == "__main__":
    # SIGTERM unwinds like Ctrl-C: the worker processes are shut down, logs and checkpoints kept
    signal.signal(signal.SIGTERM, lambda signum, frame: sys.exit(128 + signum))
    try:
        main()
    except (ConfigError, ExpertDataError, TrainingDivergedError, FileNotFoundError) as error:
        print(f"error: {error}", file=sys.stderr)
        if os.environ.get("CSIRL_TRACEBACK"):
            traceback.print_exc()
        sys.exit(2 if not isinstance(error, TrainingDivergedError) else 3)
