"""Collector life cycle helpers: shutting a collector down, and saying in one line why a worker failed.

* :func:`shutdown_collector`: a TorchRL collector shut down so that the process can exit.
* :class:`WorkerErrorLog` / :func:`start_collector`: a worker that dies (an exception in its
  environment's factory, ``reset`` or ``step``, or a killed process) becomes one
  :class:`CollectorWorkerError` line in the main process, naming the worker and its error.
"""
from __future__ import annotations

import contextlib
import functools
import os
import shutil
import signal
import tempfile
import time
import traceback
import warnings
from collections.abc import Callable
from typing import Any

from torchrl.collectors import BaseCollector
from torchrl.envs import EnvBase

from torchrl_csirl._compat import collector_weight_sync_schemes, collector_worker_processes

__all__ = ["CollectorWorkerError", "WorkerErrorLog", "shutdown_collector", "start_collector"]


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
        >>> from torchrl_csirl.tasks import SCENARIOS, make_env
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


class CollectorWorkerError(RuntimeError):
    """A collector worker process failed: an exception in its environment (at start or in a step), or
    the process was killed. The message is one line naming the worker and its error."""


def _one_line(error: BaseException) -> str:
    """``Type: first line of the message`` (``Type`` alone without a message)."""
    lines = str(error).strip().splitlines()
    return f"{type(error).__name__}: {lines[0]}" if lines else type(error).__name__


def _write_error_line(folder: str, error: BaseException) -> None:
    """In a worker: ``<folder>/<pid>.txt`` gets the error's one-line description, then its traceback."""
    with contextlib.suppress(OSError):
        with open(os.path.join(folder, f"{os.getpid()}.txt"), "w") as f:
            f.write(_one_line(error) + "\n" + "".join(traceback.format_exception(error)))


def _reporting(folder: str, method: Callable[..., Any]) -> Callable[..., Any]:
    @functools.wraps(method)
    def call(*args: Any, **kwargs: Any) -> Any:
        try:
            return method(*args, **kwargs)
        except Exception as error:
            _write_error_line(folder, error)
            raise
    return call


def _build_reporting_errors(folder: str, factory: Callable[[], EnvBase]) -> EnvBase:
    """In a worker process: ``factory()``, with the errors of the build, of ``reset`` and of ``step``
    written to ``folder`` before they end the worker."""
    try:
        env = factory()
    except Exception as error:
        _write_error_line(folder, error)
        raise
    # the instance's own _step / _reset (EnvBase.step and reset call these): no subclass, no copy
    env._step = _reporting(folder, env._step)
    env._reset = _reporting(folder, env._reset)
    return env


class WorkerErrorLog:
    """Where a multi-process collector's workers write the error that ends them, so that the main
    process can say it in one line.

    TorchRL 0.14.1 reports a worker that died while collecting as ``At least one process failed:
    worker 0 (exit code 1)``, its error only in the worker's traceback. :meth:`wrap` makes a worker's
    environment factory write the error (of the build, ``reset`` or ``step``) into a file named by
    the worker's process id, and :meth:`describe` turns the collector's failure into one line: the
    worker, its error, or the signal that killed it.

    Examples:
        >>> from torchrl_csirl.tasks import env_factory
        >>> log = WorkerErrorLog()
        >>> env = log.wrap(env_factory("merge"))()  # in a worker process, as the collector calls it
        >>> env.rollout(2, break_when_any_done=False)["observation"].shape
        torch.Size([2, 25])
        >>> log.errors()
        {}
        >>> log.close()
    """

    exit_wait_s: float = 5.0
    """How long :meth:`describe` watches the workers after a broken pipe (a worker still exiting)."""

    def __init__(self) -> None:
        self.folder = tempfile.mkdtemp(prefix="csirl-worker-errors-")

    def wrap(self, factory: Callable[[], EnvBase]) -> Callable[[], EnvBase]:
        """``factory`` (picklable), building its environment so that its errors are written here."""
        return functools.partial(_build_reporting_errors, self.folder, factory)

    def errors(self) -> dict[int, str]:
        """process id -> the one-line error its worker wrote."""
        found = {}
        for name in os.listdir(self.folder) if os.path.isdir(self.folder) else ():
            with contextlib.suppress(OSError, ValueError):
                with open(os.path.join(self.folder, name)) as f:
                    found[int(name.split(".")[0])] = f.readline().strip()
        return found

    def describe(self, collector: BaseCollector | None, error: BaseException | None = None) -> str | None:
        """One line on the failed worker of ``collector``, or None when no worker failed.

        A worker's pipe can break (``ConnectionResetError``, ``EOFError``) while the process is still
        exiting; on such an error the workers are watched for up to :attr:`exit_wait_s` seconds
        before concluding that none failed.

        Args:
            collector: the collector (None: it failed while starting, ``error`` says how).
            error: the exception the collector raised.
        """
        dead = _dead_workers(collector)
        if not dead and isinstance(error, _BROKEN_PIPE_ERRORS):
            deadline = time.monotonic() + self.exit_wait_s
            while not dead and time.monotonic() < deadline:
                time.sleep(0.05)
                dead = _dead_workers(collector)
        written = self.errors()
        for index, pid, code in sorted(dead, key=lambda worker: _failure_rank(worker, written)):
            if pid in written:
                return f"collector worker {index} (pid {pid}) failed: {written[pid]}"
            if code < 0:
                return (f"collector worker {index} (pid {pid}) was killed by {signal.Signals(-code).name}; "
                        "no error of its own")
            return f"collector worker {index} (pid {pid}) exited with status {code} (its traceback is above)"
        if collector is None and error is not None:  # failed to start: TorchRL re-raises the worker's error
            return _failed_to_start(error, written)
        if written:
            pid, line = sorted(written.items())[0]
            return f"a collector worker (pid {pid}) failed: {line}"
        return None

    def close(self) -> None:
        """Removes the folder."""
        shutil.rmtree(self.folder, ignore_errors=True)


def _failure_rank(worker: tuple[int, int, int], written: dict[int, str]) -> int:
    """The order in which dead workers are described: the one that failed first, not the ones the teardown then
    stopped (SIGTERM): an error of its own, then a signal, then an exit status, then SIGTERM."""
    _, pid, code = worker
    if pid in written:
        return 0
    if code < 0:
        return 3 if -code == signal.SIGTERM else 1
    return 2


_BROKEN_PIPE_ERRORS = (EOFError, ConnectionError)  # ConnectionResetError, BrokenPipeError among them


def _dead_workers(collector: BaseCollector | None) -> list[tuple[int, int, int]]:
    """(worker index, pid, exit code) of each worker of ``collector`` that exited with a failure."""
    dead = []
    for index, proc in enumerate(collector_worker_processes(collector)):
        try:
            alive, code, pid = proc.is_alive(), proc.exitcode, proc.pid
        except ValueError:  # closed: TorchRL terminated it after another worker failed
            continue
        if not alive and code not in (None, 0):
            dead.append((index, pid, code))
    return dead


def _failed_to_start(error: BaseException, written: dict[int, str]) -> str:
    """The line of workers that failed to start: the error a worker wrote, else the one TorchRL re-raised."""
    return f"a collector worker failed to start: {sorted(written.items())[0][1] if written else _one_line(error)}"


def _collector_being_built(error: BaseException) -> BaseCollector | None:
    """The collector whose ``__init__`` raised ``error`` (found in the traceback's frames), if any."""
    tb, found = error.__traceback__, None
    while tb is not None:
        candidate = tb.tb_frame.f_locals.get("self")
        if isinstance(candidate, BaseCollector):
            found = candidate
        tb = tb.tb_next
    return found


def start_collector(make: Callable[[], BaseCollector], errors: WorkerErrorLog | None = None) -> BaseCollector:
    """``make()``, a multi-process collector whose workers may fail to start: then the half-built
    collector is shut down (its weight-sync schemes would otherwise hang the process at exit) and a
    :class:`CollectorWorkerError` names the worker's error in one line (read from ``errors``, when the
    workers' factories were wrapped by it, or from the error TorchRL re-raises).

    Examples:
        >>> from functools import partial
        >>> from torchrl.collectors import Collector
        >>> def broken():
        ...     raise ValueError("no such track")
        >>> log = WorkerErrorLog()
        >>> start_collector(partial(Collector, log.wrap(broken), None, frames_per_batch=10, total_frames=10), log)
        Traceback (most recent call last):
        ...
        torchrl_csirl.trainers.collection.CollectorWorkerError: a collector worker failed to start: ValueError: no such track
        >>> log.close()
    """
    try:
        return make()
    except Exception as error:
        half_built = _collector_being_built(error)
        if half_built is not None:
            with contextlib.suppress(Exception):
                shutdown_collector(half_built)
        line = errors.describe(None, error) if errors is not None else _failed_to_start(error, {})
        raise CollectorWorkerError(line) from None
