"""Trains the AntMaze expert's goal-reaching ant: ``python recipes/train_ant_expert.py [key=value ...]``.

TorchRL's SAC (the baselines' learner: :func:`~torchrl_csirl.objectives._imitation.make_sac_learner`,
published SAC defaults, two critics, 256 x 256 networks) on the ``ant-goal`` task
(:class:`~torchrl_csirl.envs.robotics.AntGoalEnv`: chains of 4 goals, each 0.9-6.3 m on, in the U-maze,
reward = speed toward the goal, +10 on arrival), with the shared recipe machinery: collector
workers, checkpoints every ``checkpoint.every_rounds`` rounds with the replay buffer (exact resume
with ``checkpoint.resume=<run dir>``; the run takes hours on 2 cores), metrics CSV/JSONL, wandb
offline, a learning curve of the chain success (all 4 goals reached), ``policy.pt`` and ``summary.json``.

At the end, the trained policy drives the ant through the U-maze as
:class:`~torchrl_csirl.envs.robotics.WaypointAntExpert` on ``expert_eval.episodes`` AntMaze
episodes from seed ``expert_eval.seed`` (unseen: the training task draws its own hops), and the
summary reports that success rate (the expert's acceptance figure, docs/studies/robotics.md) beside the
chain success (``hop_success_rate``: the share of test episodes that reached all 4 goals).
``device=auto`` trains on a GPU when there is one.

Examples::

    python recipes/train_ant_expert.py                                   # 1 M frames, CPU or GPU
    python recipes/train_ant_expert.py checkpoint.resume=runs/ant-goal-sac-s0-...   # continue
    python recipes/generate_experts.py --scenario antmaze-umaze --ant-policy runs/ant-goal-sac-s0-... \\
        --episodes 100 --seed 10000                                     # the expert on unseen seeds
"""
from __future__ import annotations

import sys

from omegaconf import DictConfig

from torchrl_csirl.launch import config as config_lib
from torchrl_csirl.launch.ant_expert import AntExpertConfig
from torchrl_csirl.launch.builders import Run, check_collector, final_summary, open_train_and_finish
from torchrl_csirl.launch.expert_training import make_sac_trainer
from torchrl_csirl.launch.run import resolve_device, run_script, write_summary

__all__ = ["AntExpertConfig", "evaluate_waypoint_expert", "load_config", "main", "make_trainer"]


# ---------------------------------------------------------------------------------------- config
def _checked(cfg: DictConfig) -> DictConfig:
    check_collector(cfg.collector)
    resolve_device(cfg.device)
    return cfg


def load_config(overrides: list[str] | None = None) -> DictConfig:
    """The defaults and ``key=value`` overrides.

    Examples:
        >>> cfg = load_config(["seed=1"])
        >>> cfg.env.scenario, cfg.collector.total_frames, cfg.sac.num_qvalue_nets
        ('ant-goal', 1000000, 2)
    """
    return _checked(config_lib.load_config(AntExpertConfig, overrides))


def load_run_config(run_dir: str, overrides: list[str] | None = None) -> DictConfig:
    """The configuration saved in ``run_dir/config.yaml``, updated by ``overrides`` (resume)."""
    return _checked(config_lib.load_run_config(AntExpertConfig, run_dir, overrides))


# ---------------------------------------------------------------------------------------- assembly
#: SAC on the environment's own reward (the generic expert run, ``recipes/train_expert.py``)
make_trainer = make_sac_trainer


def evaluate_waypoint_expert(policy, episodes: int, seed: int) -> dict[str, float]:
    """The waypoint expert driven by ``policy`` on ``episodes`` AntMaze U-maze episodes (seed + i).

    Returns:
        ``success_rate`` (goal reached), ``progress`` (mean route progress), ``steps`` (mean length).
    """
    from torchrl_csirl.envs import make_gym_env
    from torchrl_csirl.envs.robotics import WaypointAntExpert

    env = make_gym_env("antmaze-umaze")
    expert = WaypointAntExpert(policy)
    successes, progress, steps = [], [], []
    try:
        for i in range(episodes):
            _, info = env.reset(seed=seed + i)
            expert.reset(env)
            for t in range(1, env.max_steps + 1):
                _, _, terminated, truncated, info = env.step(expert.act(env))
                if terminated or truncated:
                    break
            successes.append(float(info["success"]))
            progress.append(float(info["progress"]))
            steps.append(t)
    finally:
        env.close()
    n = max(len(successes), 1)
    return {"success_rate": sum(successes) / n, "progress": sum(progress) / n, "steps": sum(steps) / n}


def finish(run: Run) -> dict[str, object]:
    """Final hop test, ``policy.pt``, the learning curve, the waypoint expert on AntMaze, the summary."""
    summary = final_summary(run, "sac", title="SAC on ant-goal (4-goal chain success)")
    summary["hop_success_rate"] = summary["success_rate"]
    episodes = run.cfg.expert_eval.episodes
    if episodes:
        maze = evaluate_waypoint_expert(run.mirror.policy, episodes, run.cfg.expert_eval.seed)
        summary.update(antmaze_success_rate=maze["success_rate"], antmaze_progress=maze["progress"],
                       antmaze_episodes=episodes, antmaze_seed=run.cfg.expert_eval.seed)
    return summary


def main(argv: list[str] | None = None) -> dict[str, object]:
    argv = sys.argv[1:] if argv is None else list(argv)
    if config_lib.help_requested(argv, __doc__, AntExpertConfig):
        return {}
    summary = open_train_and_finish(argv, lambda cfg: "sac", make_trainer, load_config, load_run_config, finish)
    maze = summary.get("antmaze_success_rate")
    print(f"ant-goal: 4-goal chain success {summary['hop_success_rate']:.2f}"
          + (f", AntMaze with waypoints {maze:.2f}" if maze is not None else "")
          + f" after {summary['frames']} frames / {summary['updates']} updates", file=sys.stderr)
    return write_summary(summary, summary["run_dir"])


if __name__ == "__main__":
    run_script(main)
