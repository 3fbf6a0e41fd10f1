"""Collector life cycle helpers."""
from __future__ import annotations

from typing import Any

__all__ = ["shutdown_collector"]


def shutdown_collector(collector: Any) -> None:
    """Shut a TorchRL collector down, its weight-sync schemes included.

    TorchRL 0.14.1's multi-process collectors (``Collector(..., num_collectors=W)``) leave their
    weight-sync schemes (shared-memory policy weights) running after ``shutdown()``; the
    schemes shut themselves down in ``__del__``, which at interpreter exit starts a queue thread
    and hangs the process forever after the work is done. Shutting them down here, while the
    interpreter is alive, lets the process exit. For single-process collectors this is just
    ``collector.shutdown()``.

    Examples:
        >>> from functools import partial
        >>> from torchrl.collectors import Collector
        >>> from torchrl_csirl.envs import SCENARIOS, make_serial_env
        >>> from torchrl_csirl.modules import make_actor
        >>> spec = SCENARIOS["merge"]
        >>> collector = Collector([partial(make_serial_env, "merge", 1)] * 2, make_actor(spec.obs_dim, spec.action_dim),
        ...                       num_collectors=2, sync=True, frames_per_batch=20, total_frames=20)
        >>> next(iter(collector)).numel()
        20
        >>> shutdown_collector(collector)
    """
    try:
        collector.shutdown()
    finally:
        schemes = getattr(collector, "_weight_sync_schemes", None) or {}
        for scheme in schemes.values():
            scheme.shutdown()
