"""A :class:`~torchrl.envs.ParallelEnv` whose main process sleeps while its workers step.

TorchRL 0.14.1's ``ParallelEnv`` (with its default shared-memory buffers) waits for the workers
by spin-polling a shared "done" flag without ever yielding the CPU. With ``W`` workers that is
``W + 1`` busy processes: on a 2-core machine the spinning main process takes a core from the
workers, and 2 workers collect *no faster* than 1 (``benchmarks/bench_collection.py``).
:class:`YieldingParallelEnv` polls the same flags but sleeps ``poll_interval`` seconds between
polls, so the cores go to the workers. Everything else (buffers, resets, specs) is TorchRL's.
"""
from __future__ import annotations

import time
from typing import Any

from torchrl.envs import ParallelEnv

from torchrl_csirl._compat import check_parallel_env_internals

__all__ = ["YieldingParallelEnv"]

check_parallel_env_internals()  # the private ParallelEnv names the override below relies on


class YieldingParallelEnv(ParallelEnv):
    """``ParallelEnv`` that sleeps instead of spinning while waiting for its workers.

    Args:
        *args: as :class:`~torchrl.envs.ParallelEnv` (``num_workers``, ``create_env_fn``, ...).
        poll_interval: seconds slept between two polls of the workers' done flags, small against
            a driving scenario's step (docs/performance.md); the default 50 us adds at most the
            sleep overshoot per step. ``0`` yields the CPU (``time.sleep(0)``) between polls.
        **kwargs: as :class:`~torchrl.envs.ParallelEnv`.

    Examples:
        >>> from functools import partial
        >>> from torchrl_csirl.tasks import make_env
        >>> from torchrl_csirl.tasks.parallel import YieldingParallelEnv
        >>> env = YieldingParallelEnv(2, partial(make_env, "merge"))
        >>> env.rollout(3, break_when_any_done=False).batch_size
        torch.Size([2, 3])
        >>> env.close()
    """

    def __init__(self, *args: Any, poll_interval: float = 5e-5, **kwargs: Any) -> None:
        if poll_interval < 0:
            raise ValueError(f"poll_interval must be >= 0 seconds, got {poll_interval}.")
        super().__init__(*args, **kwargs)
        self.poll_interval = float(poll_interval)

    def _wait_for_workers(self, workers_range) -> None:
        if not getattr(self, "_internals_checked", False):
            check_parallel_env_internals(self)
            self._internals_checked = True
        if not self._use_buffers:  # the pipe mode already blocks in the OS
            return super()._wait_for_workers(workers_range)
        timeout = self.BATCHED_PIPE_TIMEOUT
        flags, index = self._shm_done_flags, self._worker_indices
        workers = list(workers_range)
        start = time.monotonic()
        polls = 0
        while not all(flags[index[i]] for i in workers):
            time.sleep(self.poll_interval)
            polls += 1
            if polls % 200 == 0:  # every ~10-20 ms: time limit and dead workers
                self._check_workers(workers, start, timeout)
        for i in workers:
            flags[index[i]] = 0

    def _check_workers(self, workers: list[int], start: float, timeout: float) -> None:
        if time.monotonic() - start > timeout:
            raise RuntimeError(
                f"Failed to run all workers within the {timeout} sec time limit. This threshold can be "
                "increased via the BATCHED_PIPE_TIMEOUT env variable."
            )
        for i in workers:
            if not self._shm_done_flags[self._worker_indices[i]] and not self._workers[i].is_alive():
                try:
                    self._shutdown_workers()
                finally:
                    raise RuntimeError(f"Cannot proceed, worker {i} dead.")
