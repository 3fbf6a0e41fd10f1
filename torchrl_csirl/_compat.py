"""Every reach into TorchRL internals, in one place.

torchrl-csirl sometimes needs behaviour that TorchRL 0.14.1 only offers through private methods or
attributes (a loss's critic target, a collector's weight-sync schemes, a wrapped gym env). Each such
reach is a small named function here, and ``tests/test_compat.py`` pins the behaviour we rely on, so
a TorchRL upgrade that changes it fails there, in one visible place, instead of deep in a run.
Where a private method must be *overridden* (``SACLoss._compute_target_v2``,
``SACLoss._cached_detached_qvalue_params``, ``ParallelEnv._wait_for_workers``), the subclass keeps
the override and calls a ``check_*`` function below when it is defined, so a rename fails at import.

Everything else in the package uses TorchRL's public API.
"""
from __future__ import annotations

import inspect
import sys
from typing import Any

import torch
from tensordict import TensorDictBase
from torchrl.envs import EnvBase, ParallelEnv
from torchrl.modules.distributions.utils import safetanh_noeps as _safetanh_noeps
from torchrl.objectives import SACLoss
from torchrl.objectives.utils import TargetNetUpdater

__all__ = [
    "check_parallel_env_internals",
    "check_sac_internals",
    "collector_weight_sync_schemes",
    "collector_worker_processes",
    "detached_qvalue_params",
    "gym_env_of",
    "replay_buffer_prefetch",
    "sac_alpha",
    "sac_reduce_loss",
    "sac_reduced_alpha_loss",
    "safe_tanh",
    "sampling_replay_buffer",
    "set_qvalue_ensemble_evaluator",
    "soft_update_leaves",
    "vmap_qvalue_networks",
]


class TorchRLInternalsChanged(RuntimeError):
    """A private TorchRL name we rely on is gone or changed (see torchrl_csirl/_compat.py)."""


def _require(condition: bool, what: str) -> None:
    if not condition:
        raise TorchRLInternalsChanged(f"TorchRL changed: {what}. Update torchrl_csirl/_compat.py.")


# ------------------------------------------------------------------------------ objectives (SACLoss)
def check_sac_internals() -> None:
    """The SACLoss internals :class:`~torchrl_csirl.objectives.EnsembleSACLoss` overrides.

    * ``_compute_target_v2(tensordict)``: the critic target (overridden to keep the graph of a
      differentiable reward);
    * ``_cached_detached_qvalue_params``: a property, the critic parameters the actor loss uses
      (overridden to evaluate the actor loss with graph-carrying critic parameters);
    * ``_make_vmap(self)``: builds the critic-ensemble evaluator ``_vmap_qnetworkN0`` (overridden
      to install a fused evaluator, :func:`set_qvalue_ensemble_evaluator`).
    """
    target = getattr(SACLoss, "_compute_target_v2", None)
    _require(callable(target) and list(inspect.signature(target).parameters) == ["self", "tensordict"],
             "SACLoss._compute_target_v2(self, tensordict) is gone or has a new signature")
    _require(isinstance(inspect.getattr_static(SACLoss, "_cached_detached_qvalue_params", None), property),
             "SACLoss._cached_detached_qvalue_params is no longer a property")
    make_vmap = getattr(SACLoss, "_make_vmap", None)
    _require(callable(make_vmap) and list(inspect.signature(make_vmap).parameters) == ["self"],
             "SACLoss._make_vmap(self) is gone or has a new signature")


def set_qvalue_ensemble_evaluator(loss: SACLoss, evaluator: Any) -> None:
    """Makes ``evaluator(tensordict, params)`` SACLoss's evaluator of the ``[N]`` stacked critics.

    SACLoss evaluates its critics in the critic loss, the actor loss and the critic target
    through one attribute, ``_vmap_qnetworkN0`` (``torch.vmap(qvalue_network, (None, 0))``,
    built by ``_make_vmap``). Call this from an override of ``_make_vmap``, after SACLoss's.
    """
    _require(hasattr(loss, "_vmap_qnetworkN0"), "SACLoss no longer builds _vmap_qnetworkN0 in _make_vmap")
    loss._vmap_qnetworkN0 = evaluator


def detached_qvalue_params(loss: SACLoss) -> TensorDictBase:
    """SACLoss's own (cached, detached) critic parameters of the actor loss."""
    return SACLoss._cached_detached_qvalue_params.fget(loss)


def vmap_qvalue_networks(loss: SACLoss, tensordict: TensorDictBase, params: TensorDictBase) -> TensorDictBase:
    """The critic evaluated with each of the ``[N]`` stacked parameter sets (SACLoss's vmap)."""
    return loss._vmap_qnetworkN0(tensordict, params)


def sac_alpha(loss: SACLoss) -> torch.Tensor:
    """The current entropy coefficient (``exp(log_alpha)`` clamped, no grad)."""
    return loss._alpha


def sac_reduced_alpha_loss(loss: SACLoss, log_prob: torch.Tensor, tensordict: TensorDictBase) -> torch.Tensor:
    """The temperature loss reduced as SACLoss's ``forward`` reduces it (priority weights included)."""
    return sac_reduce_loss(loss, loss.alpha_loss(log_prob), tensordict)


def sac_reduce_loss(loss: SACLoss, value: torch.Tensor, tensordict: TensorDictBase) -> torch.Tensor:
    """A per-sample loss reduced as SACLoss's losses reduce theirs (priority weights, masks, reduction)."""
    weights = loss._maybe_get_priority_weight(tensordict)
    return loss._reduce_loss(value, tensordict=tensordict, weights=weights)


def soft_update_leaves(updater: TargetNetUpdater) -> tuple[list[torch.Tensor], list[torch.Tensor]]:
    """The target and source parameter tensors a target-network updater blends, paired in one order.

    TorchRL 0.14.1's :class:`~torchrl.objectives.TargetNetUpdater` keeps them (after ``init_()``) as two
    TensorDicts, ``_targets`` (keys ``target_<name>``) and ``_sources`` (keys ``<name>``), each holding the
    loss module's own tensors; its ``step`` walks them pair by pair.
    """
    _require(hasattr(updater, "_sources") and hasattr(updater, "_targets"),
             "TargetNetUpdater no longer keeps _sources/_targets")
    targets, sources = [], []
    for name, source in updater._sources.items():
        target = updater._targets.get(f"target_{name}")
        if isinstance(source, torch.Tensor):
            sources.append(source)
            targets.append(target)
            continue
        keys = list(source.keys(True, True))
        sources.extend(source.get(k) for k in keys)
        targets.extend(target.get(k) for k in keys)
    return targets, sources


def safe_tanh(x: torch.Tensor) -> torch.Tensor:
    """TorchRL's ``TanhNormal`` squashing: ``tanh(x)`` clamped to ``[-1 + r, 1 - r]`` (``r`` the dtype's resolution).

    The autograd function ``SafeTanhTransform`` applies (``safetanh_noeps``, whose backward is
    ``grad * (1 - tanh^2)`` of the clamped output).
    """
    return _safetanh_noeps(x)


# ------------------------------------------------------------------------------ collectors and envs
def collector_weight_sync_schemes(collector: Any) -> dict[str, Any]:
    """The weight-sync schemes a multi-process collector keeps (empty for others).

    TorchRL 0.14.1's multi-process collectors leave them running after ``shutdown()``; see
    :func:`~torchrl_csirl.trainers.shutdown_collector`.
    """
    return dict(getattr(collector, "_weight_sync_schemes", None) or {})


def collector_worker_processes(collector: Any) -> list[Any]:
    """The worker processes of a multi-process collector (``procs``; empty for others), in worker order.

    TorchRL 0.14.1 checks them only for a non-zero exit (``At least one process failed: worker i``),
    without the worker's own error; :class:`~torchrl_csirl.trainers.WorkerErrorLog` names it.
    """
    return list(getattr(collector, "procs", None) or [])


# ------------------------------------------------------------------------------ replay buffers
def sampling_replay_buffer(max_frames: int = 16) -> Any:
    """The replay buffer whose sampling runs the caller (a buffer transform's ``forward``), or None.

    TorchRL 0.14.1 applies a buffer's transform in ``ReplayBuffer._sample``, which a buffer with
    ``prefetch`` runs ahead of time on its prefetch thread; the transform itself is not told which
    buffer calls it. The caller's stack is searched for that ``_sample`` frame (``max_frames`` up).
    """
    from torchrl.data import ReplayBuffer

    frame = sys._getframe(1)
    for _ in range(max_frames):
        frame = frame.f_back
        if frame is None:
            return None
        if frame.f_code.co_name == "_sample":
            owner = frame.f_locals.get("self")
            if isinstance(owner, ReplayBuffer):
                return owner
    return None


def replay_buffer_prefetch(buffer: Any) -> int:
    """How many batches a replay buffer prefetches on its threads (``prefetch``; 0: none)."""
    return int(getattr(buffer, "_prefetch_cap", 0) or 0)


_PARALLEL_ENV_NAMES = ("_wait_for_workers", "_shutdown_workers")
_PARALLEL_ENV_STARTED_NAMES = ("_use_buffers", "_shm_done_flags", "_worker_indices", "_workers", "BATCHED_PIPE_TIMEOUT")


def check_parallel_env_internals(env: ParallelEnv | None = None) -> None:
    """The ParallelEnv internals :class:`~torchrl_csirl.tasks.YieldingParallelEnv` relies on.

    Class level (checked at import): ``_wait_for_workers(workers_range)``, ``_shutdown_workers``.
    With a started ``env``: ``_use_buffers``, ``_shm_done_flags`` (one flag per worker, set by a
    worker when its step is done), ``_worker_indices``, ``_workers``, ``BATCHED_PIPE_TIMEOUT``.
    """
    for name in _PARALLEL_ENV_NAMES:
        _require(hasattr(ParallelEnv, name), f"ParallelEnv.{name} is gone")
    wait = ParallelEnv._wait_for_workers
    _require(list(inspect.signature(wait).parameters) == ["self", "workers_range"],
             "ParallelEnv._wait_for_workers(self, workers_range) has a new signature")
    if env is not None:
        for name in _PARALLEL_ENV_STARTED_NAMES:
            _require(hasattr(env, name), f"a started ParallelEnv has no {name}")


def gym_env_of(env: EnvBase) -> Any:
    """The gymnasium env a TorchRL ``GymEnv`` / ``GymWrapper`` wraps (no public accessor in 0.14.1).

    Examples:
        >>> from torchrl_csirl.tasks import make_env
        >>> env = make_env("merge")
        >>> type(gym_env_of(env).unwrapped).__name__
        'CSIRLMergeEnv'
    """
    base = getattr(env, "base_env", env)
    inner = getattr(base, "_env", None)
    _require(inner is not None, f"{type(base).__name__} has no _env (the wrapped gym env)")
    return inner
