"""The recipes of ``recipes/train_expert.py`` and ``recipes/train_ant_expert.py`` (:data:`EXPERT_RECIPE`,
:data:`ANT_EXPERT_RECIPE`); the schema, builder and finish of the first: SAC on a task's own reward, then demonstrations
of the trained policy written to a file, for any non-driving task (a robotics task, ``ant-goal``, a
task of your own, a gymnasium id). ``recipes/train_ant_expert.py`` is the same run on ``ant-goal`` with
the AntMaze waypoint test at the end.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Optional

import torch
from omegaconf import DictConfig, OmegaConf
from torchrl.envs import ExplorationType, set_exploration_type

from torchrl_csirl.methods.ant_expert import (
    TASK,
    AntCheckpointConfig,
    AntCollectorConfig,
    AntEvalConfig,
    AntExpertConfig,
    AntReplayBufferConfig,
)
from torchrl_csirl.methods.ant_expert import finish as ant_finish
from torchrl_csirl.modules import make_actor, make_input_features, make_qvalue
from torchrl_csirl.objectives import FusedSoftUpdate, SACHyperparameters, make_sac_learner
from torchrl_csirl.run.assembly import Run, assemble_trainer, make_online_buffer
from torchrl_csirl.run.collection import check_collector_config
from torchrl_csirl.run.config import DEVICES, LoggerConfig, UpdateRatioConfig, option
from torchrl_csirl.run.final import final_summary
from torchrl_csirl.run.recipes import Recipe, register_recipe
from torchrl_csirl.run.run import resolve_device
from torchrl_csirl.run.task_schemas import RoboticsEnvConfig
from torchrl_csirl.tasks import resolve_scenario, task_names
from torchrl_csirl.trainers import KeepBestPolicy, SACUpdate, StopAtTarget

__all__ = ["ANT_EXPERT_RECIPE", "BEST_POLICY_FILE", "DemosConfig", "EXPERT_RECIPE", "ExpertEnvConfig", "ExpertTrainingConfig",
           "finish", "make_sac_trainer", "write_demonstrations"]

#: the weights of the best evaluation (``eval.keep_best``), in the run directory
BEST_POLICY_FILE = "best_policy.pt"


def expert_task_choices() -> tuple[str, ...]:
    """Every task but the driving scenes (which have their scripted drivers): ``ant-goal`` included."""
    return task_names(driving=False)


@dataclass
class ExpertEnvConfig(RoboticsEnvConfig):
    task: str = option(TASK, choices=expert_task_choices,
                       help="the task: a robotics task, ant-goal, one of your own (env.module), or env.gym_id's "
                            "(env.scenario: deprecated spelling)")


@dataclass
class DemosConfig:
    episodes: int = option(25, minimum=0, help="demonstrations of the trained policy written at the end (0: none)")
    seed: int = option(20_000, minimum=0, help="demonstration i is seeded with seed + i (apart from the test seeds)")
    only_successful: bool = option(False, help="keep only episodes that succeed (up to 10 x episodes tries)")
    min_return: Optional[float] = option(None, help="keep only episodes that earn at least this return (up to 10 x "
                                                    "episodes tries; IQ-Learn's MuJoCo threshold; null: all)")
    path: Optional[str] = option(None, help="the .npz written (null: <run dir>/demos_<episodes>.npz)")
    minari_id: Optional[str] = option(None, help="also write a local Minari dataset with this id (null: none)")


@dataclass
class ExpertTrainingConfig:
    """``recipes/train_expert.py``: SAC on a task's own reward, then its demonstrations."""

    preset: str = option("default", help="default (no other preset)")
    seed: int = option(0, minimum=0, help="random seed")
    device: str = option("auto", choices=DEVICES, help="the learner's device (auto: a GPU when there is one)")
    updates_per_round: int = option(10_000, above=0, help="updates between two evaluations (a round)")
    env: ExpertEnvConfig = field(default_factory=ExpertEnvConfig)
    collector: AntCollectorConfig = field(default_factory=AntCollectorConfig)
    replay_buffer: AntReplayBufferConfig = field(default_factory=AntReplayBufferConfig)
    optim: UpdateRatioConfig = field(default_factory=UpdateRatioConfig)
    sac: SACHyperparameters = field(default_factory=SACHyperparameters)
    eval: AntEvalConfig = field(default_factory=AntEvalConfig)
    demos: DemosConfig = field(default_factory=DemosConfig)
    logger: LoggerConfig = field(default_factory=LoggerConfig)
    checkpoint: AntCheckpointConfig = field(default_factory=AntCheckpointConfig)


def make_sac_trainer(cfg: DictConfig, run_dir: str, frames_done: int = 0, resume_frames: int | None = None) -> Run:
    """SAC on the environment's own reward (``cfg.env.task``), with the shared hooks (evaluation,
    checkpoints, logging): the run of ``train_expert.py`` and ``train_ant_expert.py``."""
    torch.manual_seed(cfg.seed)
    device = resolve_device(cfg.device)
    spec = resolve_scenario(cfg.env.task)
    hp = SACHyperparameters(**OmegaConf.to_container(cfg.sac))
    features = make_input_features(spec, ego_relative=False)  # the task's hidden entries dropped (locomotion's x)
    actor = make_actor(spec.obs_dim, spec.action_dim, input_features=features)
    loss = make_sac_learner(actor, make_qvalue(spec.obs_dim, spec.action_dim, input_features=features), hp).to(device)
    optimizer = torch.optim.Adam([p for p in loss.parameters() if p.requires_grad], lr=hp.lr)
    online = make_online_buffer(cfg.replay_buffer.size, hp.batch_size, [], device)
    run = assemble_trainer(
        cfg, spec, run_dir, device=device, demos=None, policy=actor, online_buffer=online,
        update_step=SACUpdate(loss, optimizer, FusedSoftUpdate(loss, tau=hp.tau), hp.max_grad_norm),
        total_frames=cfg.collector.total_frames, updates_per_round=cfg.updates_per_round,
        states={"loss": loss, "optim_sac": optimizer}, frames_done=frames_done, resume_frames=resume_frames,
    )
    if cfg.eval.keep_best:  # registered after the evaluation, before the round's checkpoint
        run.keep_best = KeepBestPolicy(run.evaluation, actor, os.path.join(run_dir, BEST_POLICY_FILE))
        run.trainer.register_op("round_end", run.keep_best, "keep_best")
    if cfg.eval.stop_at_return is not None:
        run.trainer.register_op("post_round", StopAtTarget(run.evaluation, cfg.eval.stop_at_return), "stop_at_return")
    return run


# ---------------------------------------------------------------------------------------- finish
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


# ---------------------------------------------------------------------------------------- the recipes
def check_device(cfg: DictConfig) -> None:
    """The learner's device is usable (:func:`~torchrl_csirl.run.run.resolve_device`)."""
    resolve_device(cfg.device)


#: ``recipes/train_expert.py``: SAC on any non-driving task's own reward, then its demonstrations
EXPERT_RECIPE = register_recipe(Recipe(
    name="expert", script="torchrl_csirl.scripts.train_expert", methods=(), schema=ExpertTrainingConfig,
    checks=(check_collector_config, check_device), trainer=make_sac_trainer, finish=finish,
    method_of=lambda cfg: "sac"))
#: ``recipes/train_ant_expert.py``: the AntMaze expert's walker (SAC on ``ant-goal``), tested on the maze
ANT_EXPERT_RECIPE = register_recipe(Recipe(
    name="ant_expert", script="torchrl_csirl.scripts.train_ant_expert", methods=(), schema=AntExpertConfig,
    checks=(check_collector_config, check_device), trainer=make_sac_trainer, finish=ant_finish,
    method_of=lambda cfg: "sac"))
