"""The imitation baselines as pluggable methods: networks, losses, optimisers, buffer transforms, update step.

:func:`make_imitation_method` builds one baseline around the actor and critic factory of the
CSIRL recipe (same network sizes and input map for every method) and returns an
:class:`ImitationMethod`: the policy that acts, the transforms to append to the online and expert
replay buffers, the states to checkpoint and a factory of the update step that
:class:`~torchrl_csirl.trainers.CSIRLTrainer` calls once per update. The losses are in
:mod:`torchrl_csirl.objectives` and the update steps in :mod:`torchrl_csirl.trainers.imitation_updates`;
docs/baselines.md describes every method, its hyperparameters and their sources.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import partial
from typing import Any

import torch
from tensordict import TensorDict
from torch import nn
from torchrl.data import TensorDictReplayBuffer
from torchrl.envs.transforms import Transform
from torchrl.objectives import GAILLoss

from torchrl_csirl.data.mixing import DemonstrationMixer
from torchrl_csirl.modules.exploration import MeanActionGaussianNoise
from torchrl_csirl.modules.features import find_standardization
from torchrl_csirl.objectives._imitation import SACHyperparameters, logit_network, make_sac_learner, sample
from torchrl_csirl.objectives.dac import DACDiscriminatorLoss, DACHyperparameters, make_dac_discriminator
from torchrl_csirl.objectives.gail import GAILHyperparameters, gail_discriminator_input, make_gail_discriminator
from torchrl_csirl.objectives.iq_learn import IQLearnHyperparameters, IQLearnLoss
from torchrl_csirl.objectives.sqil import SQILHyperparameters, sqil_reward_labels
from torchrl_csirl.objectives.target_update import FusedSoftUpdate
from torchrl_csirl.objectives.valuedice import ValueDICEHyperparameters, ValueDICELoss, initial_observations
from torchrl_csirl.trainers.imitation_updates import AdversarialImitationUpdate, DiscriminatorStep, ValueDICEUpdate
from torchrl_csirl.trainers.trainer import CSIRLTrainer
from torchrl_csirl.trainers.updates import SACUpdate
from torchrl_csirl.transforms.discriminator_reward import DiscriminatorReward

__all__ = ["IMITATION_METHODS", "ImitationMethod", "hyperparameters_class", "make_imitation_method"]

UpdateStep = Callable[[CSIRLTrainer], dict[str, torch.Tensor]]


@dataclass
class ImitationMethod:
    """One imitation baseline, ready to be driven by :class:`~torchrl_csirl.trainers.CSIRLTrainer`.

    Attributes:
        name: the method's name (one of :data:`IMITATION_METHODS`).
        policy: the actor that acts (the one given to :func:`make_imitation_method`).
        online_transforms: to append to the online replay buffer's transforms (reward labels,
            discriminator reward, absorbing states), applied at sampling time.
        expert_transforms: to append to the expert replay buffer's transforms.
        states: every object with ``state_dict``/``load_state_dict`` to checkpoint (losses,
            optimisers, discriminators), by name.
        make_update_step: ``(online_buffer, expert_buffer) -> update_step``; the update step is
            ``update_step(trainer) -> dict`` of detached losses, one call per update.
        hyperparameters: the method's hyperparameter dataclass, as used.
        behaviour: wraps the policy for the collector only (the evaluation acts with the policy itself):
            a method's own exploration (ValueDICE's ``exploration_noise``); None: the policy samples.
    """

    name: str
    policy: nn.Module
    online_transforms: list[Transform]
    expert_transforms: list[Transform]
    states: dict[str, Any]
    make_update_step: Callable[[TensorDictReplayBuffer, TensorDictReplayBuffer], UpdateStep]
    hyperparameters: Any = None
    behaviour: Callable[[nn.Module], nn.Module] | None = None


def _adam(module: nn.Module, lr: float, lr_by_prefix: dict[str, float] | None = None) -> torch.optim.Optimizer:
    """Adam over ``module``'s trainable parameters at ``lr``, or at ``lr_by_prefix[prefix]`` for the
    parameters whose name starts with ``prefix``."""
    groups = {prefix: [] for prefix in lr_by_prefix or {}}
    rest = []
    for name, param in module.named_parameters():
        if param.requires_grad:
            prefix = next((p for p in groups if name.startswith(p)), None)
            (groups[prefix] if prefix is not None else rest).append(param)
    param_groups = [{"params": rest}] + [{"params": params, "lr": lr_by_prefix[prefix]}
                                         for prefix, params in groups.items() if params]
    return torch.optim.Adam(param_groups, lr=lr)


def _identity(tensordict):
    return tensordict


def _sac(actor: nn.Module, make_qvalue: Callable[[], nn.Module], hp: SACHyperparameters, device):
    loss = make_sac_learner(actor, make_qvalue(), hp).to(device)
    return loss, _adam(loss, hp.lr), FusedSoftUpdate(loss, tau=hp.tau)


# ------------------------------------------------------------------------------ SQIL
def _make_sqil(actor, make_qvalue, hp: SQILHyperparameters, device) -> ImitationMethod:
    loss, optimizer, target_updater = _sac(actor, make_qvalue, hp, device)
    online_label, expert_label = sqil_reward_labels(hp)

    def make_update_step(online: TensorDictReplayBuffer, expert: TensorDictReplayBuffer) -> UpdateStep:
        # the expert part keeps its own labels: no online transform on it
        mixer = DemonstrationMixer(online, expert, hp.expert_fraction, batch_size=hp.batch_size, transform=_identity)
        return SACUpdate(loss, optimizer, target_updater, hp.max_grad_norm, sample=mixer.sample)

    return ImitationMethod("sqil", actor, [online_label], [expert_label], {"loss": loss, "optim_sac": optimizer},
                           make_update_step, hp)


# ------------------------------------------------------------------------------ GAIL, DAC
def _adversarial(name: str, actor, hp, loss, discriminator_loss, discriminator, optimizer, make_input, loss_keys,
                 online_transforms, expert_transforms, sac) -> ImitationMethod:
    sac_optimizer, target_updater = sac

    def make_update_step(online: TensorDictReplayBuffer, expert: TensorDictReplayBuffer) -> UpdateStep:
        step = DiscriminatorStep(discriminator_loss, optimizer, make_input, online, expert, hp.discriminator_batch_size,
                                 loss_keys)
        sac_update = SACUpdate(loss, sac_optimizer, target_updater, hp.max_grad_norm,
                               sample=lambda: sample(online, hp.batch_size))
        return AdversarialImitationUpdate(step, sac_update, hp.discriminator_every)

    states = {"loss": loss, "optim_sac": sac_optimizer, "discriminator": discriminator,
              "optim_discriminator": optimizer}
    return ImitationMethod(name, actor, online_transforms, expert_transforms, states, make_update_step, hp)


def _make_gail(actor, make_qvalue, hp: GAILHyperparameters, device) -> ImitationMethod:
    loss, sac_optimizer, target_updater = _sac(actor, make_qvalue, hp, device)
    discriminator = make_gail_discriminator(make_qvalue()).to(device)
    discriminator_loss = GAILLoss(discriminator, use_grad_penalty=hp.use_grad_penalty, gp_lambda=hp.gp_lambda)
    optimizer = _adam(discriminator, hp.discriminator_lr)
    loss_keys = {"loss": "loss_discriminator"}
    return _adversarial("gail", actor, hp, loss, discriminator_loss, discriminator, optimizer, gail_discriminator_input,
                        loss_keys, [DiscriminatorReward(discriminator, "gail")], [], (sac_optimizer, target_updater))


def _dac_input(expert, online):
    return TensorDict({"expert": expert, "collector": online}, [])


def _make_dac(actor, make_qvalue, hp: DACHyperparameters, device) -> ImitationMethod:
    loss, sac_optimizer, target_updater = _sac(actor, make_qvalue, hp, device)
    discriminator = make_dac_discriminator(make_qvalue(), hp.absorbing_states).to(device)
    discriminator_loss = DACDiscriminatorLoss(discriminator, gp_lambda=hp.gp_lambda,
                                              self_loops_per_termination=hp.self_loops_per_termination)
    optimizer = _adam(discriminator, hp.discriminator_lr)
    loss_keys = {"loss_discriminator": "loss_discriminator", "loss_gradient_penalty": "loss_gradient_penalty"}
    online_transforms, expert_transforms = hp.absorbing_transforms(), hp.absorbing_transforms()
    online_transforms.append(DiscriminatorReward(discriminator, "logit",
                                                 absorbing_gamma=hp.gamma if hp.absorbing_states else None))
    return _adversarial("dac", actor, hp, loss, discriminator_loss, discriminator, optimizer, _dac_input, loss_keys,
                        online_transforms, expert_transforms, (sac_optimizer, target_updater))


# ------------------------------------------------------------------------------ IQ-Learn
def _make_iqlearn(actor, make_qvalue, hp: IQLearnHyperparameters, device) -> ImitationMethod:
    loss = IQLearnLoss(actor, make_qvalue(), chi2_coefficient=hp.chi2_coefficient, num_qvalue_nets=hp.num_qvalue_nets,
                       alpha_init=hp.alpha_init, fixed_alpha=hp.fixed_alpha, gamma=hp.gamma,
                       use_target_value=hp.use_target_value, value_loss=hp.value_loss,
                       chi2_policy_actions=hp.chi2_policy_actions).to(device)
    optimizer = _adam(loss, hp.lr, {"actor_network_params": hp.actor_lr})
    target_updater = FusedSoftUpdate(loss, tau=hp.tau)
    num_expert = round(hp.expert_fraction * hp.batch_size)
    if not 0 < num_expert < hp.batch_size:
        raise ValueError(f"expert_fraction={hp.expert_fraction} leaves no expert or no replay sample in a batch of {hp.batch_size}.")

    def make_update_step(online: TensorDictReplayBuffer, expert: TensorDictReplayBuffer) -> UpdateStep:
        def batch():
            return TensorDict({"expert": sample(expert, num_expert),
                               "collector": sample(online, hp.batch_size - num_expert)}, [])

        return SACUpdate(loss, optimizer, target_updater, hp.max_grad_norm, sample=batch)

    return ImitationMethod("iqlearn", actor, [], [], {"loss": loss, "optim_sac": optimizer}, make_update_step, hp)


# ------------------------------------------------------------------------------ ValueDICE
def _make_valuedice(actor, make_qvalue, hp: ValueDICEHyperparameters, device) -> ImitationMethod:
    nu = logit_network(make_qvalue(), "nu", "absorbing" if hp.absorbing_states else None)
    norms = find_standardization(actor), find_standardization(nu)
    if hp.normalize_states and (norms[0] is None or norms[1] is None):
        raise ValueError("normalize_states=True: the actor and nu must read the observation through a "
                         "StandardizeFeatures first (torchrl_csirl.modules.with_standardization).")
    loss = ValueDICELoss(actor, nu, gamma=hp.gamma, replay_regularization=hp.replay_regularization,
                         orthogonal_regularization=hp.orthogonal_regularization, gp_lambda=hp.gp_lambda,
                         observation_scale=norms[1].scale if hp.normalize_states else None,
                         self_loops_per_termination=hp.self_loops_per_termination).to(device)
    nu_optimizer, actor_optimizer = _adam(nu, hp.nu_lr), _adam(actor, hp.actor_lr)

    def make_update_step(online: TensorDictReplayBuffer, expert: TensorDictReplayBuffer) -> UpdateStep:
        starts = None if hp.initial_states == "expert" else initial_observations(expert.storage[:]).to(device)
        return ValueDICEUpdate(loss, nu_optimizer, actor_optimizer, online, expert, hp.batch_size, starts,
                               hp.max_grad_norm)

    states = {"loss": loss, "optim_nu": nu_optimizer, "optim_actor": actor_optimizer}  # the loss holds actor and nu
    # the authors' code standardises the env's states, then appends the absorbing one: zero in the standardised states
    placeholder = norms[1].loc if hp.normalize_states else 0.0
    behaviour = (None if hp.exploration_noise is None
                 else partial(MeanActionGaussianNoise, sigma=hp.exploration_noise))
    return ImitationMethod("valuedice", actor, hp.absorbing_transforms(placeholder), hp.absorbing_transforms(placeholder),
                           states, make_update_step, hp, behaviour)


_BUILDERS: dict[str, tuple[type, Callable[..., ImitationMethod]]] = {
    "iqlearn": (IQLearnHyperparameters, _make_iqlearn),
    "valuedice": (ValueDICEHyperparameters, _make_valuedice),
    "sqil": (SQILHyperparameters, _make_sqil),
    "gail": (GAILHyperparameters, _make_gail),
    "dac": (DACHyperparameters, _make_dac),
}
IMITATION_METHODS = ("gail", "dac", "valuedice", "sqil", "iqlearn")


def hyperparameters_class(name: str) -> type:
    """The hyperparameter dataclass of method ``name``.

    Examples:
        >>> hyperparameters_class("sqil").__name__
        'SQILHyperparameters'
    """
    _check_name(name)
    return _BUILDERS[name][0]


def _check_name(name: str) -> None:
    if name not in IMITATION_METHODS:
        raise ValueError(f"unknown imitation method {name!r}; expected one of {IMITATION_METHODS}.")


def _resolve(cls: type, hyperparameters: Any) -> Any:
    if hyperparameters is None:
        return cls()
    if isinstance(hyperparameters, cls):
        return hyperparameters
    if isinstance(hyperparameters, Mapping):  # a dict, or an OmegaConf DictConfig
        hyperparameters = dict(hyperparameters)
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(hyperparameters) - known)
        if unknown:
            raise ValueError(f"{cls.__name__} has no field(s) {unknown}; known: {sorted(known)}.")
        return cls(**hyperparameters)
    raise TypeError(f"hyperparameters must be a {cls.__name__}, a dict or None, got {type(hyperparameters).__name__}.")


def make_imitation_method(name: str, actor: nn.Module, make_qvalue: Callable[[], nn.Module], *, obs_dim: int,
                          action_dim: int, hyperparameters: Any = None,
                          device: torch.device | str = "cpu") -> ImitationMethod:
    """Builds the imitation baseline ``name`` around ``actor`` and critics from ``make_qvalue()``.

    Args:
        name: one of :data:`IMITATION_METHODS`.
        actor: the tanh-Gaussian policy (:func:`~torchrl_csirl.modules.make_actor`).
        make_qvalue: builds one critic ``Q(s, a)`` (:func:`~torchrl_csirl.modules.make_qvalue`, the
            same sizes and input map as CSIRL's); discriminators and ValueDICE's ``nu`` are built
            with it too.

    Keyword Args:
        obs_dim: observation size (checked by one dry call of a critic).
        action_dim: action size (checked against the actor's action spec).
        hyperparameters: the method's dataclass (:func:`hyperparameters_class`), a mapping of
            (some of) its fields (a dict, an OmegaConf ``DictConfig``), or None for the defaults.
        device: where the networks live.

    Examples:
        >>> from torchrl_csirl.modules import make_actor, make_qvalue
        >>> method = make_imitation_method("sqil", make_actor(3, 1, hidden=(8,)),
        ...                                lambda: make_qvalue(3, 1, hidden=(8,)), obs_dim=3, action_dim=1)
        >>> method.name, [t.value for t in method.online_transforms + method.expert_transforms]
        ('sqil', [0.0, 1.0])
        >>> make_imitation_method("dagger", None, None, obs_dim=3, action_dim=1)
        Traceback (most recent call last):
        ...
        ValueError: unknown imitation method 'dagger'; expected one of ('gail', 'dac', 'valuedice', 'sqil', 'iqlearn').
    """
    _check_name(name)
    cls, builder = _BUILDERS[name]
    hp = _resolve(cls, hyperparameters)
    spec = getattr(actor, "spec", None)
    if spec is not None and "action" in spec.keys() and spec["action"].shape[-1] != action_dim:
        raise ValueError(f"the actor's actions have size {spec['action'].shape[-1]}, expected action_dim={action_dim}.")
    _check_qvalue(make_qvalue, obs_dim, action_dim)
    method = builder(actor, make_qvalue, hp, torch.device(device))
    method.make_update_step = _checking_demonstrations(name, method.make_update_step)
    return method


#: what every method reads from an expert transition
DEMONSTRATION_KEYS = ("observation", "action", ("next", "observation"), ("next", "terminated"), ("next", "done"))


def _checking_demonstrations(name: str, make_update_step: Callable) -> Callable:
    """``make_update_step`` that first checks the expert buffer: not empty, with :data:`DEMONSTRATION_KEYS`."""

    def checked(online: TensorDictReplayBuffer, expert: TensorDictReplayBuffer) -> UpdateStep:
        if expert is None or not len(expert):
            raise ValueError(f"{name} needs expert demonstrations: the expert buffer is empty.")
        present = set(expert.storage[0].keys(True, True))
        missing = [key for key in DEMONSTRATION_KEYS if key not in present]
        if missing:
            raise ValueError(f"{name}: the expert transitions lack the keys {missing}.")
        return make_update_step(online, expert)

    return checked


def _check_qvalue(make_qvalue: Callable[[], nn.Module], obs_dim: int, action_dim: int) -> None:
    """One dry call of a critic from ``make_qvalue()`` on ``[1, obs_dim]`` / ``[1, action_dim]`` inputs."""
    critic = make_qvalue()
    keys = list(getattr(critic, "in_keys", ()))
    if len(keys) != 2:
        raise ValueError(f"make_qvalue() must build a TensorDictModule reading [observation, action], got in_keys {keys}.")
    probe = TensorDict({keys[0]: torch.zeros(1, obs_dim), keys[1]: torch.zeros(1, action_dim)}, [1])
    try:
        with torch.no_grad():
            critic(probe)
    except RuntimeError as err:
        raise ValueError(f"make_qvalue() builds a critic that does not take observations of size {obs_dim} and "
                         f"actions of size {action_dim}: {err}") from err
