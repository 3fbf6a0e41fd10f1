"""A run's finish: the final checkpoint and test evaluation, ``policy.pt``, the learning curve, the video and
the summary fields every recipe reports."""
from __future__ import annotations

import os
from typing import Any

from omegaconf import DictConfig

from torchrl_csirl.run.assembly import Run
from torchrl_csirl.tasks import ScenarioSpec


def learning_curve_auc(history: list[dict[str, Any]]) -> float | None:
    """The mean accomplish rate over the evaluations during training (``history``), without the one before any update
    (frame 0, a warm-started actor's); None without any.

    Examples:
        >>> learning_curve_auc([{"frames": 0, "accomplish_rate": 0.9}, {"frames": 10, "accomplish_rate": 0.2},
        ...                     {"frames": 20, "accomplish_rate": 0.4}])
        0.30000000000000004
    """
    during = [h["accomplish_rate"] for h in history if h["frames"] > 0]
    return sum(during) / len(during) if during else None


def evaluation_summary(cfg: DictConfig, spec: ScenarioSpec, method: str, final: dict[str, float],
                 expert_rate: float | None) -> dict[str, Any]:
    """The summary fields of a run's final test evaluation ``final`` (:func:`evaluate_policy`'s
    output), with the accomplish rate normalised by ``expert_rate`` (None: not normalised)."""
    from torchrl_csirl.tasks import normalized_accomplish_rate

    return {
        "scenario": spec.name,
        "method": method,
        "preset": cfg.get("preset", "default"),
        "seed": cfg.seed,
        "accomplish_rate": final["accomplish_rate"],
        "accomplish_rate_std": final["accomplish_rate_std"],
        "success_rate": final["success_rate"],
        "crash_rate": final["crash_rate"],
        "return": final["env_return"],  # the env's own reward (robotics: the paper's metric; driving: reference)
        "normalized_accomplish_rate": (
            float(normalized_accomplish_rate(final["accomplish_rate"], expert_rate)) if expert_rate else None),
        "eval_episodes": cfg.eval.final_episodes,
    }


def final_summary(run: Run, method: str, title: str) -> dict[str, Any]:
    """Final checkpoint and test evaluation, ``policy.pt``, the learning curve, and the summary
    fields every recipe reports (the method adds its own). A run keeping its best policy
    (``run.keep_best``, :class:`~torchrl_csirl.trainers.KeepBestPolicy`) is tested and saved with
    those weights (``policy_from`` in the summary); its checkpoint keeps the last ones."""
    from torchrl_csirl.analysis.visualization import plot_learning_curve
    from torchrl_csirl.modules import save_policy
    from torchrl_csirl.run.run import expert_accomplish_rate

    trainer, cfg = run.trainer, run.cfg
    run.checkpoint.save(trainer)
    # eval.keep_best: the best evaluation's weights, loaded after the checkpoint (which keeps the last, to resume)
    kept = run.keep_best.restore() if run.keep_best is not None else None
    final = run.evaluate(cfg.eval.final_episodes)
    expert_rate = expert_accomplish_rate(run.demos.metadata) if run.demos is not None else None
    save_policy(run.mirror.policy, os.path.join(run.run_dir, "policy.pt"), obs_dim=run.spec.obs_dim,
                action_dim=run.spec.action_dim, scenario=run.spec.name,
                frames=trainer.frames if kept is None else kept["frames"])  # the frames its weights had seen
    throughput = trainer.throughput
    history = run.evaluation.history
    summary = {
        **evaluation_summary(cfg, run.spec, method, final, expert_rate),
        "device": str(run.device),
        "auc": learning_curve_auc(history),
        "frames": trainer.frames,
        "updates": trainer.updates,
        "rounds": trainer.rounds,
        "frames_per_s": throughput["frames_per_s"],
        "collect_fps": throughput["collect_fps"],
        "updates_per_s": throughput["updates_per_s"],
        "wall_s": round(max(trainer.wall_time, 0.0), 1),
        "earlier_wall_s": round(trainer.elapsed_before, 1),  # a resumed run's earlier processes (total_wall_s)
        "run_dir": run.run_dir,
    }
    if kept is not None:
        summary["policy_from"] = {"kept": "best evaluation", **kept}
    run.logger.log({"frames": trainer.frames, "updates": trainer.updates,
                    **{f"test_{k}": v for k, v in final.items()}})
    if cfg.eval.video:
        from torchrl_csirl.run.video import film_final_episode

        summary["videos"] = film_final_episode(run)
    curve = plot_learning_curve(history, os.path.join(run.run_dir, "learning_curve.png"), title=title)
    summary["plots"] = [os.fspath(curve)]
    return summary
