"""Actor and critic networks of the CSIRL learner (SAC, tanh-Gaussian policy, MLP 2x256 ReLU)."""
from __future__ import annotations

from collections.abc import Sequence

import torch
from tensordict.nn import TensorDictModule
from torch import nn
from torchrl.data import Bounded
from torchrl.modules import MLP, ProbabilisticActor, TanhNormal

from torchrl_csirl.modules.precision import mlp_forward

__all__ = ["BoundedLogStdNormalParams", "ConcatMLP", "MaskedReLU", "make_actor", "make_qvalue", "masked_relu"]


class BoundedLogStdNormalParams(nn.Module):
    """Splits a ``2 * d`` vector into ``(loc, scale)`` with ``log(scale)`` squashed into ``[min, max]``.

    The log-std head goes through ``tanh`` and is rescaled affinely to
    ``[log_std_min, log_std_max]`` (the usual SAC parameterisation, also the
    one of the CSIRL code), so the scale lies in ``[exp(min), exp(max)]``.

    Args:
        log_std_min (float): lower bound of the log standard deviation. Defaults to ``-5.0``.
        log_std_max (float): upper bound of the log standard deviation. Defaults to ``2.0``.

    Examples:
        >>> import torch
        >>> m = BoundedLogStdNormalParams()
        >>> loc, scale = m(torch.randn(3, 4))
        >>> loc.shape, bool(((scale.log() >= -5 - 1e-5) & (scale.log() <= 2 + 1e-5)).all())
        (torch.Size([3, 2]), True)
    """

    def __init__(self, log_std_min: float = -5.0, log_std_max: float = 2.0) -> None:
        super().__init__()
        if not log_std_min < log_std_max:
            raise ValueError(
                f"log_std_min must be < log_std_max, got {log_std_min} and {log_std_max}."
            )
        self.log_std_min = float(log_std_min)
        self.log_std_max = float(log_std_max)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        if x.dtype in (torch.bfloat16, torch.float16):  # a stock MLP under autocast: the head in float32
            x = x.float()
        loc, log_std = x.chunk(2, dim=-1)
        half_range = 0.5 * (self.log_std_max - self.log_std_min)
        log_std = self.log_std_min + half_range * (torch.tanh(log_std) + 1.0)
        return loc, log_std.exp()


def _check_dims(obs_dim: int, action_dim: int, hidden: Sequence[int]) -> tuple[int, ...]:
    for name, value in (("obs_dim", obs_dim), ("action_dim", action_dim)):
        if not isinstance(value, int) or value <= 0:
            raise ValueError(f"{name} must be a positive int, got {value!r}.")
    hidden = tuple(hidden)
    if not hidden or any((not isinstance(h, int)) or h <= 0 for h in hidden):
        raise ValueError(f"hidden must be a non-empty sequence of positive ints, got {hidden!r}.")
    return hidden


def _input_size(obs_dim: int, input_features: nn.Module | None) -> int:
    """Width of the first layer: ``obs_dim``, or what ``input_features`` maps it to."""
    if input_features is None:
        return obs_dim
    if getattr(input_features, "in_features", obs_dim) != obs_dim:
        raise ValueError(
            f"input_features expects observations of size {input_features.in_features}, got obs_dim={obs_dim}."
        )
    return int(input_features.out_features)


def make_actor(
    obs_dim: int,
    action_dim: int,
    hidden: Sequence[int] = (256, 256),
    in_key: str = "observation",
    *,
    log_std_min: float = -5.0,
    log_std_max: float = 2.0,
    input_features: nn.Module | None = None,
) -> ProbabilisticActor:
    """Builds the CSIRL tanh-Gaussian actor (MLP with ReLU, actions in ``[-1, 1]``).

    The network writes ``"loc"`` and ``"scale"``, samples ``"action"`` from a
    :class:`~torchrl.modules.TanhNormal` on ``[-1, 1]`` and writes its log-probability
    (TorchRL's default log-prob key, ``"action_log_prob"``). ``log(scale)`` is bounded to
    ``[log_std_min, log_std_max]``.

    Args:
        obs_dim (int): observation size.
        action_dim (int): action size.
        hidden (sequence of int): hidden layer widths. Defaults to ``(256, 256)``.
        in_key (str): observation key. Defaults to ``"observation"``.

    Keyword Args:
        log_std_min (float): lower log-std bound. Defaults to ``-5.0``.
        log_std_max (float): upper log-std bound. Defaults to ``2.0``.
        input_features (nn.Module, optional): a parameter-free map applied to the observation
            before the MLP, exposing ``in_features``/``out_features`` (e.g.
            :class:`~torchrl_csirl.modules.EgoRelativeFeatures`). Defaults to ``None`` (raw observation).

    Returns:
        a :class:`~torchrl.modules.ProbabilisticActor` with a bounded action spec.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> actor = make_actor(25, 2)
        >>> td = actor(TensorDict({"observation": torch.randn(4, 25)}, [4]))
        >>> td["action"].shape, bool(td["action"].abs().le(1).all())
        (torch.Size([4, 2]), True)
    """
    hidden = _check_dims(obs_dim, action_dim, hidden)
    layers = [] if input_features is None else [input_features]
    net = nn.Sequential(
        *layers,
        MLP(
            in_features=_input_size(obs_dim, input_features),
            out_features=2 * action_dim,
            num_cells=list(hidden),
            activation_class=MaskedReLU,
        ),
        BoundedLogStdNormalParams(log_std_min, log_std_max),
    )
    module = TensorDictModule(net, in_keys=[in_key], out_keys=["loc", "scale"])
    spec = Bounded(low=-1.0, high=1.0, shape=(action_dim,))
    return ProbabilisticActor(
        module,
        in_keys=["loc", "scale"],
        out_keys=["action"],
        spec=spec,
        distribution_class=TanhNormal,
        distribution_kwargs={"low": -1.0, "high": 1.0},
        return_log_prob=True,
    )


class _ReLUDetachedMask(torch.autograd.Function):
    """ReLU whose backward reads a detached copy of the output (no second-order edge)."""

    @staticmethod
    def forward(x: torch.Tensor) -> torch.Tensor:
        return torch.relu(x)

    @staticmethod
    def setup_context(ctx, inputs, output) -> None:
        ctx.save_for_backward(output.detach())

    @staticmethod
    def backward(ctx, grad: torch.Tensor) -> torch.Tensor:
        (output,) = ctx.saved_tensors
        return torch.ops.aten.threshold_backward(grad, output, 0)

    @staticmethod
    def vmap(info, in_dims, x):  # elementwise: the batched rule is the op itself
        return _ReLUDetachedMask.apply(x), in_dims[0]


class _ReLUDetachedMaskNoFunctorch(torch.autograd.Function):
    """:class:`_ReLUDetachedMask` in the combined forward/ctx form, which ``Function.apply`` calls
    without binding the arguments through ``inspect.signature`` (several times cheaper per call);
    functorch transforms (``vmap``) need the separate ``setup_context`` form."""

    @staticmethod
    def forward(ctx, x: torch.Tensor) -> torch.Tensor:
        out = torch.relu(x)
        ctx.save_for_backward(out.detach())
        return out

    @staticmethod
    def backward(ctx, grad: torch.Tensor) -> torch.Tensor:
        (output,) = ctx.saved_tensors
        return torch.ops.aten.threshold_backward(grad, output, 0)


functorch_transforms_active = getattr(torch._C, "_are_functorch_transforms_active", lambda: True)


def masked_relu(x: torch.Tensor) -> torch.Tensor:
    """Functional :class:`MaskedReLU`.

    Examples:
        >>> import torch
        >>> x = torch.tensor([-1.0, 0.0, 2.0], requires_grad=True)
        >>> masked_relu(x).sum().backward()
        >>> x.grad
        tensor([0., 0., 1.])
    """
    if functorch_transforms_active():
        return _ReLUDetachedMask.apply(x)
    return _ReLUDetachedMaskNoFunctorch.apply(x)


class MaskedReLU(nn.Module):
    """ReLU with the same values and gradients as :class:`torch.nn.ReLU`, cheaper to differentiate twice.

    The backward of ``nn.ReLU`` (``threshold_backward(grad, x)``) keeps a derivative
    edge towards ``x`` (whose value is always zero). When a *gradient* of the critic is
    differentiated again (the CSIRL meta-gradient differentiates ``dQ/da`` and
    ``dL_Q/dphi`` w.r.t. parameters that depend on the reward), autograd therefore
    back-propagates zeros through the whole forward pass. Here the mask is read from a
    detached copy of the output, which removes that dead path (about one batched matmul
    per hidden layer and per second-order pass). Works under ``vmap``.

    Examples:
        >>> import torch
        >>> x = torch.linspace(-1, 1, 5)
        >>> torch.equal(MaskedReLU()(x), torch.relu(x))
        True
    """

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return masked_relu(x)


class ConcatMLP(nn.Module):
    """MLP over the concatenation of its inputs along the last dimension (the critic's network).

    ``input_features``, if given, maps the first input (the observation) before the concatenation.
    :func:`~torchrl_csirl.modules.fused_critic_ensemble` recognises this structure and evaluates
    an ensemble of such critics without ``vmap``.

    Args:
        in_features (int): width of the concatenated input.
        hidden (sequence of int): hidden layer widths.
        input_features (nn.Module, optional): parameter-free map of the first input.

    Examples:
        >>> import torch
        >>> net = ConcatMLP(5, (8,))
        >>> net(torch.randn(3, 4), torch.randn(3, 1)).shape
        torch.Size([3, 1])
    """

    def __init__(self, in_features: int, hidden: Sequence[int], input_features: nn.Module | None = None) -> None:
        super().__init__()
        self.input_features = input_features
        self.mlp = MLP(
            in_features=in_features,
            out_features=1,
            num_cells=list(hidden),
            activation_class=MaskedReLU,
        )

    def forward(self, *inputs: torch.Tensor) -> torch.Tensor:
        if self.input_features is not None:
            inputs = (self.input_features(inputs[0]), *inputs[1:])
        return mlp_forward(self.mlp, torch.cat(inputs, dim=-1))


def make_qvalue(
    obs_dim: int,
    action_dim: int,
    hidden: Sequence[int] = (256, 256),
    input_features: nn.Module | None = None,
) -> TensorDictModule:
    """Builds one state-action value network Q(s, a) (MLP with ReLU on ``[s, a]``).

    The ReLUs are :class:`MaskedReLU` (identical function, cheaper second-order autograd).

    Args:
        obs_dim (int): observation size.
        action_dim (int): action size.
        hidden (sequence of int): hidden layer widths. Defaults to ``(256, 256)``.
        input_features (nn.Module, optional): a parameter-free map of the observation (see
            :func:`make_actor`). Defaults to ``None``.

    Returns:
        a :class:`~tensordict.nn.TensorDictModule` reading ``["observation", "action"]`` and
        writing ``"state_action_value"`` (shape ``[*batch, 1]``).

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> q = make_qvalue(25, 2)
        >>> td = TensorDict({"observation": torch.randn(4, 25), "action": torch.rand(4, 2)}, [4])
        >>> q(td)["state_action_value"].shape
        torch.Size([4, 1])
    """
    hidden = _check_dims(obs_dim, action_dim, hidden)
    return TensorDictModule(
        ConcatMLP(_input_size(obs_dim, input_features) + action_dim, hidden, input_features),
        in_keys=["observation", "action"],
        out_keys=["state_action_value"],
    )
