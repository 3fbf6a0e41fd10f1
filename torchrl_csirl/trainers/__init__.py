"""Training loop pieces: :class:`CSIRLTrainer`, its CSIRL hooks, evaluation, checkpoints, metrics."""
from __future__ import annotations

from torchrl_csirl.trainers.collection import shutdown_collector
from torchrl_csirl.trainers.evaluation import evaluate_policy
from torchrl_csirl.trainers.hooks import (
    ActorBehaviourCloning,
    CheckpointHook,
    EvaluationHook,
    MetaRewardUpdate,
    SACUpdate,
    SubgoalSelectionHook,
    load_checkpoint,
)
from torchrl_csirl.trainers.metrics_logger import MetricsLogger
from torchrl_csirl.trainers.trainer import CSIRLTrainer, TrainingDivergedError, check_finite_losses

__all__ = [
    "ActorBehaviourCloning",
    "CSIRLTrainer",
    "CheckpointHook",
    "EvaluationHook",
    "MetaRewardUpdate",
    "MetricsLogger",
    "SACUpdate",
    "SubgoalSelectionHook",
    "TrainingDivergedError",
    "check_finite_losses",
    "evaluate_policy",
    "load_checkpoint",
    "shutdown_collector",
]
