"""One update, one pass of each input map per batch.

An update maps the same observations several times: an SAC update reads the batch's observations
through the critics (their loss, the actor's loss) and the actor, a CSIRL iteration through the
critics, the actor and the reward network, before and after the inner steps. The input maps
(:class:`~torchrl_csirl.modules.EgoRelativeFeatures`, :class:`~torchrl_csirl.modules.LaneFeatures`)
have no parameters, so each of those passes computes the same tensor. Inside
:func:`map_each_input_once` a map computes once per input tensor and hands the same output to every
later call with that tensor; outside it, every call computes. The trainer opens it around each
update (:class:`~torchrl_csirl.trainers.CSIRLTrainer`), where nothing writes to a sampled batch.

What is reused is the very tensor the map would compute again, so losses and gradients are unchanged
bit for bit (``tests/test_input_memo.py``). A call is computed afresh when its input requires grad, is an
inference tensor or a functorch-wrapped one, when inference mode is on, under tracing or
``torch.compile``, and when the input or the earlier output has been written in place since
(autograd's version counter).
"""
from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable, Iterator

import torch
from torch import nn

__all__ = ["map_each_input_once", "mapped_once"]

_scope = threading.local()


@contextlib.contextmanager
def map_each_input_once() -> Iterator[None]:
    """Within the block, each input map computes once per distinct input tensor (in this thread).

    Nested blocks share the outermost one's memo; it is dropped (with its references to the inputs and
    outputs) when that block ends.

    Examples:
        >>> import torch
        >>> from torchrl_csirl.modules import EgoRelativeFeatures
        >>> feats = EgoRelativeFeatures(3, 3, relative_indices=[1], gains=[10.0])
        >>> obs = torch.rand(4, 9)
        >>> with map_each_input_once():
        ...     feats(obs) is feats(obs)
        True
        >>> feats(obs) is feats(obs)  # outside the block every call computes
        False
    """
    if getattr(_scope, "memo", None) is not None:
        yield
        return
    _scope.memo = {}
    try:
        yield
    finally:
        _scope.memo = None


def _reusable(x: torch.Tensor) -> bool:
    """Whether an output computed from ``x`` may be handed to a later call (see the module docstring)."""
    return not (
        x.requires_grad
        or x.is_inference()
        or torch.is_inference_mode_enabled()
        or torch.compiler.is_compiling()
        or torch.jit.is_tracing()
        or torch._C._functorch.is_functorch_wrapped_tensor(x)
    )


def mapped_once(module: nn.Module, compute: Callable[[torch.Tensor], torch.Tensor], x: torch.Tensor) -> torch.Tensor:
    """``compute(x)``, or, inside :func:`map_each_input_once`, the output ``module`` computed from this ``x`` earlier.

    Args:
        module: the input map (the memo's key, with ``x``).
        compute: the map's computation, a pure function of ``x``.
        x: the input tensor.

    Examples:
        >>> import torch
        >>> from torch import nn
        >>> calls = []
        >>> def double(x):
        ...     calls.append(1)
        ...     return 2 * x
        >>> m, x = nn.Identity(), torch.ones(2)
        >>> with map_each_input_once():
        ...     _ = mapped_once(m, double, x), mapped_once(m, double, x)
        >>> len(calls)
        1
    """
    memo = getattr(_scope, "memo", None)
    if memo is None or not _reusable(x):
        return compute(x)
    key = (id(module), id(x))
    hit = memo.get(key)
    # the entry keeps ``module`` and ``x`` alive, so their ids cannot be reused by other objects in the block
    if hit is not None and hit[1] is x and hit[2] == x._version and hit[4] == hit[3]._version:
        return hit[3]
    out = compute(x)
    if not out.requires_grad:
        memo[key] = (module, x, x._version, out, out._version)
    return out
