"""Training loop pieces: :class:`CSIRLTrainer`, its CSIRL hooks, evaluation, checkpoints, metrics."""
from __future__ import annotations

from torchrl_csirl.trainers.checkpoint import (
    CheckpointError,
    CheckpointHook,
    load_checkpoint,
    read_checkpoint_state,
)
from torchrl_csirl.trainers.collection import CollectorWorkerError, WorkerErrorLog, shutdown_collector, start_collector
from torchrl_csirl.trainers.evaluation import episode_metrics, evaluate_episodes, evaluate_policy
from torchrl_csirl.trainers.hooks import EvaluationHook, KeepBestPolicy, StopAtTarget, SubgoalSelectionHook
from torchrl_csirl.trainers.imitation import (
    IMITATION_METHODS,
    ImitationMethod,
    hyperparameters_class,
    make_imitation_method,
)
from torchrl_csirl.trainers.imitation_updates import (
    AdversarialImitationUpdate,
    DiscriminatorStep,
    ValueDICEUpdate,
)
from torchrl_csirl.trainers.interrupt import StopOnSignals, ignoring_interrupts
from torchrl_csirl.trainers.metrics_logger import MetricsLogger
from torchrl_csirl.trainers.trainer import (
    CSIRLTrainer,
    TrainingDivergedError,
    TrainingInterrupted,
    check_finite_losses,
)
from torchrl_csirl.trainers.updates import BCUpdate, MetaRewardUpdate, SACUpdate

__all__ = [
    "IMITATION_METHODS",
    "AdversarialImitationUpdate",
    "BCUpdate",
    "CSIRLTrainer",
    "CheckpointError",
    "CheckpointHook",
    "CollectorWorkerError",
    "DiscriminatorStep",
    "EvaluationHook",
    "ImitationMethod",
    "MetaRewardUpdate",
    "MetricsLogger",
    "SACUpdate",
    "StopOnSignals",
    "KeepBestPolicy",
    "StopAtTarget",
    "SubgoalSelectionHook",
    "TrainingDivergedError",
    "TrainingInterrupted",
    "ValueDICEUpdate",
    "WorkerErrorLog",
    "check_finite_losses",
    "episode_metrics",
    "evaluate_episodes",
    "evaluate_policy",
    "hyperparameters_class",
    "ignoring_interrupts",
    "load_checkpoint",
    "make_imitation_method",
    "read_checkpoint_state",
    "shutdown_collector",
    "start_collector",
]
