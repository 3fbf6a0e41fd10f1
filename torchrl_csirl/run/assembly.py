"""A run's pieces put together: the networks' input map, the online buffer, the logger, the :class:`Run` and
the trainer with the shared hooks (:func:`assemble_trainer`), which a method's recipe calls with its losses and
update step."""
from __future__ import annotations

import os
import sys
from dataclasses import dataclass
from typing import Any, Callable, Generic, TypeVar

import torch
from omegaconf import DictConfig, OmegaConf
from torch import nn
from torchrl.collectors import BaseCollector
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
from torchrl.envs import Compose, EnvBase, Transform

from torchrl_csirl.data import ExpertDemonstrations, FilledRowsCheckpointer
from torchrl_csirl.modules import make_input_features
from torchrl_csirl.run.collection import PolicyMirror, make_collector, make_eval_env
from torchrl_csirl.tasks import ScenarioSpec, TaskSpec
from torchrl_csirl.trainers import (
    CheckpointHook,
    CSIRLTrainer,
    EvaluationHook,
    KeepBestPolicy,
    MetricsLogger,
    WorkerErrorLog,
    evaluate_policy,
    shutdown_collector,
)


# ---------------------------------------------------------------------------------------- models
def model_input_features(model: DictConfig, spec: TaskSpec) -> nn.Module | None:
    """The input map every network of a recipe reads the observation through (the ``model`` section:
    ``ego_relative_features``, ``lane_features``; :func:`~torchrl_csirl.modules.make_input_features`), or None."""
    return make_input_features(spec, model.ego_relative_features, model.lane_features)


# ---------------------------------------------------------------------------------------- buffers, logging
def make_online_buffer(size: int, batch_size: int, transforms: list[Transform], device: torch.device) -> TensorDictReplayBuffer:
    """The online buffer, stored on the learner's device; ``transforms`` run at sampling time.

    Its checkpoints hold the filled rows only (:class:`~torchrl_csirl.data.FilledRowsCheckpointer`).
    """
    return TensorDictReplayBuffer(
        storage=LazyTensorStorage(size, device=device),
        batch_size=batch_size,
        checkpointer=FilledRowsCheckpointer(),
        transform=Compose(*transforms) if transforms else None,
    )


def make_logger(cfg: DictConfig, run_dir: str, resume_frames: int | None = None) -> MetricsLogger:
    """metrics.jsonl / metrics.csv in the run directory, plus W&B (offline by default) or TorchRL CSV."""
    return MetricsLogger(
        run_dir,
        backend=cfg.logger.backend,
        exp_name=os.path.basename(run_dir),
        config=OmegaConf.to_container(cfg, resolve=True),
        wandb_mode=cfg.logger.mode,
        project=cfg.logger.project,
        resume_frames=resume_frames,
    )


# ---------------------------------------------------------------------------------------- the run
P = TypeVar("P")


@dataclass
class Run(Generic[P]):
    """What every recipe's run holds; a method's own pieces are ``parts`` (e.g.
    :class:`~torchrl_csirl.methods.csirl.CSIRLParts`, :class:`~torchrl_csirl.methods.baselines.ImitationParts`)."""

    cfg: DictConfig
    spec: TaskSpec
    run_dir: str
    device: torch.device
    demos: ExpertDemonstrations | None
    online_buffer: TensorDictReplayBuffer
    mirror: PolicyMirror
    collector: BaseCollector
    eval_env: EnvBase
    logger: MetricsLogger
    trainer: CSIRLTrainer
    evaluation: EvaluationHook
    checkpoint: CheckpointHook
    parts: P = None
    worker_errors: WorkerErrorLog | None = None
    #: ``eval.keep_best``: the best evaluation's weights, tested and saved at the end (the checkpoint keeps the last)
    keep_best: KeepBestPolicy | None = None

    def evaluate(self, episodes: int) -> dict[str, float]:
        """The deterministic policy on ``episodes`` seeded test episodes."""
        self.mirror.sync()
        return evaluate_policy(self.eval_env, self.mirror.policy, episodes=episodes,
                               max_steps=self.spec.max_steps, seed=self.cfg.eval.seed)

    def close(self) -> None:
        shutdown_collector(self.collector)
        self.eval_env.close()
        if self.worker_errors is not None:
            self.worker_errors.close()


def assemble_trainer(
    cfg: DictConfig,
    spec: ScenarioSpec,
    run_dir: str,
    *,
    device: torch.device,
    demos: ExpertDemonstrations | None,
    policy: nn.Module,
    online_buffer: TensorDictReplayBuffer,
    update_step: Callable[[CSIRLTrainer], dict[str, torch.Tensor]],
    total_frames: int,
    updates_per_round: int,
    states: dict[str, Any],
    round_hooks: list[tuple[str, Any]] = (),
    frames_done: int = 0,
    resume_frames: int | None = None,
    parts: Any = None,
    behaviour: Callable[[nn.Module], nn.Module] | None = None,
) -> Run:
    """The trainer with the shared hooks: evaluation and any ``round_hooks`` at each round end,
    checkpoints, metrics logging, and the CPU policy mirror for a learner on another device.

    Args:
        cfg: the recipe configuration (shared sections).
        spec: the scenario.
        run_dir: the run directory.
        device: the learner's device.
        demos: the demonstrations.
        policy: the learner's policy (what acts and is evaluated).
        online_buffer: the online replay buffer.
        update_step: one update (``callable(trainer) -> dict of losses``).
        total_frames: environment frames to collect.
        updates_per_round: updates between two round ends.
        states: ``name -> object with state_dict/load_state_dict`` saved in checkpoints.
        round_hooks: ``(name, hook)`` called at each round end before the evaluation.
        frames_done: frames already collected (resume).
        resume_frames: the resumed run's frames (the logger drops rows past them).
        parts: the method's own pieces (``run.parts``).
        behaviour: wraps the (mirrored) policy for the collector only, e.g. exploration noise
            (:class:`~torchrl_csirl.modules.MeanActionGaussianNoise`); the evaluation acts with the policy.
    """
    mirror = PolicyMirror(policy, device)
    logger = make_logger(cfg, run_dir, resume_frames)
    eval_env = make_eval_env(spec.name)
    # last: the worker processes start here
    acting = mirror.policy if behaviour is None else behaviour(mirror.policy)
    worker_errors = WorkerErrorLog()
    collector = make_collector(spec.name, cfg.collector, acting, frames_done, worker_errors)
    trainer = CSIRLTrainer(
        collector=collector,
        online_buffer=online_buffer,
        update_step=update_step,
        total_frames=total_frames,
        utd_ratio=cfg.optim.utd_ratio,
        updates_per_round=updates_per_round,
        warmup_frames=cfg.replay_buffer.warmup_frames,
        clear_buffer_each_round=cfg.replay_buffer.clear_each_round,
        seed=cfg.seed,
        progress_bar=cfg.logger.progress_bar and sys.stderr.isatty(),
    )

    curve_seed = cfg.eval.seed if cfg.eval.validation_seed is None else cfg.eval.validation_seed

    def run_eval() -> dict[str, float]:  # the learning curve: validation episodes, not the test ones
        return evaluate_policy(eval_env, mirror.policy, episodes=cfg.eval.episodes,
                               max_steps=spec.max_steps, seed=curve_seed)

    evaluation = EvaluationHook(run_eval, every_rounds=cfg.eval.every_rounds)
    checkpoint = CheckpointHook(os.path.join(run_dir, "checkpoints"),
                                online_buffer if cfg.checkpoint.save_buffer else None,
                                every_rounds=cfg.checkpoint.every_rounds)
    if mirror.mirrored:
        trainer.register_op("round_end", mirror.sync, "policy_mirror")
    for name, hook in round_hooks:
        trainer.register_op("round_end", hook, name)
    trainer.register_op("round_end", evaluation, "evaluation")
    trainer.register_op("post_round", checkpoint, "checkpoint")
    if mirror.mirrored:  # after each batch's updates, before the next collection
        trainer.register_op("log", mirror.sync, "policy_mirror")
    trainer.register_op("log", lambda t, row: logger.log(row), "metrics_logger")
    for name, obj in states.items():
        trainer.register_state(name, obj)
    trainer.register_state("evaluation", evaluation)
    return Run(cfg, spec, run_dir, device, demos, online_buffer, mirror, collector, eval_env, logger, trainer,
               evaluation, checkpoint, parts, worker_errors)
