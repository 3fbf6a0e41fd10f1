"""An expert for any task, and its demonstrations: ``python recipes/train_expert.py env.gym_id=Hopper-v5 [key=value ...]``.

SAC on the task's own reward (the baselines' learner, published SAC defaults, two critics,
256 x 256 networks) with the run layer's machinery: collector workers, checkpoints with the replay
buffer every ``checkpoint.every_rounds`` rounds (exact resume with ``checkpoint.resume=<run dir>``;
experts take hours on 2 cores), metrics, a learning curve of the test return, ``policy.pt`` and
``summary.json``. At the end the deterministic policy is rolled for ``demos.episodes`` episodes from
seed ``demos.seed`` and written as demonstrations (``demos.path``, default
``<run dir>/demos_<episodes>.npz``; ``demos.minari_id`` also writes a local Minari dataset), the file
every imitation script reads with ``expert.path=``.

The task: ``env.gym_id=<id>`` (any gymnasium id with flat ``Box`` spaces), ``env.scenario=<name>`` (a
robotics task, ``ant-goal``, or with ``env.module=<module>`` a task of your own). A batch must cover an
episode per environment: ``collector.frames_per_batch`` >= workers x the episode limit.

Examples::

    python recipes/train_expert.py env.gym_id=Hopper-v5 collector.frames_per_batch=2000
    python recipes/train_expert.py checkpoint.resume=runs/Hopper-v5-sac-s0-...        # continue
"""
from __future__ import annotations

import os
import sys

from omegaconf import DictConfig
from torchrl.envs import ExplorationType, set_exploration_type

from torchrl_csirl.launch import config as config_lib
from torchrl_csirl.launch.builders import Run, check_collector, final_summary, open_train_and_finish
from torchrl_csirl.launch.expert_training import ExpertTrainingConfig, make_sac_trainer
from torchrl_csirl.launch.robotics import prepare_task, resolve_task
from torchrl_csirl.launch.run import resolve_device, run_script, write_summary

__all__ = ["ExpertTrainingConfig", "load_config", "load_run_config", "main", "write_demonstrations"]


def _checked(cfg: DictConfig, overrides: list[str] | None) -> DictConfig:
    check_collector(cfg.collector)
    resolve_device(cfg.device)
    resolve_task(cfg, overrides)
    return cfg


def load_config(overrides: list[str] | None = None) -> DictConfig:
    """The defaults and ``key=value`` overrides (the task registered first, :func:`prepare_task`).

    Examples:
        >>> cfg = load_config(["env.gym_id=MountainCarContinuous-v0", "collector.frames_per_batch=2000"])
        >>> cfg.env.scenario, cfg.demos.episodes, cfg.sac.num_qvalue_nets
        ('MountainCarContinuous-v0', 25, 2)
    """
    overrides = prepare_task(overrides)
    return _checked(config_lib.load_config(ExpertTrainingConfig, overrides), overrides)


def load_run_config(run_dir: str, overrides: list[str] | None = None) -> DictConfig:
    """The configuration saved in ``run_dir/config.yaml``, updated by ``overrides`` (resume)."""
    overrides = prepare_task(overrides, run_dir)
    return _checked(config_lib.load_run_config(ExpertTrainingConfig, run_dir, overrides), overrides)


def write_demonstrations(run: Run) -> dict[str, object]:
    """The trained policy's demonstrations (``demos`` section): the ``.npz`` and, if asked, a Minari dataset."""
    from torchrl_csirl.data import record_demonstrations, save_minari_dataset

    demos_cfg, spec = run.cfg.demos, run.spec
    run.mirror.sync()
    with set_exploration_type(ExplorationType.DETERMINISTIC):
        demos = record_demonstrations(spec.name, run.mirror.policy, demos_cfg.episodes, seed=demos_cfg.seed,
                                      only_successful=demos_cfg.only_successful, min_return=demos_cfg.min_return)
    path = demos_cfg.path or os.path.join(run.run_dir, f"demos_{demos_cfg.episodes}.npz")
    demos.save(path)
    episodes = demos.metadata["episodes"]
    out: dict[str, object] = {"demos_path": os.path.abspath(path), "demos_episodes": len(episodes),
                              "demos_return": sum(e["return"] for e in episodes) / len(episodes),
                              "demos_success_rate": sum(e["success"] for e in episodes) / len(episodes)}
    if demos_cfg.minari_id:
        save_minari_dataset(demos, demos_cfg.minari_id, task=spec.name, overwrite=True)
        out["demos_minari_id"] = demos_cfg.minari_id
    return out


def finish(run: Run) -> dict[str, object]:
    """Final test, ``policy.pt``, the learning curve, the demonstrations, the summary."""
    summary = final_summary(run, "sac", title=f"SAC on {run.spec.name} (its own reward)")
    if run.cfg.demos.episodes:
        summary.update(write_demonstrations(run))
    return summary


def main(argv: list[str] | None = None) -> dict[str, object]:
    argv = sys.argv[1:] if argv is None else list(argv)
    if config_lib.help_requested(argv, __doc__, ExpertTrainingConfig):
        return {}
    summary = open_train_and_finish(argv, lambda cfg: "sac", make_sac_trainer, load_config, load_run_config, finish)
    demos = f"; {summary['demos_episodes']} demonstrations in {summary['demos_path']}" if "demos_path" in summary else ""
    print(f"{summary['scenario']}: test return {summary['return']:.1f} (success {summary['success_rate']:.2f}) after "
          f"{summary['frames']} frames / {summary['updates']} updates{demos}", file=sys.stderr)
    return write_summary(summary, summary["run_dir"])


if __name__ == "__main__":
    run_script(main)
