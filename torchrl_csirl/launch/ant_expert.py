"""The schema of ``recipes/train_ant_expert.py``: SAC on the ant's goal-reaching task
(``ant-goal``), the run that trains the AntMaze expert's walking policy.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

from torchrl_csirl.launch.config import (
    DEVICES,
    CheckpointConfig,
    CollectorConfig,
    EvalConfig,
    LearnerReplayBufferConfig,
    LoggerConfig,
    UpdateRatioConfig,
    option,
)
from torchrl_csirl.objectives._imitation import SACHyperparameters

__all__ = ["AntExpertConfig", "TASK"]

TASK = "ant-goal"


@dataclass
class AntEnvConfig:
    scenario: str = option(TASK, choices=(TASK,), help="the training task (chained-hop goal reaching)")


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
