"""Mixed precision for the learner: bfloat16 matmuls; float32 weights, optimiser state, outputs and losses.

The switch is PyTorch's own :func:`torch.autocast`. Inside ``torch.autocast(device, torch.bfloat16)``
the fused critic ensemble (:class:`~torchrl_csirl.modules.FusedCriticEnsemble`), the fused actor
(:class:`~torchrl_csirl.modules.FusedTanhNormalActor`), the critic and reward MLPs run their hidden
layers in bfloat16 (the float32 weights cast once per update, biases fused into the matmul,
activations kept in bfloat16) and their **output layer in float32**, so values, action means and
scales, log-probabilities, rewards and every loss stay float32. The weights, their gradients and the
optimisers' state are float32 throughout. Outside autocast nothing changes: the float32 path is the
same code, bit for bit.

:class:`LearnerPrecision` is what a recipe holds (``optim.precision=fp32|bf16|auto``): its
:meth:`~LearnerPrecision.autocast` opens the context around a loss's forward pass (the backward runs
outside it, as PyTorch recommends).

Examples:
    >>> import torch
    >>> from torchrl_csirl.modules import make_qvalue
    >>> critic = make_qvalue(4, 2, hidden=(8, 8))
    >>> obs, action = torch.randn(3, 4), torch.rand(3, 2)
    >>> with LearnerPrecision(torch.bfloat16).autocast():
    ...     value = critic.module(obs, action)
    >>> value.dtype  # the output layer ran in float32
    torch.float32
    >>> LearnerPrecision.from_setting("fp32").dtype
    torch.float32
"""
from __future__ import annotations

import contextlib
import dataclasses
import threading
from collections.abc import Iterator

import torch
from torch import nn

__all__ = [
    "PRECISIONS",
    "LearnerPrecision",
    "PrecisionUnsupported",
    "cast_weight",
    "has_native_bf16",
    "low_precision_dtype",
    "mlp_forward",
]

#: the values of ``optim.precision``
PRECISIONS = ("fp32", "bf16", "auto")

_LOW_PRECISION = (torch.bfloat16, torch.float16)
_CPU_BF16_FLAGS = ("avx512_bf16", "amx_bf16")


class PrecisionUnsupported(ValueError):
    """``bf16`` asked for on a device without native bfloat16 matmuls (one line)."""


def _cpu_flags() -> set[str]:
    get = getattr(torch.cpu, "get_capabilities", None)
    if get is not None:
        return {name for name, on in get().items() if on is True}
    try:
        with open("/proc/cpuinfo") as cpuinfo:
            return {flag for line in cpuinfo if line.startswith("flags") for flag in line.split(":", 1)[1].split()}
    except OSError:
        return set()


def has_native_bf16(device: torch.device | str = "cpu") -> bool:
    """Whether ``device`` multiplies bfloat16 matrices in hardware.

    A CPU needs ``avx512_bf16`` or ``amx_bf16``; a CUDA GPU, :func:`torch.cuda.is_bf16_supported`
    (Ampere and later). Elsewhere bfloat16 is emulated, slower than float32.

    Examples:
        >>> isinstance(has_native_bf16("cpu"), bool)
        True
    """
    device = torch.device(device)
    if device.type == "cuda":
        return torch.cuda.is_available() and torch.cuda.is_bf16_supported(including_emulation=False)
    if device.type == "cpu":
        return any(flag in _cpu_flags() for flag in _CPU_BF16_FLAGS)
    return False


@dataclasses.dataclass(frozen=True)
class LearnerPrecision:
    """The learner's matmul precision on its device.

    Args:
        dtype: ``torch.float32`` (exact, the default) or ``torch.bfloat16``.
        device_type: ``"cpu"`` or ``"cuda"``, where the learner runs.
    """

    dtype: torch.dtype = torch.float32
    device_type: str = "cpu"

    @classmethod
    def from_setting(cls, setting: str, device: torch.device | str = "cpu") -> LearnerPrecision:
        """``fp32``, ``bf16`` (refused without native bfloat16) or ``auto`` (bf16 where native, else fp32).

        Raises:
            PrecisionUnsupported: ``bf16`` on a device without native bfloat16 matmuls.
            ValueError: an unknown setting.
        """
        device = torch.device(device)
        if setting not in PRECISIONS:
            raise ValueError(f"precision={setting!r}: expected one of {', '.join(PRECISIONS)}.")
        native = setting != "fp32" and has_native_bf16(device)
        if setting == "bf16" and not native:
            raise PrecisionUnsupported(
                f"optim.precision=bf16: this {device.type.upper()} has no native bfloat16 matmuls "
                f"({'avx512_bf16 or amx_bf16' if device.type == 'cpu' else 'an Ampere or later GPU'}); "
                "use optim.precision=fp32, or auto (bf16 where the hardware has it).")
        return cls(torch.bfloat16 if native else torch.float32, device.type)

    @property
    def name(self) -> str:
        """``fp32`` or ``bf16``."""
        return "fp32" if self.dtype == torch.float32 else "bf16"

    def autocast(self) -> contextlib.AbstractContextManager:
        """The context for a forward pass: nothing at float32, autocast (with one weight cast per update) otherwise."""
        if self.dtype == torch.float32:
            return contextlib.nullcontext()
        return _autocast_with_weight_cache(self.device_type, self.dtype)


# ------------------------------------------------------------------------ the layers' side
_cache = threading.local()


@contextlib.contextmanager
def _autocast_with_weight_cache(device_type: str, dtype: torch.dtype) -> Iterator[None]:
    outer = getattr(_cache, "weights", None)
    _cache.weights = {} if outer is None else outer
    try:
        with torch.autocast(device_type, dtype=dtype):
            yield
    finally:
        _cache.weights = outer


def low_precision_dtype(like: torch.Tensor) -> torch.dtype | None:
    """The autocast dtype in force on ``like``'s device when it is lower than ``like``'s float32, else None.

    Examples:
        >>> low_precision_dtype(torch.zeros(1)) is None
        True
        >>> with torch.autocast("cpu", torch.bfloat16):
        ...     low_precision_dtype(torch.zeros(1))
        torch.bfloat16
    """
    device_type = like.device.type
    if not torch.is_autocast_enabled(device_type) or like.dtype != torch.float32:
        return None
    dtype = torch.get_autocast_dtype(device_type)
    return dtype if dtype in _LOW_PRECISION else None


def cast_weight(weight: torch.Tensor, dtype: torch.dtype) -> torch.Tensor:
    """``weight`` in ``dtype``; a parameter (a leaf) is cast once per :meth:`LearnerPrecision.autocast` block.

    The cast copy is reused, through one autograd node, by every evaluation of the block, so the
    forward casts and the gradient's cast back happen once per update instead of once per use.
    """
    cache = getattr(_cache, "weights", None)
    if cache is None or not weight.is_leaf:
        return weight.to(dtype)
    key = (id(weight), dtype)
    hit = cache.get(key)
    if hit is not None and hit[0] is weight and hit[1] == weight._version:
        return hit[2]
    cast = weight.to(dtype)
    cache[key] = (weight, weight._version, cast)
    return cast


def _output_layer(layer: nn.Linear, h: torch.Tensor) -> torch.Tensor:
    with torch.autocast(h.device.type, enabled=False):
        return layer(h.float())


def mlp_forward(mlp: nn.Sequential, x: torch.Tensor) -> torch.Tensor:
    """``mlp(x)``; under bfloat16 autocast, the hidden layers in bfloat16 and the last linear layer in float32.

    Examples:
        >>> from torchrl.modules import MLP
        >>> mlp = MLP(in_features=3, out_features=1, num_cells=[8])
        >>> with torch.autocast("cpu", torch.bfloat16):
        ...     mlp_forward(mlp, torch.randn(2, 3)).dtype
        torch.float32
    """
    dtype = low_precision_dtype(x)
    if dtype is None or not isinstance(mlp[-1], nn.Linear):
        return mlp(x)
    *hidden, output = mlp.children()
    h = x
    for layer in hidden:
        if isinstance(layer, nn.Linear):
            bias = None if layer.bias is None else cast_weight(layer.bias, dtype)
            h = torch.nn.functional.linear(h.to(dtype), cast_weight(layer.weight, dtype), bias)
        else:
            h = layer(h)
    return _output_layer(output, h)
