"""Plumbing shared by the imitation baselines (private): sampling, batch assembly, regularisers."""
from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModule
from tensordict.utils import NestedKey
from torch import nn

from torchrl_csirl.transforms.absorbing_states import AbsorbingStates, check_self_loop_count

__all__ = [
    "ABSORBING_OBSERVATIONS",
    "AbsorbingLogit",
    "AbsorbingStateSettings",
    "SACHyperparameters",
    "concat_shared",
    "gradient_penalty",
    "logit_network",
    "make_sac_learner",
    "orthogonal_regularization",
    "require_keys",
    "sample",
]


def sample(buffer, batch_size: int) -> TensorDictBase:
    """``buffer.sample(batch_size)`` without the warning about the buffer's own batch size."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Got conflicting batch_sizes")
        return buffer.sample(batch_size)


def concat_shared(*tensordicts: TensorDictBase) -> TensorDictBase:
    """Concatenates ``tensordicts`` along dim 0 on the (leaf) keys they all hold.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> a = TensorDict({"x": torch.zeros(2), "y": torch.zeros(2)}, [2])
        >>> b = TensorDict({"x": torch.ones(3)}, [3])
        >>> out = concat_shared(a, b)
        >>> out.batch_size, sorted(out.keys())
        (torch.Size([5]), ['x'])
    """
    keys = set(tensordicts[0].keys(True, True))
    for td in tensordicts[1:]:
        keys &= set(td.keys(True, True))
    keys = sorted(keys, key=str)
    return torch.cat([td.select(*keys) for td in tensordicts], 0)


def require_keys(tensordict: TensorDictBase, keys: Sequence, where: str) -> None:
    """Raises one ``KeyError`` naming every key of ``keys`` missing from ``tensordict``."""
    present = set(tensordict.keys(True, True))
    missing = [key for key in keys if key not in present]
    if missing:
        raise KeyError(f"{where}: the batch lacks the keys {missing} (has {sorted(map(str, present))}).")


def logit_network(qvalue: TensorDictModule, out_key: str = "discriminator_logit",
                  absorbing_key: NestedKey | None = None) -> TensorDictModule:
    """A network of the critic's architecture (and input map) writing a scalar under ``out_key``.

    The discriminators and ValueDICE's ``nu`` are built from ``make_qvalue()`` so that every method
    uses the same network sizes and inputs as the critics. With ``absorbing_key`` it also reads
    DAC's absorbing-state indicator (:class:`AbsorbingLogit`): ``[observation, absorbing, action]``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl_csirl.modules import make_qvalue
        >>> d = logit_network(make_qvalue(3, 1, hidden=(8,)))
        >>> d(TensorDict({"observation": torch.zeros(4, 3), "action": torch.zeros(4, 1)}, [4]))["discriminator_logit"].shape
        torch.Size([4, 1])
        >>> logit_network(make_qvalue(3, 1, hidden=(8,)), "nu", absorbing_key="absorbing").in_keys
        ['observation', 'absorbing', 'action']
    """
    if not isinstance(qvalue, TensorDictModule):
        raise TypeError(f"make_qvalue() must return a TensorDictModule, got {type(qvalue).__name__}.")
    if absorbing_key is None:
        return TensorDictModule(qvalue.module, in_keys=list(qvalue.in_keys), out_keys=[out_key])
    observation_key, action_key = qvalue.in_keys
    return TensorDictModule(AbsorbingLogit(qvalue.module), in_keys=[observation_key, absorbing_key, action_key],
                            out_keys=[out_key])


def gradient_penalty(function: Callable[..., torch.Tensor], inputs: Sequence[torch.Tensor], target_norm: float = 1.0,
                     scales: Sequence[torch.Tensor | None] | None = None) -> torch.Tensor:
    """WGAN-GP penalty ``mean_i (||grad_x f(x_i)||_2 - target_norm)^2`` (Gulrajani et al., 2017).

    Args:
        function: maps ``inputs`` to one output per sample (``[B]`` or ``[B, 1]``).
        inputs: tensors ``[B, *]`` (e.g. observation and action); the gradient norm is taken over
            all of them together, per sample.
        target_norm: the norm the gradient is pulled to (1).
        scales: per input, None or a per-entry scale ``c``: the gradient is taken with respect to
            ``x / c`` (``c * grad_x f``), e.g. standardised states whose networks read the raw ones.

    Examples:
        >>> import torch
        >>> x = torch.randn(5, 3)
        >>> round(float(gradient_penalty(lambda x: (2 * x).sum(-1), [x])), 4)  # (2 sqrt(3) - 1) ** 2
        6.0718
    """
    inputs = [x.detach().requires_grad_(True) for x in inputs]
    out = function(*inputs)
    grads = torch.autograd.grad(out.sum(), inputs, create_graph=True)
    if scales is not None:
        grads = [g if c is None else g * c.to(g.dtype) for g, c in zip(grads, scales, strict=True)]
    norm = torch.cat([g.flatten(1) for g in grads], -1).norm(dim=-1)
    return ((norm - target_norm) ** 2).mean()


def orthogonal_regularization(module: nn.Module, skip_last: bool = False) -> torch.Tensor:
    """``sum_W || W W^T * (1 - I) ||_F^2`` over the weight matrices of ``module``'s linear layers.

    The orthogonal regulariser of Brock et al. (2019, Eq. 3), used on the actor's hidden layers by
    ValueDICE (Kostrikov et al., 2020, with coefficient 1e-4). ``W`` is ``[out, in]``, so the rows
    (the output units) are pushed towards orthogonality. ``skip_last`` leaves out the last linear
    layer (an output head).

    Examples:
        >>> import torch
        >>> lin = torch.nn.Linear(4, 4)
        >>> _ = torch.nn.init.eye_(lin.weight)
        >>> float(orthogonal_regularization(lin))
        0.0
    """
    layers = [sub for sub in module.modules() if isinstance(sub, nn.Linear)]
    if skip_last:
        layers = layers[:-1]
    total = None
    for layer in layers:
        gram = layer.weight @ layer.weight.T
        off_diagonal = gram * (1.0 - torch.eye(gram.shape[0], device=gram.device, dtype=gram.dtype))
        term = off_diagonal.pow(2).sum()
        total = term if total is None else total + term
    if total is None:
        raise ValueError(f"{type(module).__name__} has no nn.Linear layer to regularise.")
    return total


# ------------------------------------------------------------------------------ absorbing states
ABSORBING_OBSERVATIONS = ("terminal", "placeholder")


@dataclass
class AbsorbingStateSettings:
    """DAC's absorbing states (Kostrikov et al. 2019), as DAC and ValueDICE use them.

    Attributes:
        absorbing_states: terminal transitions enter an absorbing state with a learned value
            (:class:`~torchrl_csirl.transforms.AbsorbingStates`); False: nothing follows a
            termination.
        absorbing_observation: which absorbing state a termination enters: ``"terminal"`` (one
            per terminal state, observed as the terminal observation: our default, since every
            driving demonstration ends in a terminating success while the learner also terminates
            by crashing) or ``"placeholder"`` (the paper's single absorbing state, a zero
            observation: zero in the standardised states where the networks read them, as ValueDICE's
            code). docs/baselines.md, "DAC's absorbing states", gives the evidence.
        self_loops_per_termination: absorbing self-loop samples per learner transition entering the
            absorbing state, i.e. the absorbing state's weight in the learner's side of a batch: 1 (default) as
            the DAC paper's replay buffer, 10 as the authors' later code (ValueDICE's, which also runs DAC:
            ``absorbing_per_episode``); the expert's side keeps one, as that code's demonstrations
            (:func:`~torchrl_csirl.transforms.absorbing_states.absorbing_self_loops`).
    """

    absorbing_states: bool = True
    absorbing_observation: str = "terminal"
    self_loops_per_termination: int = 1

    def __post_init__(self) -> None:
        check_self_loop_count(self.self_loops_per_termination, "self_loops_per_termination")
        if self.absorbing_observation not in ABSORBING_OBSERVATIONS:
            raise ValueError(f"absorbing_observation must be one of {ABSORBING_OBSERVATIONS}, "
                             f"got {self.absorbing_observation!r}.")

    def absorbing_transforms(self, placeholder: float | torch.Tensor = 0.0) -> list[AbsorbingStates]:
        """The replay-buffer transforms of these settings: ``[AbsorbingStates(...)]``, or ``[]`` without them.
        ``placeholder``: the observation of the ``"placeholder"`` form (ValueDICE's standardised states: the raw
        observation they map to zero).

        Examples:
            >>> AbsorbingStateSettings(absorbing_observation="placeholder").absorbing_transforms()[0].absorbing_observation
            0.0
            >>> AbsorbingStateSettings(absorbing_states=False).absorbing_transforms()
            []
        """
        if not self.absorbing_states:
            return []
        return [AbsorbingStates(absorbing_observation=None if self.absorbing_observation == "terminal" else placeholder)]


class AbsorbingLogit(nn.Module):
    """A scalar network (DAC's discriminator, ValueDICE's ``nu``) that reads DAC's absorbing-state indicator.

    ``logit(s, i, a) = f(s, a) + w * i`` with ``i`` the indicator (0 for real states, 1 for the
    absorbing state, whose samples carry its observation and a zero action, see
    :func:`~torchrl_csirl.transforms.absorbing_states.absorbing_self_loops`): the paper appends
    the indicator to the network's input; here it enters linearly through the learned weight
    ``w``, so that ``f`` keeps the critic's architecture. The absorbing state's logit
    ``f(s_a, 0) + w`` is regularised like any other output: the gradient penalties of
    :class:`~torchrl_csirl.objectives.DACDiscriminatorLoss` and
    :class:`~torchrl_csirl.objectives.ValueDICELoss` interpolate the indicator too and so bound ``w``.

    Args:
        network: ``network(observation, action) -> [B, 1]`` (e.g. a critic's ``ConcatMLP``).

    Examples:
        >>> import torch
        >>> from torchrl_csirl.modules import ConcatMLP
        >>> m = AbsorbingLogit(ConcatMLP(4, (8,)))
        >>> _ = torch.nn.init.constant_(m.indicator_weight, 2.0)
        >>> out = m(torch.zeros(2, 3), torch.tensor([[False], [True]]), torch.zeros(2, 1))
        >>> out.shape, round(float(out[1] - out[0]), 4)
        (torch.Size([2, 1]), 2.0)
    """

    def __init__(self, network: nn.Module) -> None:
        super().__init__()
        self.network = network
        self.indicator_weight = nn.Parameter(torch.zeros(1))

    def forward(self, observation: torch.Tensor, absorbing: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        logit = self.network(observation, action)
        return logit + self.indicator_weight * absorbing.reshape(logit.shape).to(logit.dtype)


# ------------------------------------------------------------------------------ the SAC learner
@dataclass
class SACHyperparameters:
    """The soft actor-critic learner shared by SQIL, GAIL, DAC and IQ-Learn's actor.

    Defaults are the published SAC defaults for continuous control (Haarnoja et al., 2018,
    "Soft Actor-Critic Algorithms and Applications", Table 1): Adam with learning rate 3e-4,
    batches of 256, discount 0.99, Polyak factor 0.005, two critics, a learned temperature with
    target entropy ``-dim(A)`` (initial value 1).

    Attributes:
        lr: Adam learning rate of the actor, the critics and the temperature.
        batch_size: transitions per update.
        gamma: discount.
        tau: Polyak factor of the target critics.
        num_qvalue_nets: critics (clipped double-Q with 2).
        alpha_init: initial temperature.
        fixed_alpha: keep the temperature at ``alpha_init``.
        max_grad_norm: gradient-norm clipping (None: none).
    """

    lr: float = 3e-4
    batch_size: int = 256
    gamma: float = 0.99
    tau: float = 0.005
    num_qvalue_nets: int = 2
    alpha_init: float = 1.0
    fixed_alpha: bool = False
    max_grad_norm: float | None = None


def _check_num_critics(num_qvalue_nets: int) -> None:
    # TorchRL's SACLoss stores a single critic's parameters as plain tensors: they would never train
    if num_qvalue_nets < 2:
        raise ValueError(f"num_qvalue_nets must be >= 2 (with one critic SACLoss registers no critic parameter), "
                         f"got {num_qvalue_nets}.")


def make_sac_learner(actor: nn.Module, qvalue: nn.Module, hp: SACHyperparameters):
    """TorchRL's SAC (as :class:`~torchrl_csirl.objectives.EnsembleSACLoss`, TD(0)) with ``hp``.

    Examples:
        >>> from torchrl_csirl.modules import make_actor, make_qvalue
        >>> loss = make_sac_learner(make_actor(3, 1, hidden=(8,)), make_qvalue(3, 1, hidden=(8,)), SACHyperparameters())
        >>> loss.num_qvalue_nets, float(loss.target_entropy)
        (2, -1.0)
    """
    from torchrl_csirl.objectives.ensemble_sac import EnsembleSACLoss

    _check_num_critics(hp.num_qvalue_nets)
    return EnsembleSACLoss(actor, qvalue, num_qvalue_nets=hp.num_qvalue_nets, alpha_init=hp.alpha_init,
                           fixed_alpha=hp.fixed_alpha, gamma=hp.gamma)
