"""The tanh-Gaussian actor evaluated from its parameter TensorDict (no module swapping, no distribution objects).

:class:`~torchrl.objectives.SACLoss` evaluates its actor by swapping a parameter TensorDict into
the :class:`~torchrl.modules.ProbabilisticActor` (``to_module``), running the TensorDict modules
and building a :class:`~torchrl.modules.TanhNormal` to draw and score an action. For the small
MLP of CSIRL that machinery costs more than the arithmetic. :class:`FusedTanhNormalActor` reads
the same parameters and runs the same operations directly: the MLP's ``F.linear`` layers, the
:class:`~torchrl_csirl.modules.BoundedLogStdNormalParams` head, and the draw and log-probability
of ``TanhNormal.rsample_and_log_prob`` written out op for op (same random draw, values and
gradients bit-identical; ``tests/test_modules.py`` pins this against TorchRL's distribution).
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModule
from tensordict.utils import NestedKey
from torch import nn
from torch.nn import functional as F
from torchrl.modules import ProbabilisticActor, TanhNormal

from torchrl_csirl._compat import safe_tanh as _torchrl_safe_tanh
from torchrl_csirl.modules.actor_critic import BoundedLogStdNormalParams, functorch_transforms_active
from torchrl_csirl.modules.ensemble import mlp_layer_keys, parameter_free
from torchrl_csirl.modules.precision import cast_weight, low_precision_dtype

__all__ = ["FusedTanhNormalActor", "fused_tanh_normal_actor"]

_HALF_LOG_2PI = math.log(math.sqrt(2 * math.pi))
_LOG_2 = math.log(2.0)


class _SafeTanh(torch.autograd.Function):
    """TorchRL's safe tanh (``tanh(x)`` clamped to ``1 - resolution``, backward ``grad * (1 - out^2)``)
    in the combined forward/ctx form, which ``Function.apply`` calls without binding the arguments
    through ``inspect.signature`` (several times cheaper per call). Same values and gradients, at
    every order: the backward reads the saved output, which keeps its graph."""

    @staticmethod
    def forward(ctx, x: torch.Tensor) -> torch.Tensor:
        lim = 1.0 - torch.finfo(x.dtype).resolution
        output = x.tanh().clamp(-lim, lim)
        ctx.save_for_backward(output)
        return output

    @staticmethod
    def backward(ctx, grad: torch.Tensor) -> torch.Tensor:
        (output,) = ctx.saved_tensors
        return grad * (1 - output.pow(2))


def safe_tanh(x: torch.Tensor) -> torch.Tensor:
    """The squashing of TorchRL's ``TanhNormal`` (values and gradients bit-identical).

    Examples:
        >>> import torch
        >>> safe_tanh(torch.tensor([0.0, 100.0]))
        tensor([0.0000, 1.0000])
    """
    if functorch_transforms_active():
        return _torchrl_safe_tanh(x)
    return _SafeTanh.apply(x)


class FusedTanhNormalActor:
    """Evaluates a tanh-Gaussian actor built by :func:`~torchrl_csirl.modules.make_actor` from its parameters.

    Build it with :func:`fused_tanh_normal_actor`, which returns ``None`` for actors it does not
    recognise.

    Args:
        in_key (NestedKey): the observation entry the actor reads.
        linear_keys (sequence of (NestedKey, NestedKey or None)): the ``(weight, bias)`` keys of
            each linear layer in the actor's parameter TensorDict, in order.
        activations (sequence of nn.Module): the element-wise layer after each linear layer but
            the last.
        head (BoundedLogStdNormalParams): maps the last layer's output to ``(loc, scale)``.
        input_features (nn.Module, optional): parameter-free map of the observation.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl_csirl.modules import make_actor
        >>> actor = make_actor(4, 2, hidden=(8,))
        >>> fused = fused_tanh_normal_actor(actor)
        >>> params = TensorDict.from_module(actor)
        >>> loc, scale = fused.dist_params(torch.randn(5, 4), params)
        >>> action, log_prob = fused.rsample_and_log_prob(loc, scale)
        >>> action.shape, log_prob.shape
        (torch.Size([5, 2]), torch.Size([5]))
    """

    def __init__(
        self,
        in_key: NestedKey,
        linear_keys: Sequence[tuple[NestedKey, NestedKey | None]],
        activations: Sequence[nn.Module],
        head: BoundedLogStdNormalParams,
        input_features: nn.Module | None = None,
    ) -> None:
        if len(activations) != len(linear_keys) - 1:
            raise ValueError(
                f"Need one activation between consecutive linear layers: {len(linear_keys)} "
                f"layers, {len(activations)} activations."
            )
        self.in_key = in_key
        self.linear_keys = [tuple(pair) for pair in linear_keys]
        self.activations = list(activations)
        self.head = head
        self.input_features = input_features

    def dist_params(self, observation: torch.Tensor, params: TensorDictBase) -> tuple[torch.Tensor, torch.Tensor]:
        """``(loc, scale)`` of the pre-tanh Gaussian for ``observation`` ``[*B, obs]``."""
        h = observation if self.input_features is None else self.input_features(observation)
        low = low_precision_dtype(h)
        if low is not None:
            return self.head(self._hidden_low_precision(h, params, low))
        for index, (weight_key, bias_key) in enumerate(self.linear_keys):
            bias = None if bias_key is None else params.get(bias_key)
            h = F.linear(h, params.get(weight_key), bias)
            if index < len(self.activations):
                h = self.activations[index](h)
        return self.head(h)

    def _hidden_low_precision(self, h: torch.Tensor, params: TensorDictBase, dtype: torch.dtype) -> torch.Tensor:
        """The MLP under low-precision autocast: hidden layers in ``dtype``, the output layer in float32."""
        last = len(self.linear_keys) - 1
        with torch.autocast(h.device.type, enabled=False):
            h = h.to(dtype)
            for index, (weight_key, bias_key) in enumerate(self.linear_keys):
                weight = params.get(weight_key)
                bias = None if bias_key is None else params.get(bias_key)
                if index == last:
                    h = F.linear(h.float(), weight, bias)
                else:
                    h = F.linear(h, cast_weight(weight, dtype), None if bias is None else cast_weight(bias, dtype))
                    h = self.activations[index](h)
        return h

    @staticmethod
    def rsample_and_log_prob(loc: torch.Tensor, scale: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """A reparameterised action in ``[-1, 1]`` and its log-probability (``TanhNormal``'s, same draw).

        The operations of ``TanhNormal(loc, scale).rsample_and_log_prob()`` (TorchRL 0.14.1, low -1,
        high 1, safe tanh, one event dimension): ``u = loc + eps * scale`` with ``eps`` drawn by
        ``normal_()`` as ``torch.distributions.Normal.rsample`` draws it, ``a = tanh(u)`` clamped,
        ``log N(u; loc, scale) - log|d tanh(u) / du|`` summed over the action dimension.
        """
        eps = torch.empty(loc.shape, dtype=loc.dtype, device=loc.device).normal_()
        preimage = loc + eps * scale
        action = safe_tanh(preimage)
        normal_log_prob = -((preimage - loc) ** 2) / (2 * scale**2) - scale.log() - _HALF_LOG_2PI
        log_abs_det_jacobian = 2.0 * (_LOG_2 - preimage - F.softplus(-2.0 * preimage))
        return action, normal_log_prob.sum(-1) - log_abs_det_jacobian.sum(-1)

    @staticmethod
    def rsample(loc: torch.Tensor, scale: torch.Tensor) -> torch.Tensor:
        """A reparameterised action (``TanhNormal(loc, scale).rsample()``, same draw)."""
        eps = torch.empty(loc.shape, dtype=loc.dtype, device=loc.device).normal_()
        return safe_tanh(loc + eps * scale)

    @staticmethod
    def deterministic_sample(loc: torch.Tensor) -> torch.Tensor:
        """The deterministic action ``tanh(loc)`` (``TanhNormal.deterministic_sample``)."""
        return safe_tanh(loc)


def fused_tanh_normal_actor(actor: nn.Module) -> FusedTanhNormalActor | None:
    """A :class:`FusedTanhNormalActor` for ``actor``, or ``None`` if it is not supported.

    Supported: what :func:`~torchrl_csirl.modules.make_actor` builds, a
    :class:`~torchrl.modules.ProbabilisticActor` over a :class:`~tensordict.nn.TensorDictModule`
    writing ``(loc, scale)`` with ``nn.Sequential([input_features,] MLP, BoundedLogStdNormalParams)``
    (an MLP of ``nn.Linear`` layers and element-wise activations, a parameter-free
    ``input_features``) and a :class:`~torchrl.modules.TanhNormal` on ``[-1, 1]`` with TorchRL's
    default options.

    Examples:
        >>> from torchrl_csirl.modules import make_actor
        >>> fused_tanh_normal_actor(make_actor(4, 2)) is not None
        True
        >>> import torch
        >>> fused_tanh_normal_actor(torch.nn.Linear(3, 2)) is None
        True
    """
    if not isinstance(actor, ProbabilisticActor) or len(actor.module) != 2:
        return None
    net_module, prob_module = actor.module[0], actor.module[1]
    if not _is_default_tanh_normal(prob_module) or not isinstance(net_module, TensorDictModule):
        return None
    if list(net_module.in_keys) != [actor.in_keys[0]] or len(actor.in_keys) != 1:
        return None
    net = net_module.module
    if not isinstance(net, nn.Sequential) or len(net) not in (2, 3):
        return None
    *features, mlp, head = net
    input_features = features[0] if features else None
    if not isinstance(head, BoundedLogStdNormalParams) or not parameter_free(input_features):
        return None
    layers = mlp_layer_keys(actor, mlp)
    if layers is None:
        return None
    return FusedTanhNormalActor(actor.in_keys[0], *layers, head, input_features)


def _is_default_tanh_normal(prob_module: nn.Module) -> bool:
    """A ``TanhNormal`` on ``[-1, 1]`` from ``(loc, scale)``, no other distribution option."""
    kwargs = dict(getattr(prob_module, "distribution_kwargs", None) or {})
    bounds = (kwargs.pop("low", -1.0), kwargs.pop("high", 1.0))
    return (
        getattr(prob_module, "distribution_class", None) is TanhNormal
        and list(getattr(prob_module, "in_keys", ())) == ["loc", "scale"]
        and not kwargs
        and all(isinstance(b, (int, float)) for b in bounds)
        and bounds == (-1.0, 1.0)
    )
