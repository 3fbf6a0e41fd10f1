"""The schema and finish of ``recipes/train_ant_expert.py``: SAC on the ant's goal-reaching task
(``ant-goal``), the run that trains the AntMaze expert's walking policy, tested at the end as the walker of the
AntMaze waypoint expert (its recipe: :data:`~torchrl_csirl.methods.expert.ANT_EXPERT_RECIPE`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

from torchrl_csirl.objectives._imitation import SACHyperparameters
from torchrl_csirl.run.assembly import Run
from torchrl_csirl.run.config import (
    DEVICES,
    CheckpointConfig,
    CollectorConfig,
    EvalConfig,
    LearnerReplayBufferConfig,
    LoggerConfig,
    UpdateRatioConfig,
    option,
)
from torchrl_csirl.run.final import final_summary

__all__ = ["AntExpertConfig", "TASK", "evaluate_waypoint_expert", "finish"]

TASK = "ant-goal"


@dataclass
class AntEnvConfig:
    task: str = option(TASK, choices=(TASK,), help="the training task (chained-hop goal reaching; env.scenario: deprecated "
                                                   "spelling)")


@dataclass
class AntCollectorConfig(CollectorConfig):
    total_frames: int = option(1_000_000, above=0, help="environment frames")
    frames_per_batch: int = option(1200, above=0,
                                   help="frames per collected batch (>= 300, one episode, per environment)")
    init_random_frames: int = option(10_000, minimum=0, help="uniform random actions first")


@dataclass
class AntReplayBufferConfig(LearnerReplayBufferConfig):
    warmup_frames: int = option(10_000, minimum=0, help="transitions in the buffer before the first update")


@dataclass
class AntEvalConfig(EvalConfig):
    episodes: int = option(20, above=0, help="deterministic ant-goal episodes (4-goal chains) per evaluation")
    final_episodes: int = option(100, above=0, help="ant-goal episodes of the final test")
    stop_at_return: Optional[float] = option(None, help="end training at the first evaluation whose mean return reaches "
                                                        "this (then the final test; null: train to collector.total_frames)")
    keep_best: bool = option(False, help="finish (final test, policy.pt, demonstrations) with the policy of the best "
                                         "evaluation, kept in <run dir>/best_policy.pt, instead of the last")


@dataclass
class AntCheckpointConfig(CheckpointConfig):
    every_rounds: int = option(5, minimum=0, help="checkpoint cadence in rounds (0: only at the end)")


@dataclass
class ExpertEvalConfig:
    episodes: int = option(20, minimum=0, help="AntMaze episodes driven by the waypoint expert at the end (0: none)")
    seed: int = option(10_000, minimum=0, help="AntMaze episode i uses seed + i")


@dataclass
class AntExpertConfig:
    """``recipes/train_ant_expert.py``: SAC on the ant's goal-reaching task."""

    preset: str = option("default", help="default (no other preset)")
    seed: int = option(0, minimum=0, help="random seed")
    device: str = option("auto", choices=DEVICES, help="the learner's device (auto: a GPU when there is one)")
    updates_per_round: int = option(10_000, above=0, help="updates between two evaluations (a round)")
    env: AntEnvConfig = field(default_factory=AntEnvConfig)
    collector: AntCollectorConfig = field(default_factory=AntCollectorConfig)
    replay_buffer: AntReplayBufferConfig = field(default_factory=AntReplayBufferConfig)
    optim: UpdateRatioConfig = field(default_factory=UpdateRatioConfig)
    sac: SACHyperparameters = field(default_factory=SACHyperparameters)
    eval: AntEvalConfig = field(default_factory=AntEvalConfig)
    expert_eval: ExpertEvalConfig = field(default_factory=ExpertEvalConfig)
    logger: LoggerConfig = field(default_factory=LoggerConfig)
    checkpoint: AntCheckpointConfig = field(default_factory=AntCheckpointConfig)


# ---------------------------------------------------------------------------------------- finish
def evaluate_waypoint_expert(policy, episodes: int, seed: int) -> dict[str, float]:
    """The waypoint expert driven by ``policy`` on ``episodes`` AntMaze U-maze episodes (seed + i).

    Returns:
        ``success_rate`` (goal reached), ``progress`` (mean route progress), ``steps`` (mean length).
    """
    from torchrl_csirl.tasks import make_gym_env
    from torchrl_csirl.tasks.robotics import WaypointAntExpert

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
