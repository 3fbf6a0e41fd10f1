"""The baselines' part of ``recipes/imitation_highway.py``: their configuration schema and builders.

Methods (``method=<name>``):

* ``sac``: SAC (:class:`~torchrl_csirl.objectives.EnsembleSACLoss` with 2 critics, i.e. standard
  SAC) on the paper's "true distance reward": :class:`~torchrl_csirl.transforms.ProgressReward`
  toward the scenario's finish, recomputed at sampling time. Uses no demonstrations for training.
* ``bc``: behavioural cloning, TorchRL's :class:`~torchrl.objectives.BCLoss` (``bc.loss_function``)
  on the deterministic action, on expert batches of ``expert.batch_size``. It runs in the same
  loop as every trained method (same frames collected with its own policy, same number of
  updates, same evaluation cadence), so its learning curve sits on the same axis; the collected
  frames are not used by its update.
* ``random``, ``expert``: reference rows, no training: uniform random actions, and the expert
  driver (:class:`~torchrl_csirl.envs.expert_policy.ExpertDriverPolicy`), scored on the same
  test episodes.

The pieces every recipe shares (environments, collector, buffers, logging, evaluation,
checkpoints, device, run directory, summary) are :mod:`common`'s; fairness with CSIRL comes from
the shared defaults: the same demonstrations (``expert.*``), the same frame budget
(``collector.total_frames``), the same networks (``make_actor`` / ``make_qvalue``, 256 x 256),
the same input features (``model.ego_relative_features``) and the same evaluation (``eval.*``).

Examples:
    >>> cfg = load_config(["method=bc", "env.scenario=roundabout"])
    >>> cfg.method, cfg.env.scenario, cfg.collector.total_frames
    ('bc', 'roundabout', 60000)
    >>> load_config(["method=gibberish"])  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    common.config.ConfigError: method=gibberish: must be one of sac, bc, random, expert...
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import partial
from typing import Any, Optional

import torch
from omegaconf import DictConfig, OmegaConf
from torchrl.envs.utils import RandomPolicy
from torchrl.objectives import BCLoss, SoftUpdate

from common import config as config_lib
from common.builders import Run, assemble_trainer, check_collector, load_experts, make_eval_env, make_logger, \
    make_online_buffer
from common.config import (
    DEVICES,
    CheckpointConfig,
    CollectorConfig,
    ConfigError,
    EnvConfig,
    EvalConfig,
    ExpertConfig,
    LoggerConfig,
    ModelConfig,
    option,
)
from common.registry import register_recipe
from common.run import ExpertDataError, expert_accomplish_rate, resolve_device
from torchrl_csirl.data import ExpertDemonstrations
from torchrl_csirl.envs import SCENARIOS, ScenarioSpec, normalized_accomplish_rate
from torchrl_csirl.modules import EgoRelativeFeatures, make_actor, make_qvalue
from torchrl_csirl.objectives import EnsembleSACLoss
from torchrl_csirl.trainers import BCUpdate, SACUpdate, evaluate_policy
from torchrl_csirl.transforms import CombineRewards, ProgressReward

__all__ = ["ImitationHighwayConfig", "METHODS", "REFERENCE_METHODS", "load_config", "load_run_config", "make_trainer",
           "evaluate_reference"]

#: methods trained by this recipe's loop
TRAINED_METHODS = ("sac", "bc")
#: reference rows: evaluated, not trained
REFERENCE_METHODS = ("random", "expert")
METHODS = (*TRAINED_METHODS, *REFERENCE_METHODS)
#: methods of the benchmark trained by recipes/csirl_highway.py
CSIRL_METHODS = ("csirl", "csirl-b")


# ---------------------------------------------------------------------------------------- config
@dataclass
class ImitationExpertConfig(ExpertConfig):
    batch_size: int = option(256, above=0, help="expert transitions per update (as many as online ones)")


@dataclass
class ImitationReplayBufferConfig:
    size: int = option(1_000_000, above=0, help="online buffer capacity")
    batch_size: int = option(256, above=0, help="online transitions per update")
    clear_each_round: bool = option(False, help="empty the buffer at each round start")
    warmup_frames: int = option(1000, minimum=0, help="transitions in the buffer before the first update of a round")


@dataclass
class ImitationOptimConfig:
    lr: float = option(3.0e-4, above=0.0, help="every network of the method (Adam)")
    utd_ratio: float = option(0.5, above=0.0, help="updates per collected frame")
    tau: float = option(0.005, above=0.0, below=1.0, help="Polyak factor of the target critics")
    max_grad_norm: Optional[float] = option(None, above=0.0, help="clip the gradient norm (null: no clipping)")


@dataclass
class SACBaselineConfig:
    num_qvalue_nets: int = option(2, minimum=2, help="critics (2: standard SAC, the minimum of two)")
    gamma: float = option(0.99, above=0.0, below=1.0, help="discount")
    alpha: float = option(0.01, above=0.0, help="entropy coefficient (its initial value unless fixed_alpha)")
    fixed_alpha: bool = option(False, help="false: SAC's automatic temperature")
    reward_scale: Optional[float] = option(
        None, above=0.0, help="progress reward per unit of normalised distance (null: the scenario's matching scale)")


@dataclass
class BCConfig:
    loss_function: str = option("l2", choices=("l2", "l1"), help="distance of the deterministic action to the expert's")


@dataclass
class ImitationHighwayConfig:
    """``recipes/imitation_highway.py``: one baseline under CSIRL's default budget and evaluation."""

    method: Optional[str] = option(None, choices=METHODS, help="the baseline (required)")
    preset: str = option("default", help="default (no other preset)")
    seed: int = option(0, minimum=0, help="random seed")
    device: str = option("cpu", choices=DEVICES, help="the learner's device (collection stays on the CPU)")
    updates_per_round: int = option(2000, above=0, help="updates between two evaluations (a round)")
    env: EnvConfig = field(default_factory=EnvConfig)
    collector: CollectorConfig = field(default_factory=CollectorConfig)
    expert: ImitationExpertConfig = field(default_factory=ImitationExpertConfig)
    replay_buffer: ImitationReplayBufferConfig = field(default_factory=ImitationReplayBufferConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    optim: ImitationOptimConfig = field(default_factory=ImitationOptimConfig)
    sac: SACBaselineConfig = field(default_factory=SACBaselineConfig)
    bc: BCConfig = field(default_factory=BCConfig)
    eval: EvalConfig = field(default_factory=EvalConfig)
    logger: LoggerConfig = field(default_factory=LoggerConfig)
    checkpoint: CheckpointConfig = field(default_factory=CheckpointConfig)


def check_method(overrides: list[str]) -> None:
    """One clear line for a missing method, or for a CSIRL method (another recipe trains it)."""
    given = [o.split("=", 1)[1] for o in overrides if o.startswith("method=")]
    if not given:
        raise ConfigError(f"method: required (method=<name>), one of {', '.join(METHODS)}")
    if given[-1] in CSIRL_METHODS:
        raise ConfigError(f"method={given[-1]}: CSIRL is trained by recipes/csirl_highway.py "
                          "(recipes/benchmark.py dispatches it there)")


def _checked(cfg: DictConfig) -> DictConfig:
    if cfg.method is None:
        raise ConfigError(f"method=null: must be one of {', '.join(METHODS)}")
    check_collector(cfg.collector)
    resolve_device(cfg.device)
    return cfg


def load_config(overrides: list[str] | None = None) -> DictConfig:
    """The defaults and ``key=value`` overrides (``method=<name>`` required).

    Raises:
        ConfigError: one line naming the bad key or value.
    """
    overrides = list(overrides or [])
    check_method(overrides)
    return _checked(config_lib.load_config(ImitationHighwayConfig, overrides))


def load_run_config(run_dir: str, overrides: list[str] | None = None) -> DictConfig:
    """The configuration saved in ``run_dir/config.yaml``, updated by ``overrides`` (resume)."""
    overrides = list(overrides or [])
    if any(o.startswith("method=") for o in overrides):
        check_method(overrides)
    return _checked(config_lib.load_run_config(ImitationHighwayConfig, run_dir, overrides))


def _loader_of(method: str):
    def load(overrides: list[str]) -> DictConfig:
        return load_config([f"method={method}", *overrides])

    return load


for _method in METHODS:
    register_recipe((_method,), _loader_of(_method))


# ---------------------------------------------------------------------------------------- data
def load_demonstrations(cfg: DictConfig, spec: ScenarioSpec) -> ExpertDemonstrations:
    """:func:`common.builders.load_experts`, with an unavailable shipped size as one :class:`ExpertDataError` line."""
    try:
        return load_experts(cfg.expert, spec)
    except ValueError as err:
        if isinstance(err, ExpertDataError):
            raise
        raise ExpertDataError(f"expert.num_trajectories={cfg.expert.num_trajectories}: {err} "
                              f"(method={cfg.method} needs these demonstrations)") from None


def input_features(cfg: DictConfig, spec: ScenarioSpec) -> EgoRelativeFeatures | None:
    """The ego-relative input map of every network (``model.ego_relative_features``), or None."""
    return EgoRelativeFeatures.from_scenario(spec) if cfg.model.ego_relative_features else None


# ---------------------------------------------------------------------------------------- methods
@dataclass
class MethodParts:
    """What a trained method hands to :func:`common.builders.assemble_trainer`."""

    policy: Any
    online_transforms: list
    make_update_step: Any  # (online_buffer) -> update step
    states: dict[str, Any]


def make_sac(cfg: DictConfig, spec: ScenarioSpec, demos: ExpertDemonstrations, device: torch.device) -> MethodParts:
    """SAC on the progress reward toward the finish (the paper's "SAC (true distance reward)")."""
    features = input_features(cfg, spec)
    actor = make_actor(spec.obs_dim, spec.action_dim, input_features=features)
    loss = EnsembleSACLoss(actor, make_qvalue(spec.obs_dim, spec.action_dim, input_features=features),
                           num_qvalue_nets=cfg.sac.num_qvalue_nets, alpha_init=cfg.sac.alpha,
                           fixed_alpha=cfg.sac.fixed_alpha, gamma=cfg.sac.gamma).to(device)
    optimizer = torch.optim.Adam([p for p in loss.parameters() if p.requires_grad], lr=cfg.optim.lr)
    target_updater = SoftUpdate(loss, tau=cfg.optim.tau)
    reward = ProgressReward.from_scenario(spec, scale=cfg.sac.reward_scale).to(device)
    update = SACUpdate(loss, optimizer, target_updater, cfg.optim.max_grad_norm)
    return MethodParts(actor, [reward, CombineRewards(["progress_reward"])], lambda online: update,
                       {"loss": loss, "optim_sac": optimizer})


def make_bc(cfg: DictConfig, spec: ScenarioSpec, demos: ExpertDemonstrations, device: torch.device) -> MethodParts:
    """Behavioural cloning (TorchRL's ``BCLoss``) on expert batches."""
    actor = make_actor(spec.obs_dim, spec.action_dim, input_features=input_features(cfg, spec)).to(device)
    loss = BCLoss(actor, loss_function=cfg.bc.loss_function)
    optimizer = torch.optim.Adam(actor.parameters(), lr=cfg.optim.lr)
    expert = demos.as_replay_buffer(batch_size=cfg.expert.batch_size, device=device)
    update = BCUpdate(loss, optimizer, expert, cfg.optim.max_grad_norm)
    return MethodParts(actor, [], lambda online: update, {"actor": actor, "optim_bc": optimizer})


METHOD_BUILDERS = {"sac": make_sac, "bc": make_bc}


def make_trainer(cfg: DictConfig, run_dir: str, frames_done: int = 0, resume_frames: int | None = None) -> Run:
    """Builds the method and the trainer with the shared hooks (``run.parts["method"]`` holds its pieces)."""
    torch.manual_seed(cfg.seed)
    device = resolve_device(cfg.device)
    spec = SCENARIOS[cfg.env.scenario]
    demos = load_demonstrations(cfg, spec)
    parts = METHOD_BUILDERS[cfg.method](cfg, spec, demos, device)
    online = make_online_buffer(cfg.replay_buffer.size, cfg.replay_buffer.batch_size, parts.online_transforms, device)
    return assemble_trainer(
        cfg, spec, run_dir, device=device, demos=demos, policy=parts.policy, online_buffer=online,
        update_step=parts.make_update_step(online), total_frames=cfg.collector.total_frames,
        updates_per_round=cfg.updates_per_round, states=parts.states, frames_done=frames_done,
        resume_frames=resume_frames, parts={"method": parts},
    )


# ---------------------------------------------------------------------------------------- reference rows
def reference_policy(method: str, env: Any, spec: ScenarioSpec) -> Any:
    """Uniform random actions (``random``) or the expert driver on ``env`` (``expert``)."""
    if method == "random":
        return RandomPolicy(env.full_action_spec[env.action_key])
    from torchrl_csirl.envs.expert_policy import ExpertDriverPolicy

    return ExpertDriverPolicy(env, spec.name)


def evaluate_reference(cfg: DictConfig, run_dir: str) -> dict[str, Any]:
    """A reference row: its policy on the ``eval.final_episodes`` test episodes, logged; the summary."""
    torch.manual_seed(cfg.seed)
    spec = SCENARIOS[cfg.env.scenario]
    demos = load_demonstrations(cfg, spec)
    env = make_eval_env(spec.name)
    logger = make_logger(cfg, run_dir)
    start = time.perf_counter()
    try:
        final = evaluate_policy(env, reference_policy(cfg.method, env, spec), episodes=cfg.eval.final_episodes,
                                max_steps=spec.max_steps, seed=cfg.eval.seed)
        logger.log({"frames": 0, "updates": 0, **{f"test_{k}": v for k, v in final.items()}})
    finally:
        logger.close()
        env.close()
    expert_rate = expert_accomplish_rate(demos.metadata)
    return {
        "scenario": spec.name,
        "method": cfg.method,
        "preset": cfg.preset,
        "seed": cfg.seed,
        "device": "cpu",
        "accomplish_rate": final["accomplish_rate"],
        "accomplish_rate_std": final["accomplish_rate_std"],
        "success_rate": final["success_rate"],
        "crash_rate": final["crash_rate"],
        "normalized_accomplish_rate": (
            float(normalized_accomplish_rate(final["accomplish_rate"], expert_rate)) if expert_rate else None),
        "auc": None,
        "eval_episodes": cfg.eval.final_episodes,
        "frames": 0,
        "updates": 0,
        "rounds": 0,
        "wall_s": round(time.perf_counter() - start, 1),
        "run_dir": run_dir,
        "plots": [],
    }
