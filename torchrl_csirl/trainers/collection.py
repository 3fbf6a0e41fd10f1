"""Collector life cycle helpers."""
from __future__ import annotations

import warnings

from torchrl.collectors import BaseCollector

from torchrl_csirl._compat import collector_weight_sync_schemes

__all__ = ["shutdown_collector"]


def shutdown_collector(collector: BaseCollector) -> None:
    """Shut a TorchRL collector down, its weight-sync schemes included.

    TorchRL 0.14.1's multi-process collectors (``Collector(..., num_collectors=W)``) leave their
    weight-sync schemes (the shared-memory policy weights) running after ``shutdown()``; the
    schemes shut themselves down in ``__del__``, which at interpreter exit starts a queue thread
    and hangs the process forever after the work is done. Shutting them down here, while the
    interpreter is alive, lets the process exit. For a single-process collector this is just
    ``collector.shutdown()``. Calling it twice is harmless.

    Args:
        collector: any TorchRL collector.

    Examples:
        >>> from torchrl.collectors import Collector
        >>> from torchrl_csirl.envs import SCENARIOS, make_env
        >>> from torchrl_csirl.modules import make_actor
        >>> spec = SCENARIOS["merge"]
        >>> collector = Collector(make_env("merge"), make_actor(spec.obs_dim, spec.action_dim),
        ...                       frames_per_batch=10, total_frames=10)
        >>> next(iter(collector)).numel()
        10
        >>> shutdown_collector(collector)
    """
    try:
        collector.shutdown()
    finally:
        for name, scheme in collector_weight_sync_schemes(collector).items():
            try:
                scheme.shutdown()
            except Exception as error:  # keep shutting the others down
                warnings.warn(f"weight-sync scheme {name!r} failed to shut down: {error}", stacklevel=2)
