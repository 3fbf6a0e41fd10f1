"""A critic ensemble evaluated with one batched matmul per layer (no ``torch.vmap``).

:class:`~torchrl.objectives.SACLoss` keeps the ``N`` critics as one parameter TensorDict of
batch size ``[N]`` (every weight stacked as ``[N, out, in]``) and evaluates them with
``torch.vmap`` over the critic module. For the small MLPs of CSIRL the vmap machinery (parameter
swapping, batching rules, TensorDict wrapping) costs about as much as the arithmetic.
:class:`FusedCriticEnsemble` reads the same stacked parameters and evaluates the whole ensemble
directly: one batched matmul per layer, the bias added as vmap adds it, the activations called
on the whole ``[N, batch, width]`` block. The values are bit-identical to the vmapped critic;
see docs/performance.md for the timings.
"""
from __future__ import annotations

from collections.abc import Sequence

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModule
from tensordict.utils import NestedKey
from torch import nn

from torchrl_csirl.modules.actor_critic import ConcatMLP, MaskedReLU
from torchrl_csirl.modules.precision import cast_weight, low_precision_dtype

__all__ = ["FusedCriticEnsemble", "fused_critic_ensemble", "mlp_layer_keys", "parameter_free"]

# parameter-free, element-wise layers that act the same on [M, H] and on [N, M, H]
_ELEMENTWISE = (MaskedReLU, nn.ReLU, nn.Tanh, nn.ELU, nn.LeakyReLU, nn.SiLU, nn.GELU, nn.Identity)


class FusedCriticEnsemble:
    """Evaluates ``N`` stacked copies of a :class:`ConcatMLP` critic without ``vmap``.

    A drop-in replacement of ``torch.vmap(critic, (None, 0))`` for critics built by
    :func:`~torchrl_csirl.modules.make_qvalue`: called with a TensorDict of inputs (batch
    ``[*B]``, shared by the critics) and a parameter TensorDict of batch ``[N]`` (SACLoss's
    ``qvalue_network_params``, its target copy, a detached or graph-carrying version), it
    returns a TensorDict of batch ``[N, *B]`` holding the critic's output entry ``[N, *B, 1]``.
    Gradients flow to the parameters and inputs as through the vmapped critic; forward values
    are bit-identical to it.

    Build it with :func:`fused_critic_ensemble`, which returns ``None`` for critics it does not
    recognise.

    Args:
        in_keys (sequence of NestedKey): the critic's inputs, concatenated in this order.
        out_key (NestedKey): the critic's output entry.
        linear_keys (sequence of (NestedKey, NestedKey or None)): the ``(weight, bias)`` keys
            of each linear layer in the parameter TensorDict, in order.
        activations (sequence of nn.Module): the element-wise layer after each linear layer
            but the last.
        input_features (nn.Module, optional): parameter-free map of the first input.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from tensordict.nn import TensorDictParams
        >>> from torchrl_csirl.modules import make_qvalue
        >>> critic = make_qvalue(4, 2, hidden=(8, 8))
        >>> fused = fused_critic_ensemble(critic)
        >>> params = TensorDict.from_module(critic).expand(3).clone()  # 3 stacked critics
        >>> td = TensorDict({"observation": torch.randn(5, 4), "action": torch.rand(5, 2)}, [5])
        >>> fused(td, params)["state_action_value"].shape
        torch.Size([3, 5, 1])
    """

    def __init__(
        self,
        in_keys: Sequence[NestedKey],
        out_key: NestedKey,
        linear_keys: Sequence[tuple[NestedKey, NestedKey | None]],
        activations: Sequence[nn.Module],
        input_features: nn.Module | None = None,
    ) -> None:
        if len(activations) != len(linear_keys) - 1:
            raise ValueError(
                f"Need one activation between consecutive linear layers: {len(linear_keys)} "
                f"layers, {len(activations)} activations."
            )
        self.in_keys = list(in_keys)
        self.out_key = out_key
        self.linear_keys = [tuple(pair) for pair in linear_keys]
        self.activations = list(activations)
        self.input_features = input_features

    def critic_input(self, tensordict: TensorDictBase) -> torch.Tensor:
        """The concatenated input ``[*B, D]`` the critics share."""
        return self.concat_inputs([tensordict.get(key) for key in self.in_keys])

    def concat_inputs(self, inputs: Sequence[torch.Tensor]) -> torch.Tensor:
        """The critics' input ``[*B, D]`` from their input tensors, in the order of :attr:`in_keys`."""
        inputs = list(inputs)
        if self.input_features is not None:
            inputs[0] = self.input_features(inputs[0])
        return torch.cat(inputs, dim=-1)

    def values(
        self, x: torch.Tensor, params: TensorDictBase, activations: list[tuple[torch.Tensor, torch.Tensor]] | None = None
    ) -> torch.Tensor:
        """``[N, *B, out]`` outputs of the ``N`` critics on a shared input ``x`` of shape ``[*B, D]``.

        ``activations``, if given, receives the detached ``(pre-activation, output)`` pair of every
        hidden layer, which :meth:`jvp` can reuse instead of running the forward pass again.
        """
        low = low_precision_dtype(x)
        if low is not None:
            return self._values_low_precision(x, params, low, activations)
        batch_shape = x.shape[:-1]
        x = x.reshape(-1, x.shape[-1])
        h = None
        for index, (weight_key, bias_key) in enumerate(self.linear_keys):
            weight = params.get(weight_key)
            bias = None if bias_key is None else params.get(bias_key)
            h = _first_layer(x, weight) if index == 0 else torch.bmm(h, weight.transpose(1, 2))
            if bias is not None:
                h = h.add_(bias.unsqueeze(1))  # in place: the matmul output is fresh, and its backward does not read it
            if index < len(self.activations):
                z = h
                h = self.activations[index](h)
                if activations is not None:
                    activations.append((z.detach(), h.detach()))
        return h.reshape(h.shape[0], *batch_shape, h.shape[-1])

    def _values_low_precision(
        self, x: torch.Tensor, params: TensorDictBase, dtype: torch.dtype,
        activations: list[tuple[torch.Tensor, torch.Tensor]] | None,
    ) -> torch.Tensor:
        """:meth:`values` under low-precision autocast (:mod:`~torchrl_csirl.modules.precision`): the
        hidden layers in ``dtype`` with the bias fused into the matmul, the output layer in float32."""
        batch_shape = x.shape[:-1]
        last = len(self.linear_keys) - 1
        with torch.autocast(x.device.type, enabled=False):
            h = x.reshape(-1, x.shape[-1]).to(dtype)
            for index, (weight_key, bias_key) in enumerate(self.linear_keys):
                weight = params.get(weight_key)
                bias = None if bias_key is None else params.get(bias_key)
                if index == last:
                    h = h.float()
                else:
                    weight = cast_weight(weight, dtype)
                    bias = None if bias is None else cast_weight(bias, dtype)
                if index == 0:
                    h = h.expand(weight.shape[0], *h.shape)
                if bias is None:
                    h = torch.bmm(h, weight.transpose(1, 2))
                else:
                    h = torch.baddbmm(bias.unsqueeze(1), h, weight.transpose(1, 2))
                if index < len(self.activations):
                    z = h
                    h = self.activations[index](h)
                    if activations is not None:
                        activations.append((z.detach().float(), h.detach().float()))
        return h.reshape(h.shape[0], *batch_shape, h.shape[-1])

    def jvp(
        self,
        x: torch.Tensor,
        params: TensorDictBase,
        tangents: TensorDictBase,
        activations: list[tuple[torch.Tensor, torch.Tensor]] | None = None,
    ) -> torch.Tensor:
        """Forward-mode derivative of :meth:`values` along a direction in parameter space.

        ``J_phi Q_k(x; phi_k) . t_k`` for every critic ``k``: the linear layers by hand
        (``dz = h dW^T + dh W^T + db``), the activations' derivatives by their masks (ReLU) or
        :func:`torch.func.jvp`. Nothing is differentiable: the result is computed without a graph, in
        float32 even under autocast (:mod:`~torchrl_csirl.modules.precision`).

        Args:
            x (Tensor): shared input ``[*B, D]``.
            params (TensorDictBase): stacked parameters, batch ``[N]``.
            tangents (TensorDictBase): the direction ``t``, with the entries of ``params``.
            activations (list, optional): the hidden layers' ``(pre-activation, output)`` pairs
                recorded by :meth:`values` for the same ``x`` and ``params``; without them the
                forward pass runs again.

        Returns:
            the ``[N, *B, out]`` directional derivatives of the values.

        Examples:
            >>> import torch
            >>> from tensordict import TensorDict
            >>> from torchrl_csirl.modules import make_qvalue
            >>> fused = fused_critic_ensemble(make_qvalue(4, 2, hidden=(8,)))
            >>> params = TensorDict.from_module(make_qvalue(4, 2, hidden=(8,))).expand(3).clone()
            >>> x, cache = torch.randn(5, 6), []
            >>> q = fused.values(x, params, cache)
            >>> t = fused.jvp(x, params, params.apply(torch.ones_like), cache)
            >>> q.shape == t.shape == (3, 5, 1)
            True
        """
        with torch.no_grad(), torch.autocast(x.device.type, enabled=False):
            batch_shape = x.shape[:-1]
            x = x.reshape(-1, x.shape[-1])
            h = dh = None
            for index, (weight_key, bias_key) in enumerate(self.linear_keys):
                weight, dweight = params.get(weight_key), tangents.get(weight_key)
                if index == 0:
                    dz = _first_layer(x, dweight)
                else:
                    dz = torch.baddbmm(torch.bmm(h, dweight.transpose(1, 2)), dh, weight.transpose(1, 2))
                if bias_key is not None:
                    dz = dz + tangents.get(bias_key).unsqueeze(1)
                if index == len(self.activations):
                    break
                if activations is not None:
                    z, h = activations[index]
                else:  # the primal pass again
                    z = _first_layer(x, weight) if index == 0 else torch.bmm(h, weight.transpose(1, 2))
                    if bias_key is not None:
                        z = z + params.get(bias_key).unsqueeze(1)
                    h = self.activations[index](z)
                dh = _activation_jvp(self.activations[index], z, h, dz)
        return dz.reshape(dz.shape[0], *batch_shape, dz.shape[-1])

    def __call__(self, tensordict: TensorDictBase, params: TensorDictBase) -> TensorDictBase:
        if params.ndim != 1:
            raise ValueError(f"Expected critic parameters of batch size [N], got {params.batch_size}.")
        value = self.values(self.critic_input(tensordict), params)
        return TensorDict({self.out_key: value}, batch_size=value.shape[:-1])


def _first_layer(x: torch.Tensor, weight: torch.Tensor) -> torch.Tensor:
    """``[N, M, out]`` products of a shared input ``[M, in]`` with ``N`` stacked weights.

    A broadcast ``matmul``, which is what ``vmap`` runs: one ``mm`` over the stacked weights would
    also do, but for small batches it sums in a different order (values would differ in the last bit).
    """
    return torch.matmul(x, weight.transpose(1, 2))


def _activation_jvp(activation: nn.Module, z: torch.Tensor, h: torch.Tensor, dz: torch.Tensor) -> torch.Tensor:
    """The derivative of ``h = activation(z)`` along ``dz`` (element-wise activations)."""
    if isinstance(activation, nn.Identity):
        return dz
    if isinstance(activation, (MaskedReLU, nn.ReLU)):
        return torch.ops.aten.threshold_backward(dz, h, 0)  # ``dz`` where ``h > 0``: ReLU's own mask
    return torch.func.jvp(activation, (z,), (dz,))[1]


def fused_critic_ensemble(qvalue_network: nn.Module) -> FusedCriticEnsemble | None:
    """A :class:`FusedCriticEnsemble` for ``qvalue_network``, or ``None`` if it is not supported.

    Supported: a :class:`~tensordict.nn.TensorDictModule` over a :class:`ConcatMLP` (what
    :func:`~torchrl_csirl.modules.make_qvalue` builds) whose MLP alternates ``nn.Linear`` layers
    with parameter-free element-wise activations, with one output.

    Examples:
        >>> from torchrl_csirl.modules import make_qvalue
        >>> fused_critic_ensemble(make_qvalue(4, 2)) is not None
        True
        >>> import torch
        >>> fused_critic_ensemble(torch.nn.Linear(3, 1)) is None
        True
    """
    if not isinstance(qvalue_network, TensorDictModule) or not isinstance(qvalue_network.module, ConcatMLP):
        return None
    if len(qvalue_network.out_keys) != 1:
        return None
    concat = qvalue_network.module
    if not parameter_free(concat.input_features):
        return None
    layers = mlp_layer_keys(qvalue_network, concat.mlp)
    if layers is None:
        return None
    linear_keys, activations = layers
    return FusedCriticEnsemble(
        qvalue_network.in_keys,
        qvalue_network.out_keys[0],
        linear_keys,
        activations,
        concat.input_features,
    )


def mlp_layer_keys(
    root: nn.Module, mlp: nn.Module
) -> tuple[list[tuple[NestedKey, NestedKey | None]], list[nn.Module]] | None:
    """The ``(weight, bias)`` parameter keys (relative to ``root``) and activations of an MLP.

    ``mlp`` (a submodule of ``root``) must alternate ``nn.Linear`` layers with parameter-free
    element-wise activations and end on a linear layer; ``None`` otherwise. The keys are those of
    ``TensorDict.from_module(root)``, which is how TorchRL losses store a network's parameters.

    Examples:
        >>> from torchrl_csirl.modules import make_qvalue
        >>> critic = make_qvalue(4, 2, hidden=(8,))
        >>> keys, activations = mlp_layer_keys(critic, critic.module.mlp)
        >>> keys[0], len(activations)
        ((('module', 'mlp', '0', 'weight'), ('module', 'mlp', '0', 'bias')), 1)
    """
    prefix = _module_path(root, mlp)
    linear_keys, activations = [], []
    expect_linear = True
    for name, layer in mlp.named_children():
        if expect_linear and isinstance(layer, nn.Linear):
            bias = None if layer.bias is None else (*prefix, name, "bias")
            linear_keys.append(((*prefix, name, "weight"), bias))
        elif not expect_linear and isinstance(layer, _ELEMENTWISE):
            activations.append(layer)
        else:
            return None
        expect_linear = not expect_linear
    if expect_linear or not linear_keys:  # must end on a linear layer
        return None
    return linear_keys, activations


def parameter_free(module: nn.Module | None) -> bool:
    """Whether ``module`` is ``None`` or holds neither parameters nor buffers."""
    return module is None or not any(True for _ in (*module.parameters(), *module.buffers()))


def _module_path(root: nn.Module, target: nn.Module) -> tuple[str, ...]:
    for name, module in root.named_modules():
        if module is target:
            return tuple(name.split(".")) if name else ()
    raise ValueError("target is not a submodule of root.")
