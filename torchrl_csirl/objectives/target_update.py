"""The target critics' soft update as one fused in-place blend.

TorchRL's :class:`~torchrl.objectives.SoftUpdate` blends each target TensorDict into place
(``target.lerp_(source, tau)``), walking its TensorDicts at every step. :class:`FusedSoftUpdate` does the
same blend of the same tensors in one ``torch._foreach_lerp_`` call, so its targets are bit-identical to the
stock ones (``tests/test_target_update.py``); what it saves is on the performance page
(``benchmarks/bench_target_update.py``). :class:`~torchrl.objectives.SoftUpdate` stays selectable
(``make_csirl_learner(..., fused_target_update=False)``).
"""
from __future__ import annotations

import torch
from torchrl.objectives import SoftUpdate

from torchrl_csirl._compat import soft_update_leaves

__all__ = ["FusedSoftUpdate"]


class FusedSoftUpdate(SoftUpdate):
    """:class:`~torchrl.objectives.SoftUpdate` whose ``step`` is one ``torch._foreach_lerp_`` over every target.

    Takes :class:`~torchrl.objectives.SoftUpdate`'s arguments (``loss_module``, ``tau`` or ``eps``) and keeps
    its state (``state_dict``); each step blends the tensors :class:`~torchrl.objectives.SoftUpdate`'s own step
    would, so it follows the loss module wherever the stock one does (a reload: ``tests/test_target_update.py``).

    Examples:
        >>> import torch
        >>> from torchrl_csirl.modules import make_actor, make_qvalue
        >>> from torchrl_csirl.objectives import EnsembleSACLoss, FusedSoftUpdate
        >>> loss = EnsembleSACLoss(make_actor(4, 2, hidden=(8,)), make_qvalue(4, 2, hidden=(8,)))
        >>> updater = FusedSoftUpdate(loss, tau=0.5)
        >>> before = loss.target_qvalue_network_params.data.clone()
        >>> _ = loss.qvalue_network_params.data.apply_(lambda x: x.add_(1.0))  # the critics move by 1
        >>> updater.step()  # the targets follow by tau
        >>> moved = loss.target_qvalue_network_params.data - before
        >>> [round(v.mean().item(), 3) for v in moved.values(True, True)]
        [0.5, 0.5, 0.5, 0.5]
    """

    def step(self) -> None:
        """Blends every target tensor towards its source by ``1 - eps`` (``tau``), in place."""
        if not self.initialized:
            raise RuntimeError(f"{type(self).__name__} must be initialized (init_()) before step()")
        targets, sources = self._leaves()
        if any(t.requires_grad for t in targets):
            raise RuntimeError("a target parameter is part of a graph")
        with torch.no_grad():
            torch._foreach_lerp_(targets, sources, 1 - self.eps)

    def _leaves(self) -> tuple[list[torch.Tensor], list[torch.Tensor]]:
        """The targets and sources, read once per ``init_()``: after it, the stock updater walks two locked
        TensorDicts whose tensors stay the same objects, so the lists are rebuilt only when those change."""
        pair = (self._targets, self._sources)
        cached = self.__dict__.get("_leaves_cache")
        if cached is None or cached[0][0] is not pair[0] or cached[0][1] is not pair[1]:
            cached = self.__dict__["_leaves_cache"] = (pair, soft_update_leaves(self))
        return cached[1]
