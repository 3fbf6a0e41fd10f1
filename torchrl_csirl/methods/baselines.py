"""The baselines' part of ``recipes/imitation_highway.py``: their configuration schema and builders.

Methods (``method=<name>``):

* ``sac``: SAC on the paper's "true distance reward": :class:`~torchrl_csirl.transforms.ProgressReward`
  toward the scenario's finish, recomputed at sampling time. Uses no demonstrations for training.
  Its learner is the one every SAC-based baseline uses (``sac.*``: the published SAC defaults,
  :class:`~torchrl_csirl.objectives._imitation.SACHyperparameters`, two critics).
* ``bc``: behavioural cloning, TorchRL's :class:`~torchrl.objectives.BCLoss` (``bc.loss_function``)
  on the deterministic action, on expert batches of ``expert.batch_size``. It runs in the same
  loop as every trained method (same frames collected with its own policy, same number of
  updates, same evaluation cadence), so its learning curve sits on the same axis; the collected
  frames are not used by its update.
* ``gail``, ``dac``, ``valuedice``, ``sqil``, ``iqlearn``: built by
  :func:`~torchrl_csirl.trainers.imitation.make_imitation_method`; the ``<method>`` section holds
  the fields of its hyperparameter dataclass (docs/baselines.md gives their sources).
* ``random``, ``expert``: reference rows, no training: uniform random actions, and the expert
  driver (:class:`~torchrl_csirl.tasks.expert_policy.ExpertDriverPolicy`), scored on the same
  test episodes.

The pieces every recipe shares (environments, collector, buffers, logging, evaluation,
checkpoints, device, run directory, summary) are :mod:`common`'s; fairness with CSIRL comes from
the shared defaults: the same demonstrations (``expert.*``), the same frame budget
(``collector.total_frames``), the same networks (``make_actor`` / ``make_qvalue``, 256 x 256),
the same input features (``model.ego_relative_features``) and the same evaluation (``eval.*``).

Examples:
    >>> cfg = load_config(["method=bc", "env.task=roundabout"])
    >>> cfg.method, cfg.env.task, cfg.collector.total_frames
    ('bc', 'roundabout', 60000)
    >>> load_config(["method=gibberish"])  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    torchrl_csirl.run.config.ConfigError: method=gibberish: must be one of sac, bc, ..., random, expert or null
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from functools import partial
from typing import Any, Optional

import torch
from omegaconf import DictConfig, OmegaConf
from torch import nn
from torchrl.data import TensorDictReplayBuffer
from torchrl.envs import Compose
from torchrl.envs.utils import RandomPolicy
from torchrl.objectives import BCLoss

from torchrl_csirl.data import DemonstrationMixer, ExpertDemonstrations
from torchrl_csirl.methods.csirl import CSIRL_RECIPE
from torchrl_csirl.modules import make_actor, make_qvalue, with_standardization
from torchrl_csirl.objectives._imitation import SACHyperparameters, make_sac_learner
from torchrl_csirl.objectives.target_update import FusedSoftUpdate
from torchrl_csirl.run.assembly import Run, assemble_trainer, make_logger, make_online_buffer, model_input_features
from torchrl_csirl.run.collection import check_collector_config, make_eval_env
from torchrl_csirl.run.config import (
    DEVICES,
    CheckpointConfig,
    CollectorConfig,
    CommandLine,
    ConfigError,
    EnvConfig,
    EvalConfig,
    ExpertConfig,
    LearnerReplayBufferConfig,
    LoggerConfig,
    ModelConfig,
    UpdateRatioConfig,
    option,
    parse_command_line,
)
from torchrl_csirl.run.experts import load_experts
from torchrl_csirl.run.final import evaluation_summary, final_summary
from torchrl_csirl.run.recipes import Recipe, register_recipe
from torchrl_csirl.run.run import expert_accomplish_rate, resolve_device
from torchrl_csirl.run.task_schemas import RoboticsSections
from torchrl_csirl.tasks import ScenarioSpec, TaskSpec, resolve_scenario
from torchrl_csirl.trainers import BCUpdate, SACUpdate, evaluate_policy
from torchrl_csirl.trainers.imitation import (
    IMITATION_METHODS,
    ImitationMethod,
    hyperparameters_class,
    make_imitation_method,
)
from torchrl_csirl.transforms import CombineRewards, ProgressReward

__all__ = ["IMITATION_RECIPE", "ImitationHighwayConfig", "ImitationParts", "ImitationRoboticsConfig", "ImitationTaskConfig",
           "METHODS", "REFERENCE_METHODS", "evaluate_reference", "finish", "load_config", "load_run_config", "make_trainer"]

#: the loss-based baselines of :func:`~torchrl_csirl.trainers.imitation.make_imitation_method`
LOSS_METHODS = tuple(IMITATION_METHODS)
#: methods trained by this recipe's loop
TRAINED_METHODS = ("sac", "bc", *LOSS_METHODS)
#: reference rows: evaluated, not trained
REFERENCE_METHODS = ("random", "expert")
METHODS = (*TRAINED_METHODS, *REFERENCE_METHODS)
#: methods of the benchmark trained by recipes/csirl_highway.py (its recipe's)
CSIRL_METHODS = CSIRL_RECIPE.methods


# ---------------------------------------------------------------------------------------- config
@dataclass
class ImitationExpertConfig(ExpertConfig):
    batch_size: int = option(256, above=0, help="expert pairs per bc update (the other methods set their own sizes)")


@dataclass
class SACBaselineConfig(SACHyperparameters):
    """The ``sac`` baseline: the SAC learner of every baseline (published SAC defaults) and its reward's scale."""

    reward_scale: Optional[float] = option(
        None, above=0.0, help="progress reward per unit of normalised distance (null: the scenario's matching scale)")
    expert_fraction: float = option(
        0.0, minimum=0.0, below=1.0,
        help="share of each batch drawn from the demonstrations, rewarded as the online part is (SAC from "
             "demonstrations); 0: SAC")


@dataclass
class BCConfig:
    loss_function: str = option("l2", choices=("l2", "l1"), help="distance of the deterministic action to the expert's")
    lr: float = option(3.0e-4, above=0.0, help="Adam learning rate")
    max_grad_norm: Optional[float] = option(None, above=0.0, help="clip the gradient norm (null: no clipping)")


@dataclass
class _ImitationHighwayBase:
    method: Optional[str] = option(None, choices=METHODS, help="the baseline (required)")
    preset: str = option("default", help="default (no other preset)")
    seed: int = option(0, minimum=0, help="random seed")
    device: str = option("cpu", choices=DEVICES, help="the learner's device (collection stays on the CPU)")
    updates_per_round: int = option(2000, above=0, help="updates between two evaluations (a round)")
    env: EnvConfig = field(default_factory=EnvConfig)
    collector: CollectorConfig = field(default_factory=CollectorConfig)
    expert: ImitationExpertConfig = field(default_factory=ImitationExpertConfig)
    replay_buffer: LearnerReplayBufferConfig = field(default_factory=LearnerReplayBufferConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    optim: UpdateRatioConfig = field(default_factory=UpdateRatioConfig)
    eval: EvalConfig = field(default_factory=EvalConfig)
    logger: LoggerConfig = field(default_factory=LoggerConfig)
    checkpoint: CheckpointConfig = field(default_factory=CheckpointConfig)
    sac: SACBaselineConfig = field(default_factory=SACBaselineConfig)
    bc: BCConfig = field(default_factory=BCConfig)


#: ``recipes/imitation_highway.py``'s schema: the shared sections, ``sac``, ``bc`` and one section per
#: loss-based method, the fields of its hyperparameter dataclass (``hyperparameters_class``)
ImitationHighwayConfig = dataclasses.make_dataclass(
    "ImitationHighwayConfig",
    [(name, hyperparameters_class(name), field(default_factory=hyperparameters_class(name))) for name in LOSS_METHODS],
    bases=(_ImitationHighwayBase,),
)
ImitationHighwayConfig.__doc__ = "``recipes/imitation_highway.py``: one baseline under CSIRL's default budget and evaluation."
ImitationHighwayConfig.__module__ = __name__


@dataclass
class RoboticsImitationExpertConfig(ImitationExpertConfig):
    curriculum: str = option("expert", choices=("expert",),
                             help="the task's shipped file (its trajectory order; the baselines use no curriculum)")


@dataclass
class ImitationTaskConfig(RoboticsSections, ImitationHighwayConfig):
    """``recipes/imitation_highway.py`` on any task but the driving scenes: the driving baselines' schema with the
    task sections (``env``, ``expert``, ``model``, ``collector``)."""

    expert: RoboticsImitationExpertConfig = field(default_factory=RoboticsImitationExpertConfig)


#: the name this schema had when the robotics tasks had a script of their own
ImitationRoboticsConfig = ImitationTaskConfig


def check_method(command: CommandLine | list[str], resuming: bool = False) -> None:
    """One clear line for a missing method (a resumed run keeps its own), or for a CSIRL method."""
    given = parse_command_line(command).values.get("method")
    if given is None:
        if resuming:
            return
        raise ConfigError(f"method: required (method=<name>), one of {', '.join(METHODS)}")
    if given in CSIRL_METHODS:
        raise ConfigError(f"method={given}: CSIRL is trained by recipes/csirl_highway.py (torchrl-csirl train)")


def check_named_method(cfg: DictConfig) -> None:
    """A method is named and the device is usable (the recipe's checks besides the collector's)."""
    if cfg.method is None:
        raise ConfigError(f"method=null: must be one of {', '.join(METHODS)}")
    resolve_device(cfg.device)


# ---------------------------------------------------------------------------------------- data
# ---------------------------------------------------------------------------------------- methods
def sac_hyperparameters(section: DictConfig) -> SACHyperparameters:
    """The SAC learner's settings of the ``sac`` section (its ``reward_scale`` and ``expert_fraction`` aside)."""
    values = OmegaConf.to_container(section)
    values.pop("reward_scale")
    values.pop("expert_fraction")
    return SACHyperparameters(**values)


def true_reward_transforms(cfg: DictConfig, spec: TaskSpec, device: torch.device) -> list:
    """The ``sac`` baseline's reward: on a driving scenario the progress toward the finish (the
    paper's "true distance reward", written over highway-env's own reward); on a robotics task the
    environment's own reward, the task's (no transform)."""
    if not isinstance(spec, ScenarioSpec):
        if cfg.sac.reward_scale is not None:
            raise ConfigError(f"sac.reward_scale={cfg.sac.reward_scale}: {spec.name} trains SAC on the "
                              "environment's own reward, which has no scale to set (null)")
        return []
    reward = ProgressReward.from_scenario(spec, scale=cfg.sac.reward_scale).to(device)
    return [reward, CombineRewards(["progress_reward"])]


def make_sac(cfg: DictConfig, spec: TaskSpec, device: torch.device, features: nn.Module | None) -> ImitationMethod:
    """SAC on the task's true reward (:func:`true_reward_transforms`; the paper's "SAC (true distance reward)");
    with ``sac.expert_fraction`` > 0 a share of each batch is expert transitions, rewarded by the same reward
    (on a robotics task the demonstrations' recorded environment reward)."""
    hp = sac_hyperparameters(cfg.sac)
    actor = make_actor(spec.obs_dim, spec.action_dim, input_features=features)
    loss = make_sac_learner(actor, make_qvalue(spec.obs_dim, spec.action_dim, input_features=features), hp).to(device)
    optimizer = torch.optim.Adam([p for p in loss.parameters() if p.requires_grad], lr=hp.lr)
    target_updater = FusedSoftUpdate(loss, tau=hp.tau)

    def make_update_step(online, expert) -> SACUpdate:
        sample = None
        if cfg.sac.expert_fraction > 0:
            check_recorded_reward(expert, spec, cfg.sac.expert_fraction)
            sample = DemonstrationMixer(online, expert, cfg.sac.expert_fraction, batch_size=hp.batch_size).sample
        return SACUpdate(loss, optimizer, target_updater, hp.max_grad_norm, sample=sample)

    return ImitationMethod("sac", actor, true_reward_transforms(cfg, spec, device), [],
                           {"loss": loss, "optim_sac": optimizer}, make_update_step, hp)


def check_recorded_reward(expert: TensorDictReplayBuffer, spec: TaskSpec, fraction: float) -> None:
    """On a task trained on the environment's own reward, the demonstrations must carry it (``("next", "reward")``)."""
    if isinstance(spec, ScenarioSpec):  # the progress reward is computed for the expert part too
        return
    if ("next", "reward") not in expert.storage[:1].keys(True):
        raise ConfigError(f"sac.expert_fraction={fraction}: the demonstrations of {spec.name} hold no reward "
                          "(\"next\", \"reward\"); record them with their environment reward, or set 0")


def make_bc(cfg: DictConfig, spec: TaskSpec, device: torch.device, features: nn.Module | None) -> ImitationMethod:
    """Behavioural cloning (TorchRL's ``BCLoss``) on expert batches of ``expert.batch_size``."""
    actor = make_actor(spec.obs_dim, spec.action_dim, input_features=features).to(device)
    loss = BCLoss(actor, loss_function=cfg.bc.loss_function)
    optimizer = torch.optim.Adam(actor.parameters(), lr=cfg.bc.lr)

    def make_update_step(online, expert) -> BCUpdate:
        return BCUpdate(loss, optimizer, expert, cfg.bc.max_grad_norm)

    return ImitationMethod("bc", actor, [], [], {"actor": actor, "optim_bc": optimizer}, make_update_step)


def make_loss_method(cfg: DictConfig, spec: TaskSpec, device: torch.device, features: nn.Module | None) -> ImitationMethod:
    """A loss-based baseline (:func:`~torchrl_csirl.trainers.imitation.make_imitation_method`) with
    the ``<method>`` section as its hyperparameters and CSIRL's actor and critic factory."""
    actor = make_actor(spec.obs_dim, spec.action_dim, input_features=features)
    return make_imitation_method(
        cfg.method, actor, partial(make_qvalue, spec.obs_dim, spec.action_dim, input_features=features),
        obs_dim=spec.obs_dim, action_dim=spec.action_dim, hyperparameters=OmegaConf.to_object(cfg[cfg.method]),
        device=device)


METHOD_BUILDERS = {"sac": make_sac, "bc": make_bc, **{name: make_loss_method for name in LOSS_METHODS}}


def method_input_features(cfg: DictConfig, spec: TaskSpec, demos: ExpertDemonstrations) -> nn.Module | None:
    """The input map of the method's networks: the ``model`` section's
    (:func:`~torchrl_csirl.run.assembly.model_input_features`), after a standardisation fitted to the
    demonstrations' observations where the method's section asks for it (``valuedice.normalize_states``)."""
    features = model_input_features(cfg.model, spec)
    section = cfg.get(cfg.method)
    if section is None or not section.get("normalize_states"):
        return features
    try:
        return with_standardization(features, demos.transitions().get("observation"))
    except ValueError as err:
        raise ConfigError(f"{cfg.method}.normalize_states=true: {err} (model.ego_relative_features=false "
                          "model.lane_features=false)") from None


def make_trainer(cfg: DictConfig, run_dir: str, frames_done: int = 0, resume_frames: int | None = None) -> Run[ImitationParts]:
    """Builds the method and the trainer with the shared hooks (the method and its demonstrations: ``run.parts``,
    :class:`ImitationParts`).

    The online buffer samples the method's ``batch_size`` (``expert.batch_size`` for ``bc``); the
    expert buffer holds every demonstrated transition, with the method's expert transforms.
    """
    torch.manual_seed(cfg.seed)
    device = resolve_device(cfg.device)
    spec = resolve_scenario(cfg.env.task)  # a driving scenario or a robotics task
    demos = load_experts(cfg.expert, spec)
    try:  # e.g. a negative learning rate of a section read from a hyperparameter dataclass
        method = METHOD_BUILDERS[cfg.method](cfg, spec, device, method_input_features(cfg, spec, demos))
    except ConfigError:
        raise
    except (ValueError, TypeError) as err:
        raise ConfigError(f"{cfg.method}.*: {err}") from None
    batch_size = getattr(method.hyperparameters, "batch_size", cfg.expert.batch_size)
    online = make_online_buffer(cfg.replay_buffer.size, batch_size, method.online_transforms, device)
    expert = demos.as_replay_buffer(batch_size=cfg.expert.batch_size, device=device,
                                    transform=Compose(*method.expert_transforms) if method.expert_transforms else None)
    return assemble_trainer(
        cfg, spec, run_dir, device=device, demos=demos, policy=method.policy, online_buffer=online,
        update_step=method.make_update_step(online, expert), total_frames=cfg.collector.total_frames,
        updates_per_round=cfg.updates_per_round, states=method.states, frames_done=frames_done,
        resume_frames=resume_frames, parts=ImitationParts(method, expert), behaviour=method.behaviour,
    )


@dataclass
class ImitationParts:
    """A baseline's own pieces of a :class:`~torchrl_csirl.run.assembly.Run` (``run.parts``)."""

    method: ImitationMethod  #: the method's losses, policy, update step and transforms
    expert_buffer: TensorDictReplayBuffer  #: the demonstrations' transitions (with the method's expert transforms)


# ---------------------------------------------------------------------------------------- reference rows
def reference_policy(method: str, env: Any, spec: ScenarioSpec) -> Any:
    """Uniform random actions (``random``) or the expert driver on ``env`` (``expert``)."""
    if method == "random":
        return RandomPolicy(env.full_action_spec[env.action_key])
    from torchrl_csirl.tasks.expert_policy import ExpertDriverPolicy

    return ExpertDriverPolicy(env, spec.name)


def evaluate_reference(cfg: DictConfig, run_dir: str) -> dict[str, Any]:
    """A reference row: its policy on the ``eval.final_episodes`` test episodes, logged; the summary."""
    torch.manual_seed(cfg.seed)
    spec = resolve_scenario(cfg.env.task)
    demos = load_experts(cfg.expert, spec)
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
    return {**evaluation_summary(cfg, spec, cfg.method, final, expert_accomplish_rate(demos.metadata)), "device": "cpu",
            "auc": None, "frames": 0, "updates": 0, "rounds": 0, "wall_s": round(time.perf_counter() - start, 1),
            "run_dir": run_dir, "plots": []}


# ---------------------------------------------------------------------------------------- the recipe
def finish(run: Run[ImitationParts]) -> dict[str, object]:
    """The final evaluation, policy, curve and summary of a trained method."""
    return final_summary(run, run.cfg.method, title=f"{run.cfg.method} on {run.spec.name}")


def reference_evaluation(cfg: DictConfig):
    """:func:`evaluate_reference` for a reference row (``random``, ``expert``), None for a trained method."""
    return evaluate_reference if cfg.method in REFERENCE_METHODS else None


#: ``recipes/imitation_highway.py``: one baseline (``method=<name>``) on any task
IMITATION_RECIPE = register_recipe(Recipe(
    name="imitation", script="torchrl_csirl.scripts.imitation_highway", methods=METHODS,
    schema=ImitationHighwayConfig, task_schema=ImitationTaskConfig,
    checks=(check_collector_config, check_named_method), command_check=check_method,
    method_overrides=lambda method: [f"method={method}"], trainer=make_trainer, finish=finish,
    untrained=reference_evaluation))
load_config = IMITATION_RECIPE.load_config
load_run_config = IMITATION_RECIPE.load_run_config
