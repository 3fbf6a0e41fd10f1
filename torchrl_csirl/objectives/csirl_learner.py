"""CSIRL's learner in one call: the actor, the ensemble-SAC loss and its target updater, the reward
network ``r_w`` and the meta-gradient loss, built from plain arguments.

This is what ``recipes/csirl_highway.py`` builds from its configuration (the ``csirl`` and
``optim`` sections); a script of one's own gets the same learner without the recipe's configuration.
The defaults are the configuration's (:mod:`torchrl_csirl.hyperparameters`; :data:`CSIRL_DEFAULTS` and
:class:`CSIRLHyperparameters` are importable from here too).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch
from torch import nn
from torchrl.modules import ProbabilisticActor
from torchrl.objectives import SoftUpdate

from torchrl_csirl.hyperparameters import CSIRL_DEFAULTS, CSIRL_OPTIM_DEFAULTS, CSIRLHyperparameters
from torchrl_csirl.modules import (
    ExpertCenteredReward,
    make_actor,
    make_qvalue,
    make_reward_network,
)
from torchrl_csirl.objectives.ensemble_sac import EnsembleSACLoss, _first_time
from torchrl_csirl.objectives.meta_reward import MetaRewardLoss
from torchrl_csirl.objectives.target_update import FusedSoftUpdate

__all__ = ["CSIRL_DEFAULTS", "CSIRLHyperparameters", "CSIRLLearner", "make_csirl_learner"]


@dataclass
class CSIRLLearner:
    """The trainable parts of CSIRL (:func:`make_csirl_learner`).

    Attributes:
        actor: the policy (a TorchRL ``ProbabilisticActor``), shared by ``sac``.
        sac: the ensemble-SAC loss over the actor and the critic ensemble.
        target_updater: Polyak averaging of ``sac``'s target critics.
        reward_network: the learned reward ``r_w`` (wrapped in an
            :class:`~torchrl_csirl.modules.ExpertCenteredReward` when built with reference states).
        meta: the meta-gradient loss of ``r_w``; ``None`` for CSIRL-B (no learned reward).
    """

    actor: ProbabilisticActor
    sac: EnsembleSACLoss
    target_updater: SoftUpdate
    reward_network: nn.Module
    meta: MetaRewardLoss | None

    def optimizers(self, lr: float = CSIRL_OPTIM_DEFAULTS.lr,
                   reward_lr: float = CSIRL_OPTIM_DEFAULTS.reward_lr) -> dict[str, torch.optim.Optimizer]:
        """Adam on the actor and critics (``"optim_sac"``, ``lr``) and on ``r_w`` (``"optim_reward"``, ``reward_lr``)."""
        return {
            "optim_sac": torch.optim.Adam([p for p in self.sac.parameters() if p.requires_grad], lr=lr),
            "optim_reward": torch.optim.Adam(self.reward_network.parameters(), lr=reward_lr),
        }


def make_csirl_learner(
    obs_dim: int,
    action_dim: int,
    *,
    input_features: nn.Module | None = None,
    hidden: Sequence[int] = (256, 256),
    num_qvalue_nets: int = CSIRL_DEFAULTS.num_qvalue_nets,
    alpha_init: float = CSIRL_DEFAULTS.alpha_init,
    fixed_alpha: bool = CSIRL_DEFAULTS.fixed_alpha,
    gamma: float = CSIRL_DEFAULTS.gamma,
    dispersion: str = CSIRL_DEFAULTS.dispersion,
    tau: float = CSIRL_OPTIM_DEFAULTS.tau,
    intrinsic: bool = CSIRL_DEFAULTS.intrinsic,
    reward_activation: str = CSIRL_DEFAULTS.reward_activation,
    reward_reference: torch.Tensor | None = None,
    reward_scale: float = CSIRL_DEFAULTS.reward_scale,
    lr_inner: float = CSIRL_DEFAULTS.lr_inner,
    meta_scale: float = CSIRL_DEFAULTS.meta_scale,
    reward_l1_coef: float = CSIRL_DEFAULTS.reward_l1_coef,
    gradient_balance: str = CSIRL_DEFAULTS.gradient_balance,
    meta_gradient: str = CSIRL_DEFAULTS.meta_gradient,
    fused_target_update: bool = True,
    device: torch.device | str = "cpu",
) -> CSIRLLearner:
    """Builds CSIRL's actor, ensemble-SAC loss, target updater, reward network and meta-gradient loss.

    The defaults are :data:`CSIRL_DEFAULTS` and ``CSIRL_OPTIM_DEFAULTS.tau``
    (:mod:`torchrl_csirl.hyperparameters`), the recipes' default preset (docs/recipes.md; the
    paper's values where they differ are ``fixed_alpha=True`` and ``meta_every=1``, ``preset=paper``).
    The networks are MLPs of ``hidden`` units (:func:`~torchrl_csirl.modules.make_actor`,
    :func:`~torchrl_csirl.modules.make_qvalue`, :func:`~torchrl_csirl.modules.make_reward_network`).

    Args:
        obs_dim (int): observation size.
        action_dim (int): action size.
        input_features (nn.Module, optional): an input map every network reads the observation
            through (e.g. :func:`~torchrl_csirl.modules.make_input_features`).
        hidden (sequence of int): hidden layer sizes of the actor, the critics and ``r_w``.
            Defaults to ``(256, 256)``.
        num_qvalue_nets (int): critics in the ensemble. Defaults to ``5``.
        alpha_init (float): the entropy coefficient (its initial value unless ``fixed_alpha``).
            Defaults to ``0.01``.
        fixed_alpha (bool): keep ``alpha`` fixed instead of SAC's automatic temperature.
            Defaults to ``False``.
        gamma (float): discount. Defaults to ``0.99``.
        dispersion (str): the ensemble's uncertainty, ``"variance"`` (paper) or ``"abs_cv"``.
            Defaults to ``"variance"``.
        tau (float): Polyak factor of the target critics. Defaults to ``0.005``.
        intrinsic (bool): learn the reward ``r_w`` with the meta-gradient; ``False``: CSIRL-B
            (``meta`` is ``None``). Defaults to ``True``.
        reward_activation (str): hidden activation of ``r_w`` (one of
            :data:`~torchrl_csirl.modules.REWARD_ACTIVATIONS`). Defaults to ``"relu"``.
        reward_reference (torch.Tensor, optional): expert states ``(N, obs_dim)``; when given,
            ``r_w`` is measured against its mean over them
            (:class:`~torchrl_csirl.modules.ExpertCenteredReward`, e.g. with
            :func:`~torchrl_csirl.modules.expert_reference_states`).
        reward_scale (float): multiplies the expert-centred ``r_w``. Defaults to ``1.0``.
        lr_inner (float): the meta-gradient's inner SGD step. Defaults to ``0.01``.
        meta_scale (float): multiplies the meta-objective. Defaults to ``100.0``.
        reward_l1_coef (float): weight of ``mean |r_w|`` in the meta-objective. Defaults to ``1.0``.
        gradient_balance (str): ``"sum"`` (paper) or ``"normalized"``
            (:class:`~torchrl_csirl.objectives.MetaRewardLoss`). Defaults to ``"sum"``.
        meta_gradient (str): ``"double_backward"`` or ``"jvp"`` (the inner critic step in closed
            form; :class:`~torchrl_csirl.objectives.MetaRewardLoss`). Defaults to ``"double_backward"``.
        fused_target_update (bool): blend the target critics in one fused call
            (:class:`~torchrl_csirl.objectives.FusedSoftUpdate`, bit-identical); ``False``: TorchRL's
            :class:`~torchrl.objectives.SoftUpdate`. Defaults to ``True``.
        device: where the losses and networks live. Defaults to ``"cpu"``.

    Returns:
        CSIRLLearner: the parts; :meth:`CSIRLLearner.optimizers` gives their Adam optimisers.

    Examples:
        >>> learner = make_csirl_learner(25, 2, num_qvalue_nets=3)
        >>> learner.sac.num_qvalue_nets, learner.meta is not None
        (3, True)
        >>> sorted(learner.optimizers(lr=3e-4, reward_lr=1e-3))
        ['optim_reward', 'optim_sac']
        >>> make_csirl_learner(25, 2, intrinsic=False).meta is None  # CSIRL-B
        True
        >>> make_csirl_learner(3, 1, hidden=(64, 64)).actor(observation=torch.zeros(3))[0].shape  # a smaller task
        torch.Size([1])
    """
    hidden = tuple(hidden)
    actor = make_actor(obs_dim, action_dim, hidden=hidden, input_features=input_features)
    _first_time("sacloss_differences")  # CSIRL's learner, built with its documented settings on purpose: no notice
    sac = EnsembleSACLoss(
        actor,
        make_qvalue(obs_dim, action_dim, hidden=hidden, input_features=input_features),
        num_qvalue_nets=num_qvalue_nets,
        alpha_init=alpha_init,
        fixed_alpha=fixed_alpha,
        gamma=gamma,
        dispersion=dispersion,
    ).to(device)
    target_updater = (FusedSoftUpdate if fused_target_update else SoftUpdate)(sac, tau=tau)
    reward_network = make_reward_network(obs_dim, hidden=hidden, input_features=input_features,
                                         activation=reward_activation)
    if reward_reference is not None:
        reward_network = ExpertCenteredReward(reward_network, reward_reference, scale=reward_scale)
    reward_network = reward_network.to(device)
    meta = None
    if intrinsic:
        meta = MetaRewardLoss(sac, reward_network, lr_inner=lr_inner, scale=meta_scale, reward_l1_coef=reward_l1_coef,
                              gradient_balance=gradient_balance, joint_sac_update=True, meta_gradient=meta_gradient)
    return CSIRLLearner(actor, sac, target_updater, reward_network, meta)
