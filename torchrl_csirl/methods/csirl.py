"""CSIRL's part of the run layer (``recipes/csirl_highway.py``, any task): its recipe (:data:`CSIRL_RECIPE`:
schemas, presets, checks, trainer, finish) and its builders.

The pieces every script shares (environments, collector, buffers, logging, evaluation,
checkpoints, device, run directory, summary) live in :mod:`torchrl_csirl.run.builders`' modules; this module
adds the ``csirl`` section of the configuration and builds the ensemble-SAC learner, the reward network,
the meta-gradient loss, the subgoal curriculum and the matching reward, then hands them to
:func:`~torchrl_csirl.run.assembly.assemble_trainer`. A driving scene is configured by
:class:`CSIRLHighwayConfig`, any other task by :class:`CSIRLTaskConfig` (its family decides).

Examples:
    >>> cfg = load_config(["env.task=roundabout", "csirl.intrinsic=false"])
    >>> cfg.env.task, method_name(cfg)
    ('roundabout', 'csirl-b')
    >>> cfg = load_config(["env.task=hopper"])
    >>> cfg.env.task, cfg.model.ego_relative_features, cfg.collector.frames_per_batch
    ('hopper', False, 1400)
"""
from __future__ import annotations

import os
import sys
from dataclasses import dataclass, field
from typing import Any, Callable

import torch
from omegaconf import DictConfig
from torchrl.data import TensorDictReplayBuffer
from torchrl.objectives import BCLoss

from torchrl_csirl.curriculum import SubgoalCurriculum
from torchrl_csirl.data import DemonstrationMixer, ExpertDemonstrations
from torchrl_csirl.hyperparameters import CSIRLHyperparameters
from torchrl_csirl.modules import LearnerPrecision, PrecisionUnsupported, expert_reference_states
from torchrl_csirl.objectives import ActorBehaviourCloning, CSIRLLearner, make_csirl_learner, pretrain_actor
from torchrl_csirl.run.assembly import Run, assemble_trainer, make_online_buffer, model_input_features
from torchrl_csirl.run.collection import check_collector_config
from torchrl_csirl.run.config import (
    DEVICES,
    CheckpointConfig,
    CollectorConfig,
    ConfigError,
    EnvConfig,
    EvalConfig,
    ExpertConfig,
    LoggerConfig,
    ModelConfig,
    OptimConfig,
    ReplayBufferConfig,
    option,
)
from torchrl_csirl.run.experts import load_experts
from torchrl_csirl.run.final import final_summary
from torchrl_csirl.run.recipes import Recipe, register_recipe
from torchrl_csirl.run.run import ExpertDataError, resolve_device
from torchrl_csirl.run.task_schemas import RoboticsExpertConfig, RoboticsSections
from torchrl_csirl.tasks import FAILURE_KEYS, SCENARIOS, ScenarioSpec, resolve_scenario  # noqa: F401 - SCENARIOS: used by tests
from torchrl_csirl.trainers import MetaRewardUpdate, SACUpdate, SubgoalSelectionHook
from torchrl_csirl.transforms import CombineRewards, GoalConditionedMatchingReward, IntrinsicReward, SubgoalMatchingReward

__all__ = ["CSIRL_RECIPE", "ConfigError", "CSIRLConfig", "CSIRLHighwayConfig", "CSIRLParts", "CSIRLRoboticsConfig", "CSIRLTaskConfig",
           "ExpertDataError", "finish", "load_config", "load_run_config", "make_trainer"]

#: the preset config group (``preset/<name>.yaml``, ``scene/<scenario>.yaml``), shipped in the package
CONFIG_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "config", "csirl_highway")
#: the other tasks' own defaults (``scene/<task>.yaml``), over :class:`CSIRLTaskConfig`'s
TASK_CONFIG_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "config", "csirl_task")


# ---------------------------------------------------------------------------------------- config
@dataclass
class CSIRLConfig(CSIRLHyperparameters):
    """The ``csirl`` section: CSIRL's hyperparameters (:class:`~torchrl_csirl.hyperparameters.CSIRLHyperparameters`,
    declared once there), as the baselines' ``sac`` section is their learner's dataclass."""


@dataclass
class CSIRLHighwayConfig:
    """``recipes/csirl_highway.py``: the default preset ("our cheaper procedure", docs/recipes.md)."""

    preset: str = option("default", help="default | paper (config group torchrl_csirl/methods/config/csirl_highway/preset)")
    seed: int = option(0, minimum=0, help="random seed")
    device: str = option("cpu", choices=DEVICES, help="the learner's device (collection stays on the CPU)")
    env: EnvConfig = field(default_factory=EnvConfig)
    collector: CollectorConfig = field(default_factory=CollectorConfig)
    expert: ExpertConfig = field(default_factory=ExpertConfig)
    replay_buffer: ReplayBufferConfig = field(default_factory=ReplayBufferConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    optim: OptimConfig = field(default_factory=OptimConfig)
    csirl: CSIRLConfig = field(default_factory=CSIRLConfig)
    eval: EvalConfig = field(default_factory=EvalConfig)
    logger: LoggerConfig = field(default_factory=LoggerConfig)
    checkpoint: CheckpointConfig = field(default_factory=CheckpointConfig)


@dataclass
class CSIRLTaskConfig(RoboticsSections, CSIRLHighwayConfig):
    """``recipes/csirl_highway.py`` on any task but the driving scenes (robotics, locomotion, ``env.gym_id``, yours):
    the driving defaults with the task sections (``env``, ``expert``, ``model``, ``collector``)."""

    preset: str = option("default", help="default | paper (config group torchrl_csirl/methods/config/csirl_task/preset)")
    expert: RoboticsExpertConfig = field(default_factory=RoboticsExpertConfig)


#: the name this schema had when the robotics tasks had a script of their own
CSIRLRoboticsConfig = CSIRLTaskConfig


def learner_precision(cfg: DictConfig) -> LearnerPrecision:
    """``optim.precision`` on ``device`` (:class:`~torchrl_csirl.modules.LearnerPrecision`).

    Raises:
        ConfigError: one line, for ``bf16`` on a device without native bfloat16 matmuls.
    """
    device = resolve_device(cfg.device)
    try:
        return LearnerPrecision.from_setting(cfg.optim.precision, device)
    except PrecisionUnsupported as err:
        raise ConfigError(str(err)) from None


def method_name(cfg: DictConfig) -> str:
    """``csirl``, or ``csirl-b`` without the learned reward."""
    return "csirl" if cfg.csirl.intrinsic else "csirl-b"


def total_frames(cfg: DictConfig, curriculum_length: int) -> int:
    """``collector.total_frames``, or the paper's budget (a round per curriculum state) when null."""
    if cfg.collector.total_frames is not None:
        return cfg.collector.total_frames
    per_round = cfg.csirl.updates_per_round / cfg.optim.utd_ratio + cfg.replay_buffer.warmup_frames
    return int(per_round * curriculum_length)


# ---------------------------------------------------------------------------------------- models
def make_loss_modules(cfg: DictConfig, spec: ScenarioSpec, device: torch.device | str = "cpu",
                      demos: ExpertDemonstrations | None = None) -> CSIRLLearner:
    """Actor, ensemble SAC loss, target updater, reward network and meta-loss (None for CSIRL-B), on ``device``:
    :func:`~torchrl_csirl.objectives.make_csirl_learner` with the ``csirl`` and ``optim`` sections.

    With ``model.ego_relative_features`` every network reads the observation through
    :class:`~torchrl_csirl.modules.EgoRelativeFeatures` (a fixed map, no parameters), with
    ``model.lane_features`` (also) through :class:`~torchrl_csirl.modules.LaneFeatures`. With
    ``csirl.reward_reference=expert`` the reward network is wrapped in
    :class:`~torchrl_csirl.modules.ExpertCenteredReward` over 256 states of ``demos``.
    """
    reference = None
    if cfg.csirl.reward_reference == "expert":
        if demos is None:
            raise ValueError("csirl.reward_reference=expert needs the demonstrations (demos=).")
        reference = expert_reference_states(demos.transitions()["observation"], seed=cfg.seed)
    c = cfg.csirl
    return make_csirl_learner(
        spec.obs_dim, spec.action_dim, input_features=model_input_features(cfg.model, spec),
        num_qvalue_nets=c.num_qvalue_nets, alpha_init=c.alpha, fixed_alpha=c.fixed_alpha, gamma=c.gamma,
        dispersion=c.dispersion, tau=cfg.optim.tau, intrinsic=c.intrinsic, reward_activation=c.reward_activation,
        reward_reference=reference, reward_scale=c.reward_scale, lr_inner=c.lr_inner, meta_scale=c.meta_scale,
        reward_l1_coef=c.reward_l1_coef, gradient_balance=c.gradient_balance, meta_gradient=c.meta_gradient,
        device=device)


def make_optimizers(cfg: DictConfig, modules: CSIRLLearner) -> dict[str, torch.optim.Optimizer]:
    """Adam for the actor + critics, Adam for the reward network (``optim.lr``, ``optim.reward_lr``)."""
    return modules.optimizers(lr=cfg.optim.lr, reward_lr=cfg.optim.reward_lr)


def matching_feature_indices(cfg: DictConfig, spec: ScenarioSpec) -> tuple[int, ...]:
    """Observation entries of the nearest-expert-state search (``csirl.matching_features``).

    ``ego`` (paper and code): the whole ego row, velocities included; ``position``: the ego
    position only, the entries the matching potential measures (docs/algorithm.md).
    """
    return spec.ego_feature_indices if cfg.csirl.matching_features == "ego" else spec.position_feature_indices


def make_matching(cfg: DictConfig, spec: ScenarioSpec, curriculum_obs: torch.Tensor, subgoal: Any,
                  demos: ExpertDemonstrations | None = None) -> SubgoalMatchingReward:
    """The matching reward toward ``subgoal`` (an index, or the curriculum that owns it) of the curriculum trajectory;
    on a goal-conditioned task (:func:`goal_features`) each transition against the demonstration of its goal."""
    kwargs = dict(
        subgoal=subgoal,
        ego_feature_indices=matching_feature_indices(cfg, spec),
        position_feature_indices=spec.position_feature_indices,
        scale=spec.matching_scale if cfg.csirl.matching_scale is None else cfg.csirl.matching_scale,
        target=cfg.csirl.matching_target,
        failure_keys=FAILURE_KEYS if cfg.csirl.failure_resets_progress else (),
    )
    goal = goal_features(cfg.csirl, spec)
    if goal is None or demos is None:
        return SubgoalMatchingReward(curriculum_obs, **kwargs)
    demonstrations = [curriculum_obs, *(demos.trajectory_observations(k, include_final=True).to(curriculum_obs.device)
                                        for k in range(1, demos.num_trajectories))]
    return GoalConditionedMatchingReward(demonstrations, goal_feature_indices=goal, **kwargs)


def goal_features(csirl: DictConfig, spec: ScenarioSpec) -> tuple[int, ...] | None:
    """The observation entries of the episode's goal when the matching reward is goal-conditioned
    (``csirl.goal_conditioned``; null: where the task's observation has a ``desired_goal``), else None.

    Raises:
        ConfigError: ``csirl.goal_conditioned=true`` on a task without a ``desired_goal`` entry.
    """
    layout = getattr(spec, "observation_layout", None) or {}
    if csirl.goal_conditioned is False or (csirl.goal_conditioned is None and "desired_goal" not in layout):
        return None
    if "desired_goal" not in layout:
        raise ConfigError(f"csirl.goal_conditioned=true: {spec.name}'s observation has no desired_goal entry "
                          "(a goal-conditioned task's Dict observation has one)")
    start, stop = layout["desired_goal"]
    return tuple(range(start, stop))


def make_reward_transforms(cfg: DictConfig, matching: SubgoalMatchingReward, modules: CSIRLLearner) -> list:
    """Matching reward, ``r_w`` (unless CSIRL-B) and their sum into ``("next", "reward")``, at sampling time."""
    transforms, keys = [matching], ["matching_reward"]
    if modules.meta is not None:
        transforms.append(IntrinsicReward(modules.reward_network))
        keys.append("intrinsic_reward")
    transforms.append(CombineRewards(keys))
    return transforms


def make_sampler(cfg: DictConfig, online: TensorDictReplayBuffer, expert: TensorDictReplayBuffer) -> Callable[[], Any] | None:
    """The SAC batch sampler: online transitions plus ``replay_buffer.expert_fraction`` of expert ones (None: online only)."""
    if cfg.replay_buffer.expert_fraction == 0:
        return None
    return DemonstrationMixer(online, expert, cfg.replay_buffer.expert_fraction).sample


def make_actor_bc(cfg: DictConfig, modules: CSIRLLearner, expert: TensorDictReplayBuffer) -> ActorBehaviourCloning | None:
    """The actor's behavioural-cloning term on ``expert.batch_size`` pairs (``csirl.actor_bc_coef`` > 0, weighted as
    ``csirl.actor_bc_scale``), else None."""
    if cfg.csirl.actor_bc_coef == 0:
        return None
    critic = modules.sac if cfg.csirl.actor_bc_scale == "qvalue" else None
    return ActorBehaviourCloning(BCLoss(modules.actor, loss_function="l2"), expert, cfg.csirl.actor_bc_coef,
                                 critic=critic)


def make_update_step(cfg: DictConfig, modules: CSIRLLearner, optimizers: dict, online: TensorDictReplayBuffer,
                     expert: TensorDictReplayBuffer) -> SACUpdate | MetaRewardUpdate:
    """CSIRL's update: a joint SAC + meta-gradient step every ``csirl.meta_every`` updates; CSIRL-B's: SAC."""
    sac_update = SACUpdate(modules.sac, optimizers["optim_sac"], modules.target_updater, cfg.optim.max_grad_norm,
                           sample=make_sampler(cfg, online, expert), actor_bc=make_actor_bc(cfg, modules, expert),
                           precision=learner_precision(cfg), critic_warmup_updates=cfg.csirl.critic_warmup_updates)
    if modules.meta is None:
        return sac_update
    return MetaRewardUpdate(modules.meta, sac_update, optimizers["optim_reward"], expert,
                            meta_every=cfg.csirl.meta_every)


def warm_start_actor(cfg: DictConfig, modules: CSIRLLearner, expert: TensorDictReplayBuffer) -> None:
    """``csirl.actor_pretrain_updates`` behavioural-cloning updates of the actor before training (none by default)."""
    updates = cfg.csirl.actor_pretrain_updates
    if updates:
        print(f"actor warm start: {updates} behavioural-cloning updates before the first round", file=sys.stderr)
        error = pretrain_actor(modules.actor, expert, updates, lr=cfg.optim.lr,
                               batch_size=cfg.csirl.actor_pretrain_batch_size, progress_bar=cfg.logger.progress_bar)
        print(f"actor warm-started: {updates} behavioural-cloning updates, last batch's error {error:.4f}",
              file=sys.stderr)


def evaluate_warm_start(run: Run[CSIRLParts]) -> dict[str, float]:
    """The warm-started actor's validation episodes before any reinforcement update: the learning curve's first
    point (frame 0, ``eval_*`` in the metrics), so that a run shows whether its updates keep what the cloning gave.
    Not counted in the summary's ``auc`` (the evaluations during training)."""
    metrics = run.evaluation.run(run.trainer)
    run.trainer.log_now()
    shown = ", ".join(f"{k} {metrics[k]:.3g}" for k in ("success_rate", "accomplish_rate", "env_return") if k in metrics)
    print(f"actor warm start, before any update: {shown} ({run.cfg.eval.episodes} validation episodes)",
          file=sys.stderr)
    return metrics


def first_subgoal(cfg: DictConfig, length: int) -> int | None:
    """The curriculum's first subgoal: the last state with ``fixed_subgoal`` (it can never move
    on from there), else None (drawn in ``[1, 5]`` as in the paper)."""
    return length - 1 if cfg.fixed_subgoal else None


# ---------------------------------------------------------------------------------------- assembly
def make_trainer(cfg: DictConfig, run_dir: str, frames_done: int = 0, resume_frames: int | None = None) -> Run[CSIRLParts]:
    """Builds every piece and the trainer with the CSIRL hooks registered (CSIRL's own pieces: ``run.parts``,
    :class:`CSIRLParts`)."""
    torch.manual_seed(cfg.seed)
    device = resolve_device(cfg.device)
    spec = resolve_scenario(cfg.env.task)  # a driving scenario or a robotics task
    demos = load_experts(cfg.expert, spec)
    curriculum_obs = demos.trajectory_observations(0, include_final=True).to(device)
    modules = make_loss_modules(cfg, spec, device, demos)
    optimizers = make_optimizers(cfg, modules)
    curriculum = SubgoalCurriculum(curriculum_obs, modules.sac, modules.actor, delta=cfg.csirl.delta,
                                   sigma=cfg.csirl.sigma, dispersion=cfg.csirl.dispersion, seed=cfg.seed,
                                   initial_subgoal=first_subgoal(cfg.csirl, curriculum_obs.shape[0]))
    matching = make_matching(cfg, spec, curriculum_obs, curriculum, demos)
    online = make_online_buffer(cfg.replay_buffer.size, cfg.replay_buffer.batch_size,
                                make_reward_transforms(cfg, matching, modules), device)
    expert = demos.as_replay_buffer(batch_size=cfg.expert.batch_size, device=device)
    if not frames_done:  # a resumed run's actor comes from its checkpoint
        warm_start_actor(cfg, modules, expert)
    selection = SubgoalSelectionHook(curriculum)
    states: dict[str, Any] = {"loss": modules.sac, "reward_network": modules.reward_network, **optimizers,
                              "subgoal_selection": selection}
    run = assemble_trainer(
        cfg, spec, run_dir, device=device, demos=demos, policy=modules.actor, online_buffer=online,
        update_step=make_update_step(cfg, modules, optimizers, online, expert),
        total_frames=total_frames(cfg, curriculum.length), updates_per_round=cfg.csirl.updates_per_round,
        states=states, round_hooks=[("subgoal_selection", selection)], frames_done=frames_done,
        resume_frames=resume_frames,
        parts=CSIRLParts(modules, optimizers, curriculum, matching, expert, selection),
    )
    if cfg.csirl.actor_pretrain_updates and not frames_done:
        evaluate_warm_start(run)
    return run


@dataclass
class CSIRLParts:
    """CSIRL's own pieces of a :class:`~torchrl_csirl.run.assembly.Run` (``run.parts``)."""

    modules: CSIRLLearner  #: actor, ensemble SAC loss, reward network, meta-loss
    optimizers: dict[str, torch.optim.Optimizer]  #: ``optim_sac``, ``optim_reward``
    curriculum: SubgoalCurriculum  #: the subgoal curriculum
    matching: SubgoalMatchingReward  #: the matching reward toward the current subgoal
    expert_buffer: TensorDictReplayBuffer  #: the demonstrations' transitions
    selection: SubgoalSelectionHook  #: the round-end subgoal selection and its history


# ---------------------------------------------------------------------------------------- finish
def curriculum_plots(run: Run[CSIRLParts]) -> list[str]:
    """The subgoal curriculum with its uncertainty profiles, and the task with the selected subgoals: the driving
    scene (:func:`~torchrl_csirl.analysis.visualization.render_curriculum`) or any other task's picture
    (:func:`~torchrl_csirl.analysis.visualization.plot_robotics_curriculum`: the maze from above, or the matching features)."""
    from torchrl_csirl.analysis.visualization import plot_robotics_curriculum, plot_subgoal_curriculum, render_curriculum

    curriculum, history = run.parts.curriculum, run.parts.selection.history
    picture = render_curriculum if run.spec.family == "driving" else plot_robotics_curriculum
    paths = [
        plot_subgoal_curriculum(history, os.path.join(run.run_dir, "subgoals.png"),
                                curriculum_length=curriculum.length, delta=curriculum.delta),
        picture(run.spec, curriculum.expert_observations.cpu(),
                sorted({h["subgoal"] for h in history} | {curriculum.subgoal}),
                os.path.join(run.run_dir, "curriculum.png")),
    ]
    return [os.fspath(p) for p in paths]


def finish(run: Run[CSIRLParts]) -> dict[str, object]:
    """Final evaluation, checkpoint, policy, plots and the summary."""
    summary = final_summary(run, method_name(run.cfg), title=f"CSIRL on {run.spec.name}")
    summary.update(final_subgoal=run.parts.curriculum.subgoal, curriculum_length=run.parts.curriculum.length,
                   precision=learner_precision(run.cfg).name)  # what optim.precision=auto resolved to
    summary["plots"] += curriculum_plots(run)
    if run.cfg.eval.health_episodes:
        summary.update(write_health(run, run.cfg.eval.health_episodes, test=summary))
        summary["plots"].append(summary["health_picture"])
    return summary


def write_health(run: Run[CSIRLParts], episodes: int, metrics_dir: str | None = None,
                 out_dir: str | None = None, test: dict[str, object] | None = None) -> dict[str, object]:
    """The run's health report (:mod:`torchrl_csirl.analysis.diagnostics`) in ``health.json`` / ``health.png`` of
    ``out_dir`` (default: the run's directory), one line naming the flagged checks; the summary's fields.
    ``test``: the final test's summary, where the run has one (the task's last word in the report)."""
    from torchrl_csirl.analysis.diagnostics import health_report, write_health_report

    report = health_report(run, method_name(run.cfg), episodes=episodes, metrics_dir=metrics_dir, test=test)
    paths = write_health_report(report, out_dir)
    if report.flagged:
        print(f"health: {len(report.flagged)} of {len(report.checks)} checks flagged "
              f"({', '.join(c.name for c in report.flagged)}): {paths['health']}", file=sys.stderr)
    return {**paths, "health_flagged": [c.name for c in report.flagged]}


def check_precision(cfg: DictConfig) -> None:
    """``optim.precision`` usable on ``device`` (:func:`learner_precision`)."""
    learner_precision(cfg)


#: ``recipes/csirl_highway.py``: CSIRL and CSIRL-B on any task
CSIRL_RECIPE = register_recipe(Recipe(
    name="csirl", script="torchrl_csirl.scripts.csirl_highway", methods=("csirl", "csirl-b"),
    schema=CSIRLHighwayConfig, task_schema=CSIRLTaskConfig, config_dir=CONFIG_DIR,
    task_config_dir=TASK_CONFIG_DIR,
    checks=(check_collector_config, check_precision),
    method_overrides=lambda method: ["csirl.intrinsic=false"] if method == "csirl-b" else [],
    trainer=make_trainer, finish=finish, method_of=lambda cfg: method_name(cfg)))
load_config = CSIRL_RECIPE.load_config
load_run_config = CSIRL_RECIPE.load_run_config
