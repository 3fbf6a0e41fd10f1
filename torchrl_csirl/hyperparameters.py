"""CSIRL's hyperparameters, each declared once: its default, the values it accepts, what it does.

* :class:`CSIRLHyperparameters` (:data:`CSIRL_DEFAULTS`): the method's own settings, the ``csirl``
  section of the recipes' configuration (:class:`torchrl_csirl.methods.csirl.CSIRLConfig` is this
  dataclass, as the baselines' ``sac`` section is :class:`~torchrl_csirl.objectives.SACHyperparameters`).
* :class:`CSIRLOptimHyperparameters` (:data:`CSIRL_OPTIM_DEFAULTS`): how it is optimised, the ``optim``
  section (:class:`torchrl_csirl.run.config.OptimConfig`).

The building blocks read their keyword defaults from here: :func:`~torchrl_csirl.objectives.make_csirl_learner`,
:class:`~torchrl_csirl.objectives.EnsembleSACLoss`, :class:`~torchrl_csirl.objectives.MetaRewardLoss`
(whose ``scale`` is ``meta_scale``), :class:`~torchrl_csirl.trainers.MetaRewardUpdate`,
:class:`~torchrl_csirl.curriculum.SubgoalCurriculum`, so a learner built in Python and one built
from a configuration start from the same values (``tests/test_one_default.py`` checks it). Where the
paper's procedure differs, ``preset=paper`` sets it (docs/recipes.md).

This module imports nothing heavy (no torch), so that the configuration can be read without it.

Examples:
    >>> CSIRL_DEFAULTS.num_qvalue_nets, CSIRL_DEFAULTS.fixed_alpha, CSIRL_DEFAULTS.meta_every
    (5, False, 2)
    >>> CSIRL_DEFAULTS.alpha_init == CSIRL_DEFAULTS.alpha, CSIRL_OPTIM_DEFAULTS.tau
    (True, 0.005)
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

from torchrl_csirl._options import option

__all__ = [
    "CSIRL_DEFAULTS",
    "CSIRL_OPTIM_DEFAULTS",
    "CSIRLHyperparameters",
    "CSIRLOptimHyperparameters",
    "DISPERSIONS",
    "GRADIENT_BALANCES",
    "META_GRADIENTS",
]

#: the ensemble's uncertainty measures (:func:`~torchrl_csirl.objectives.ensemble_sac.qvalue_dispersion`)
DISPERSIONS = ("variance", "abs_cv")
#: how the meta-objective's two parts are combined (:class:`~torchrl_csirl.objectives.MetaRewardLoss`)
GRADIENT_BALANCES = ("sum", "normalized")
#: how the meta-gradient is computed (:class:`~torchrl_csirl.objectives.MetaRewardLoss`)
META_GRADIENTS = ("double_backward", "jvp")


def _reward_activations() -> tuple[str, ...]:
    from torchrl_csirl.modules.reward import REWARD_ACTIVATIONS  # torch stays out of this module's import

    return tuple(REWARD_ACTIVATIONS)


def _precisions() -> tuple[str, ...]:
    from torchrl_csirl.modules.precision import PRECISIONS  # torch stays out of this module's import

    return PRECISIONS


@dataclass
class CSIRLHyperparameters:
    """CSIRL's settings with their defaults (the recipes' ``csirl`` section): the one place they are declared.

    The loss classes call ``alpha`` ``alpha_init`` (:attr:`alpha_init`) and ``meta_scale`` ``scale``
    (:class:`~torchrl_csirl.objectives.MetaRewardLoss`). Treat :data:`CSIRL_DEFAULTS` as read-only: the
    keyword defaults were read from it when the package was imported.
    """

    intrinsic: bool = option(True, help="false: CSIRL-B (matching reward only, no meta-gradient)")
    fixed_subgoal: bool = option(
        False, help="true: no curriculum, the subgoal stays at the curriculum trajectory's last state (ablation)")
    delta: float = option(5.0, above=0.0, help="subgoal threshold on U_i / U_avg")
    sigma: float = option(0.2, above=0.0, help="soft-average factor")
    dispersion: str = option("variance", choices=DISPERSIONS, help="variance (paper) | abs_cv (code)")
    num_qvalue_nets: int = option(5, minimum=2, help="critics in the ensemble")
    updates_per_round: int = option(2000, above=0, help="updates between two subgoal selections (paper: 20000)")
    meta_every: int = option(2, above=0, help="a meta-gradient step every k updates (paper: 1)")
    lr_inner: float = option(0.01, above=0.0, help="inner SGD step of the meta-gradient")
    meta_scale: float = option(100.0, above=0.0, help="multiplies the meta-objective")
    reward_l1_coef: float = option(1.0, minimum=0.0, help="weight of mean |r_w| in the meta-objective")
    gradient_balance: str = option(
        "sum", choices=GRADIENT_BALANCES,
        help="sum: the gradient of the meta-objective (paper); normalized: its imitation and regulariser parts "
             "each at unit norm, weighted 1 : reward_l1_coef (balanced_meta_gradient)")
    meta_gradient: str = option(
        "double_backward", choices=META_GRADIENTS,
        help="double_backward: through both inner steps; jvp: the inner critic step in closed form (a forward-mode "
             "pass of the critics; the same gradient up to float rounding)")
    reward_activation: str = option(
        "relu", choices=_reward_activations,
        help="hidden-layer activation of r_w: relu (paper) or a smooth one whose units cannot die")
    reward_reference: str = option(
        "none", choices=("none", "expert"),
        help="expert: r_w measured against its mean over 256 expert states (no constant shift can be learned; "
             "ExpertCenteredReward); none: the paper")
    reward_scale: float = option(1.0, above=0.0, help="multiplies the expert-centred r_w (reward_reference=expert)")
    matching_scale: Optional[float] = option(
        None, above=0.0, help="multiplies the matching potential (null: the scenario's or task's published value)")
    matching_target: str = option("final", choices=("final", "next", "path"),
                                  help="final (the paper's text) | next (published code) | path (final's targets, "
                                       "distances along the expert's path)")
    goal_conditioned: Optional[bool] = option(
        None, help="match each transition against the demonstration of its goal (desired_goal; "
                   "GoalConditionedMatchingReward) instead of the first one only; null: on where the observation "
                   "has a desired_goal entry")
    matching_features: str = option("position", choices=("ego", "position"),
                                    help="nearest expert state on: position | ego (the whole ego row: paper, code)")
    failure_resets_progress: bool = option(
        False, help="true: a crash or leaving the road gives s' the matching potential of the curriculum's start "
                    "(the episode pays back its progress); false: the paper")
    gamma: float = option(0.99, above=0.0, below=1.0, help="discount")
    alpha: float = option(0.01, above=0.0, help="entropy coefficient (its initial value unless fixed_alpha)")
    actor_bc_coef: float = option(0.0, minimum=0.0, help="> 0: behavioural cloning on the actor (TD3+BC-style)")
    actor_bc_scale: str = option(
        "actor_loss", choices=("actor_loss", "qvalue"),
        help="the cloning term's weight, actor_bc_coef times: actor_loss, |mean actor loss| (vanishes where the batch's "
             "values of either sign cancel); qvalue, TD3+BC's mean |min_k Q(s, mu(s))| over the batch")
    actor_pretrain_updates: int = option(
        0, minimum=0, help="behavioural-cloning updates of the actor on the demonstrations before training starts "
                           "(a warm start, batches of actor_pretrain_batch_size, Adam at optim.lr), evaluated before the first "
                           "update (the learning curve at frame 0); 0: none, the paper")
    actor_pretrain_batch_size: int = option(256, above=0, help="expert pairs per warm-start update")
    critic_warmup_updates: int = option(
        0, minimum=0, help="the run's first updates step the critics only (the actor, its cloning term and alpha "
                           "held), so that a warm-started actor meets calibrated critics; 0: none, the paper")
    fixed_alpha: bool = option(False, help="false: SAC's automatic temperature (paper: true)")

    @property
    def alpha_init(self) -> float:
        """``alpha`` under the losses' name (:class:`~torchrl_csirl.objectives.EnsembleSACLoss`'s ``alpha_init``)."""
        return self.alpha


@dataclass
class CSIRLOptimHyperparameters:
    """How CSIRL's learner is optimised (the recipes' ``optim`` section), with its defaults."""

    lr: float = option(3.0e-4, above=0.0, help="actor and critics (Adam)")
    reward_lr: float = option(1.0e-3, above=0.0, help="reward network (Adam)")
    utd_ratio: float = option(0.5, above=0.0, help="updates per collected frame")
    tau: float = option(0.005, above=0.0, below=1.0, help="Polyak factor of the target critics")
    max_grad_norm: Optional[float] = option(None, above=0.0, help="clip the gradient norm (null: no clipping)")
    precision: str = option(
        "auto", choices=_precisions,
        help="the learner's matmuls: auto (bf16 where the hardware has native bfloat16, else fp32), fp32, or bf16 "
             "(bfloat16 hidden layers, float32 weights, outputs and losses; needs native bf16); "
             "docs/performance.md#bfloat16")


#: the defaults of the ``csirl`` section and of the building blocks' CSIRL keywords
CSIRL_DEFAULTS = CSIRLHyperparameters()
#: the defaults of the ``optim`` section, of ``make_csirl_learner(tau=)`` and of ``CSIRLLearner.optimizers``
CSIRL_OPTIM_DEFAULTS = CSIRLOptimHyperparameters()
