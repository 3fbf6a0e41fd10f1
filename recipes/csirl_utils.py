"""Builders of recipes/csirl_highway.py, in the style of TorchRL's sota-implementations utils.

Every ``make_*`` function takes the run configuration (an OmegaConf ``DictConfig``, see
``recipes/config/csirl_highway.yaml``) and returns one piece; :func:`make_trainer` assembles them.
"""
from __future__ import annotations

import atexit
import os
import sys
import time
import weakref
from dataclasses import dataclass
from functools import partial
from typing import Any, Callable

import torch
from omegaconf import DictConfig, OmegaConf
from torchrl.collectors import BaseCollector, Collector
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
from torchrl.envs import Compose, EnvBase
from torchrl.objectives import BCLoss, SoftUpdate

from torchrl_csirl.curriculum import SubgoalCurriculum
from torchrl_csirl.data import DemonstrationMixer, ExpertDemonstrations, import_published, load_expert_demonstrations
from torchrl_csirl.envs import SCENARIOS, ScenarioSpec, make_serial_env
from torchrl_csirl.envs import make_env as make_scenario_env
from torchrl_csirl.modules import EgoRelativeFeatures, make_actor, make_qvalue, make_reward_network
from torchrl_csirl.objectives import EnsembleSACLoss, MetaRewardLoss
from torchrl_csirl.trainers import (
    ActorBehaviourCloning,
    CheckpointHook,
    CSIRLTrainer,
    EvaluationHook,
    MetaRewardUpdate,
    MetricsLogger,
    SACUpdate,
    SubgoalSelectionHook,
    evaluate_policy,
    shutdown_collector,
)
from torchrl_csirl.transforms import CombineRewards, IntrinsicReward, SubgoalMatchingReward

CONFIG_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "config")
PRESETS = ("default", "paper")


class ConfigError(ValueError):
    """A bad configuration key or value."""


class ExpertDataError(ValueError):
    """A missing, malformed or mismatched expert file."""


# ---------------------------------------------------------------------------------------- config
def load_config(overrides: list[str] | None = None, config_dir: str = CONFIG_DIR) -> DictConfig:
    """The default configuration, the preset (``preset=paper``) and ``key=value`` overrides.

    Unknown keys and malformed overrides raise :class:`ConfigError` naming them.
    """
    overrides = list(overrides or [])
    for item in overrides:
        if "=" not in item or item.startswith("="):
            raise ConfigError(f"Override {item!r} is not of the form key=value (e.g. env.scenario=merge).")
    cfg = OmegaConf.load(os.path.join(config_dir, "csirl_highway.yaml"))
    cli = OmegaConf.from_dotlist(overrides)
    preset = cli.get("preset", cfg.preset)
    if preset not in PRESETS:
        raise ConfigError(f"preset must be one of {PRESETS}, got {preset!r}.")
    if preset != "default":
        cfg = OmegaConf.merge(cfg, OmegaConf.load(os.path.join(config_dir, f"preset_{preset}.yaml")))
    OmegaConf.set_struct(cfg, True)
    try:
        cfg = OmegaConf.merge(cfg, cli)
    except Exception as err:  # omegaconf raises ConfigKeyError / ValidationError
        raise ConfigError(f"Bad override: {err}".splitlines()[0]) from None
    validate_config(cfg)
    return cfg


def flatten_config(cfg: DictConfig) -> dict[str, Any]:
    """``{"dotted.key": value}`` for every leaf of ``cfg`` (e.g. to turn it back into overrides).

    Examples:
        >>> from omegaconf import OmegaConf
        >>> flatten_config(OmegaConf.create({"env": {"scenario": "merge"}, "seed": 0}))
        {'env.scenario': 'merge', 'seed': 0}
    """
    out: dict[str, Any] = {}

    def visit(node: dict, prefix: str) -> None:
        for key, value in node.items():
            if isinstance(value, dict):
                visit(value, f"{prefix}{key}.")
            else:
                out[f"{prefix}{key}"] = value

    visit(OmegaConf.to_container(cfg), "")
    return out


def format_override(key: str, value: Any) -> str:
    """``key=value`` as the command line writes it (``null``, lower-case booleans).

    Examples:
        >>> format_override("expert.path", None), format_override("csirl.intrinsic", False)
        ('expert.path=null', 'csirl.intrinsic=false')
    """
    text = "null" if value is None else str(value).lower() if isinstance(value, bool) else value
    return f"{key}={text}"


def load_run_config(run_dir: str, overrides: list[str] | None = None) -> DictConfig:
    """The configuration saved in ``run_dir/config.yaml``, updated by ``overrides``.

    ``checkpoint.resume`` of the saved configuration is dropped (the caller decides).
    """
    saved = flatten_config(OmegaConf.load(os.path.join(run_dir, "config.yaml")))
    saved_overrides = [format_override(k, v) for k, v in saved.items() if k != "checkpoint.resume"]
    return load_config(saved_overrides + list(overrides or []))


def validate_config(cfg: DictConfig) -> None:
    """Checks values that would otherwise fail late (after workers started)."""
    if cfg.env.scenario not in SCENARIOS:
        raise ConfigError(f"env.scenario must be one of {sorted(SCENARIOS)}, got {cfg.env.scenario!r}.")
    positive = {
        "collector.frames_per_batch": cfg.collector.frames_per_batch,
        "collector.num_workers": cfg.collector.num_workers,
        "replay_buffer.batch_size": cfg.replay_buffer.batch_size,
        "expert.batch_size": cfg.expert.batch_size,
        "csirl.updates_per_round": cfg.csirl.updates_per_round,
        "csirl.meta_every": cfg.csirl.meta_every,
        "eval.episodes": cfg.eval.episodes,
    }
    for key, value in positive.items():
        if not isinstance(value, int) or value <= 0:
            raise ConfigError(f"{key} must be a positive integer, got {value!r}.")
    if cfg.collector.total_frames is not None and cfg.collector.total_frames <= 0:
        raise ConfigError(f"collector.total_frames must be positive, got {cfg.collector.total_frames}.")
    if cfg.collector.main_threads is not None and (
        not isinstance(cfg.collector.main_threads, int) or cfg.collector.main_threads <= 0
    ):
        raise ConfigError(f"collector.main_threads must be a positive integer or null, got {cfg.collector.main_threads!r}.")
    if cfg.collector.frames_per_batch % cfg.collector.num_workers:
        raise ConfigError(
            f"collector.frames_per_batch ({cfg.collector.frames_per_batch}) must be a multiple of "
            f"collector.num_workers ({cfg.collector.num_workers})."
        )
    k = cfg.collector.envs_per_worker
    if k is not None:
        if not isinstance(k, int) or k <= 0:
            raise ConfigError(f"collector.envs_per_worker must be a positive integer or null, got {k!r}.")
        if cfg.collector.frames_per_batch % (cfg.collector.num_workers * k):
            raise ConfigError(
                f"collector.frames_per_batch ({cfg.collector.frames_per_batch}) must be a multiple of "
                f"collector.num_workers x collector.envs_per_worker ({cfg.collector.num_workers} x {k})."
            )
    if cfg.logger.backend not in ("wandb", "csv", "none"):
        raise ConfigError(f"logger.backend must be wandb, csv or none, got {cfg.logger.backend!r}.")
    if cfg.expert.curriculum not in ("empty", "traffic"):
        raise ConfigError(f"expert.curriculum must be empty or traffic, got {cfg.expert.curriculum!r}.")
    if cfg.csirl.matching_features not in ("ego", "position"):
        raise ConfigError(f"csirl.matching_features must be ego or position, got {cfg.csirl.matching_features!r}.")
    if not 0 <= cfg.replay_buffer.expert_fraction < 1:
        raise ConfigError(f"replay_buffer.expert_fraction must be in [0, 1), got {cfg.replay_buffer.expert_fraction}.")
    if cfg.csirl.actor_bc_coef < 0:
        raise ConfigError(f"csirl.actor_bc_coef must be >= 0, got {cfg.csirl.actor_bc_coef}.")
    if cfg.optim.utd_ratio <= 0:
        raise ConfigError(f"optim.utd_ratio must be positive, got {cfg.optim.utd_ratio}.")


def total_frames(cfg: DictConfig, curriculum_length: int) -> int:
    """``collector.total_frames``, or the paper's budget (a round per curriculum state) when null."""
    if cfg.collector.total_frames is not None:
        return int(cfg.collector.total_frames)
    per_round = cfg.csirl.updates_per_round / cfg.optim.utd_ratio + cfg.replay_buffer.warmup_frames
    return int(per_round * curriculum_length)


def make_run_dir(cfg: DictConfig) -> str:
    """``<logger.output_dir>/<exp_name>`` (created)."""
    name = cfg.logger.exp_name or "-".join(
        [cfg.env.scenario, "csirl" if cfg.csirl.intrinsic else "csirl-b", f"s{cfg.seed}",
         time.strftime("%Y%m%d-%H%M%S")]
    )
    run_dir = os.path.abspath(os.path.join(cfg.logger.output_dir, name))
    os.makedirs(run_dir, exist_ok=True)
    return run_dir


# ---------------------------------------------------------------------------------------- data
def load_experts(cfg: DictConfig, spec: ScenarioSpec) -> ExpertDemonstrations:
    """The demonstrations: the shipped ones, or ``expert.path`` (checked against the scenario)."""
    n = int(cfg.expert.num_trajectories)
    path = cfg.expert.path
    if path is None:
        return load_expert_demonstrations(spec.name, n, curriculum=cfg.expert.curriculum)
    path = os.path.abspath(os.path.expanduser(str(path)))
    if not os.path.isfile(path):
        raise ExpertDataError(f"expert.path: no such file {path!r}.")
    try:
        demos = ExpertDemonstrations.load(path) if path.endswith(".npz") else import_published(path)
    except Exception as err:
        raise ExpertDataError(f"expert.path: {path!r} is not a valid expert file ({type(err).__name__}: {err}).") from None
    if demos.observation_dim != spec.obs_dim or demos.action_dim != spec.action_dim:
        raise ExpertDataError(
            f"expert.path: {path!r} has observations of size {demos.observation_dim} and actions of size "
            f"{demos.action_dim}, but {spec.name!r} has {spec.obs_dim} and {spec.action_dim}."
        )
    if demos.num_trajectories < n:
        raise ExpertDataError(
            f"expert.path: {path!r} holds {demos.num_trajectories} trajectories, "
            f"expert.num_trajectories asks for {n}."
        )
    return demos.subset(n) if n < demos.num_trajectories else demos


# ---------------------------------------------------------------------------------------- envs
MAX_ENVS_PER_WORKER = 4


def envs_per_worker(cfg: DictConfig, spec: ScenarioSpec) -> int:
    """``collector.envs_per_worker``, or for ``null`` the most (up to 4) that keep whole episodes.

    Collection resets every environment at each batch start (exact resume), so each of the
    ``num_workers x k`` environments steps ``frames_per_batch / (num_workers x k)`` times per batch;
    the automatic choice keeps that at least the scenario's episode limit.

    Examples:
        >>> from omegaconf import OmegaConf
        >>> from torchrl_csirl.envs import SCENARIOS
        >>> cfg = OmegaConf.create({"collector": {"envs_per_worker": None, "frames_per_batch": 480, "num_workers": 2}})
        >>> envs_per_worker(cfg, SCENARIOS["merge"]), envs_per_worker(cfg, SCENARIOS["highway-fast"])
        (4, 1)
    """
    if cfg.collector.envs_per_worker is not None:
        return int(cfg.collector.envs_per_worker)
    fpb, workers = int(cfg.collector.frames_per_batch), int(cfg.collector.num_workers)
    fitting = [k for k in range(1, MAX_ENVS_PER_WORKER + 1)
               if fpb % (workers * k) == 0 and fpb // (workers * k) >= spec.max_steps]
    return max(fitting, default=1)


def make_worker_env_fn(cfg: DictConfig) -> Callable[[], EnvBase]:
    """A picklable factory of one collector worker's environments: ``envs_per_worker`` copies of ``env.scenario``.

    Args:
        cfg: the recipe configuration (``env.scenario``, ``collector.*``).

    Returns:
        ``partial(make_serial_env, scenario, envs_per_worker)``: it pickles, as spawned workers need.

    Examples:
        >>> cfg = load_config(["collector.envs_per_worker=2"])
        >>> make_worker_env_fn(cfg)().batch_size
        torch.Size([2])
    """
    return partial(make_serial_env, cfg.env.scenario, envs_per_worker(cfg, SCENARIOS[cfg.env.scenario]))


def make_env(cfg: DictConfig) -> EnvBase:
    """The environments of one collector worker: ``envs_per_worker`` copies of ``env.scenario``."""
    return make_worker_env_fn(cfg)()


def make_eval_env(cfg: DictConfig) -> EnvBase:
    """One evaluation environment (main process, seeded per episode by the evaluator)."""
    return make_scenario_env(cfg.env.scenario)


def make_collector(cfg: DictConfig, policy: Any, frames_done: int = 0) -> BaseCollector:
    """A synchronous collector of ``collector.num_workers`` worker processes (unbounded; the trainer stops it).

    Each worker process holds ``envs_per_worker`` environments *and a copy of the policy*, and
    collects its share of every batch on its own: TorchRL's multi-process synchronous collector
    (``Collector(..., num_collectors=W, sync=True)``). The workers wait while the main process
    updates (every core goes to the updates, ``collector.main_threads``). The reward transforms
    are replay-buffer transforms and stay in the main process. Collection with the policy in the
    main process and only the environments in the workers (a ``ParallelEnv``) scales worse:
    1.37-1.54x from 1 to 2 workers instead of 1.76-1.99x (``benchmarks/bench_collection.py``,
    docs/PERFORMANCE.md).

    The workers act with the weights the main process trains because TorchRL moves the policy's
    parameter storage into shared memory *in place*: optimiser steps and ``load_state_dict``
    (which copy into the existing tensors) reach them with no explicit sync; replacing a
    parameter tensor (``p.data = ...``, ``load_state_dict(assign=True)``, ``.to(device)``) would
    not (tested: ``test_worker_processes_act_with_the_weights_the_main_process_trains``).

    Args:
        cfg: the recipe configuration (``collector.*``, ``env.scenario``).
        policy: the actor; with one worker it runs in this process.
        frames_done: frames collected before (resume): the uniform-random frames
            (``collector.init_random_frames``) already collected are not collected again.

    Returns:
        With ``collector.num_workers=1`` a single-process ``Collector`` (the environments step
        here), otherwise a ``MultiSyncCollector``. Shut it down with
        :func:`~torchrl_csirl.trainers.shutdown_collector`.

    Examples:
        >>> cfg = load_config(["collector.num_workers=1", "collector.frames_per_batch=20", "collector.init_random_frames=0"])
        >>> spec = SCENARIOS[cfg.env.scenario]
        >>> collector = make_collector(cfg, make_actor(spec.obs_dim, spec.action_dim))
        >>> next(iter(collector)).numel()
        20
        >>> shutdown_collector(collector)
    """
    fpb = int(cfg.collector.frames_per_batch)
    random_frames = max(0, int(cfg.collector.init_random_frames) - frames_done)
    random_frames = -(-random_frames // fpb) * fpb
    workers = int(cfg.collector.num_workers)
    main_threads = cfg.collector.main_threads or os.cpu_count() or 1
    common: dict[str, Any] = dict(frames_per_batch=fpb, total_frames=-1, init_random_frames=random_frames or None,
                                  auto_register_policy_transforms=False)
    if workers == 1:
        torch.set_num_threads(main_threads)
        return Collector(make_env(cfg), policy=policy, **common)
    collector = Collector([make_worker_env_fn(cfg)] * workers, policy, num_collectors=workers, sync=True,
                          num_threads=main_threads, num_sub_threads=1, **common)
    # whatever path the process leaves by (see shutdown_collector); a weak reference, so that
    # collectors dropped earlier (tests) are not kept alive
    atexit.register(_shutdown_if_alive, weakref.ref(collector))
    return collector


def _shutdown_if_alive(collector_ref: weakref.ref) -> None:
    collector = collector_ref()
    if collector is not None:
        shutdown_collector(collector)


# ---------------------------------------------------------------------------------------- models
@dataclass
class LossModules:
    actor: Any
    sac: EnsembleSACLoss
    target_updater: SoftUpdate
    reward_network: Any
    meta: MetaRewardLoss | None


def make_loss_modules(cfg: DictConfig, spec: ScenarioSpec) -> LossModules:
    """Actor, ensemble SAC loss, target updater, reward network and meta-loss (None for CSIRL-B).

    With ``model.ego_relative_features`` every network reads the observation through
    :class:`~torchrl_csirl.modules.EgoRelativeFeatures` (a fixed map, no parameters).
    """
    features = EgoRelativeFeatures.from_scenario(spec) if cfg.model.ego_relative_features else None
    actor = make_actor(spec.obs_dim, spec.action_dim, input_features=features)
    sac = EnsembleSACLoss(
        actor,
        make_qvalue(spec.obs_dim, spec.action_dim, input_features=features),
        num_qvalue_nets=int(cfg.csirl.num_qvalue_nets),
        alpha_init=float(cfg.csirl.alpha),
        fixed_alpha=bool(cfg.csirl.fixed_alpha),
        gamma=float(cfg.csirl.gamma),
        dispersion=cfg.csirl.dispersion,
    )
    target_updater = SoftUpdate(sac, tau=float(cfg.optim.tau))
    reward_network = make_reward_network(spec.obs_dim, input_features=features)
    meta = None
    if cfg.csirl.intrinsic:
        meta = MetaRewardLoss(
            sac,
            reward_network,
            lr_inner=float(cfg.csirl.lr_inner),
            scale=float(cfg.csirl.meta_scale),
            reward_l1_coef=float(cfg.csirl.reward_l1_coef),
            joint_sac_update=True,
        )
    return LossModules(actor, sac, target_updater, reward_network, meta)


def make_optimizers(cfg: DictConfig, modules: LossModules) -> dict[str, torch.optim.Optimizer]:
    """Adam for the actor + critics, Adam for the reward network."""
    sac_params = [p for p in modules.sac.parameters() if p.requires_grad]
    return {
        "optim_sac": torch.optim.Adam(sac_params, lr=float(cfg.optim.lr)),
        "optim_reward": torch.optim.Adam(modules.reward_network.parameters(), lr=float(cfg.optim.reward_lr)),
    }


def matching_feature_indices(cfg: DictConfig, spec: ScenarioSpec) -> tuple[int, ...]:
    """Observation entries of the nearest-expert-state search (``csirl.matching_features``).

    ``ego`` (paper and code): the whole ego row, velocities included; ``position``: the ego
    position only, the entries the matching potential measures (docs/ALGORITHM.md).
    """
    return spec.ego_feature_indices if cfg.csirl.matching_features == "ego" else spec.position_feature_indices


def make_matching(cfg: DictConfig, spec: ScenarioSpec, curriculum_obs: torch.Tensor, subgoal: int) -> SubgoalMatchingReward:
    """The matching reward toward the current subgoal of the curriculum trajectory."""
    return SubgoalMatchingReward(
        curriculum_obs,
        subgoal=subgoal,
        ego_feature_indices=matching_feature_indices(cfg, spec),
        position_feature_indices=spec.position_feature_indices,
        scale=spec.matching_scale,
        target=cfg.csirl.matching_target,
    )


def make_replay_buffers(
    cfg: DictConfig, demos: ExpertDemonstrations, matching: SubgoalMatchingReward, modules: LossModules
) -> tuple[TensorDictReplayBuffer, TensorDictReplayBuffer]:
    """The online buffer (rewards recomputed at sampling time) and the expert buffer.

    The online buffer's transform writes ``("next", "matching_reward")`` for the current subgoal
    and, with the intrinsic reward, ``("next", "intrinsic_reward")``; their sum goes to
    ``("next", "reward")`` for the plain SAC steps (the meta step recomputes ``r_w`` with its graph).
    """
    transforms = [matching]
    keys = ["matching_reward"]
    if modules.meta is not None:
        transforms.append(IntrinsicReward(modules.reward_network))
        keys.append("intrinsic_reward")
    transforms.append(CombineRewards(keys))
    online = TensorDictReplayBuffer(
        storage=LazyTensorStorage(int(cfg.replay_buffer.size)),
        batch_size=int(cfg.replay_buffer.batch_size),
        transform=Compose(*transforms),
    )
    expert = demos.as_replay_buffer(batch_size=int(cfg.expert.batch_size))
    return online, expert


def make_sampler(cfg: DictConfig, online: TensorDictReplayBuffer, expert: TensorDictReplayBuffer) -> Callable[[], Any] | None:
    """The SAC batch sampler: online transitions plus ``replay_buffer.expert_fraction`` of expert ones (None: online only)."""
    fraction = float(cfg.replay_buffer.expert_fraction)
    if fraction == 0:
        return None
    return DemonstrationMixer(online, expert, fraction).sample


def make_actor_bc(cfg: DictConfig, modules: LossModules, expert: TensorDictReplayBuffer) -> ActorBehaviourCloning | None:
    """The actor's behavioural-cloning term on ``expert.batch_size`` pairs (``csirl.actor_bc_coef`` > 0), else None."""
    coef = float(cfg.csirl.actor_bc_coef)
    if coef == 0:
        return None
    return ActorBehaviourCloning(BCLoss(modules.actor, loss_function="l2"), expert, coef)


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


# ---------------------------------------------------------------------------------------- assembly
@dataclass
class Run:
    """Everything a training run holds (what the recipe and the tests need)."""

    cfg: DictConfig
    spec: ScenarioSpec
    run_dir: str
    demos: ExpertDemonstrations
    modules: LossModules
    optimizers: dict[str, torch.optim.Optimizer]
    curriculum: SubgoalCurriculum
    matching: SubgoalMatchingReward
    online_buffer: TensorDictReplayBuffer
    expert_buffer: TensorDictReplayBuffer
    collector: BaseCollector
    eval_env: EnvBase
    logger: MetricsLogger
    trainer: CSIRLTrainer
    selection: SubgoalSelectionHook
    evaluation: EvaluationHook
    checkpoint: CheckpointHook

    def evaluate(self, episodes: int) -> dict[str, float]:
        return evaluate_policy(self.eval_env, self.modules.actor, episodes=episodes,
                               max_steps=self.spec.max_steps, seed=int(self.cfg.eval.seed))

    def close(self) -> None:
        shutdown_collector(self.collector)
        self.eval_env.close()


def make_trainer(cfg: DictConfig, run_dir: str, frames_done: int = 0, resume_frames: int | None = None) -> Run:
    """Builds every piece and a :class:`CSIRLTrainer` with the CSIRL hooks registered."""
    torch.manual_seed(int(cfg.seed))
    spec = SCENARIOS[cfg.env.scenario]
    demos = load_experts(cfg, spec)
    curriculum_obs = demos.trajectory_observations(0, include_final=True)
    modules = make_loss_modules(cfg, spec)
    optimizers = make_optimizers(cfg, modules)
    curriculum = SubgoalCurriculum(
        curriculum_obs, modules.sac, modules.actor,
        delta=float(cfg.csirl.delta), sigma=float(cfg.csirl.sigma),
        dispersion=cfg.csirl.dispersion, seed=int(cfg.seed),
    )
    matching = make_matching(cfg, spec, curriculum_obs, curriculum.subgoal)
    online, expert = make_replay_buffers(cfg, demos, matching, modules)
    logger = make_logger(cfg, run_dir, resume_frames)
    eval_env = make_eval_env(cfg)
    # last: the worker processes start here
    collector = make_collector(cfg, modules.actor, frames_done)

    sac_update = SACUpdate(modules.sac, optimizers["optim_sac"], modules.target_updater, cfg.optim.max_grad_norm,
                           sample=make_sampler(cfg, online, expert), actor_bc=make_actor_bc(cfg, modules, expert))
    update = sac_update
    if modules.meta is not None:
        update = MetaRewardUpdate(modules.meta, sac_update, optimizers["optim_reward"], expert,
                                  meta_every=int(cfg.csirl.meta_every))
    trainer = CSIRLTrainer(
        collector=collector,
        online_buffer=online,
        update_step=update,
        total_frames=total_frames(cfg, curriculum.length),
        utd_ratio=float(cfg.optim.utd_ratio),
        updates_per_round=int(cfg.csirl.updates_per_round),
        warmup_frames=int(cfg.replay_buffer.warmup_frames),
        clear_buffer_each_round=bool(cfg.replay_buffer.clear_each_round),
        seed=int(cfg.seed),
        progress_bar=bool(cfg.logger.progress_bar) and sys.stderr.isatty(),
    )
    selection = SubgoalSelectionHook(curriculum, matching)
    run_eval = partial(evaluate_policy, eval_env, modules.actor, episodes=int(cfg.eval.episodes),
                       max_steps=spec.max_steps, seed=int(cfg.eval.seed))
    evaluation = EvaluationHook(run_eval, every_rounds=int(cfg.eval.every_rounds))
    checkpoint = CheckpointHook(os.path.join(run_dir, "checkpoints"),
                                online if cfg.checkpoint.save_buffer else None,
                                every_rounds=int(cfg.checkpoint.every_rounds))
    trainer.register_op("round_end", selection, "subgoal_selection")
    trainer.register_op("round_end", evaluation, "evaluation")
    trainer.register_op("post_round", checkpoint, "checkpoint")
    trainer.register_op("log", lambda t, row: logger.log(row), "metrics_logger")
    trainer.register_state("loss", modules.sac)
    trainer.register_state("reward_network", modules.reward_network)
    for name, optimizer in optimizers.items():
        trainer.register_state(name, optimizer)
    trainer.register_state("subgoal_selection", selection)
    trainer.register_state("evaluation", evaluation)
    return Run(cfg, spec, run_dir, demos, modules, optimizers, curriculum, matching, online, expert,
               collector, eval_env, logger, trainer, selection, evaluation, checkpoint)
