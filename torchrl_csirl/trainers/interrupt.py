"""Stopping a training run on SIGTERM / Ctrl-C at a consistent point, so that it can be checkpointed.

* :class:`StopOnSignals`: while training, the first SIGINT or SIGTERM asks the trainer to stop at
  the end of the current batch (:meth:`~torchrl_csirl.trainers.CSIRLTrainer.request_stop`, then
  :class:`~torchrl_csirl.trainers.TrainingInterrupted`); a second one goes to the handler installed before
  (Python's for Ctrl-C: ``KeyboardInterrupt``) or, where that is not a function, exits at once.
* :func:`ignoring_interrupts`: a collector worker's environment factory whose worker ignores SIGINT.
  Ctrl-C in a terminal reaches the whole process group; the workers must keep collecting until the
  main process, which owns their shutdown, has finished the batch.
"""
from __future__ import annotations

import multiprocessing
import os
import signal
from collections.abc import Callable
from functools import partial
from typing import Any

__all__ = ["StopOnSignals", "ignoring_interrupts"]


class StopOnSignals:
    """Context manager: SIGINT / SIGTERM ask ``trainer`` to stop at its next batch boundary.

    The first signal sets the trainer's stop request (its name as the reason) and writes one line to
    stderr; the second one of either kind runs the handler that was there before (SIGINT: Ctrl-C's
    ``KeyboardInterrupt``; a default SIGTERM: exit status 143). The previous handlers come back on exit.
    Only the main thread may install handlers; elsewhere this does nothing.

    Args:
        trainer: anything with ``request_stop(reason)`` (a :class:`~torchrl_csirl.trainers.CSIRLTrainer`).
        signals: the signals to catch.

    Examples:
        >>> class Trainer:
        ...     stop_reason = None
        ...     def request_stop(self, reason):
        ...         self.stop_reason = reason
        >>> trainer = Trainer()
        >>> with StopOnSignals(trainer, message=False) as stop:
        ...     os.kill(os.getpid(), signal.SIGTERM)
        >>> trainer.stop_reason, stop.signum
        ('SIGTERM', 15)
    """

    def __init__(self, trainer: Any, signals: tuple[int, ...] = (signal.SIGINT, signal.SIGTERM),
                 message: bool = True) -> None:
        self.trainer = trainer
        self.signals = tuple(signals)
        self.message = message
        self.signum: int | None = None
        self._previous: dict[int, Any] = {}

    def _handle(self, signum: int, frame: Any) -> None:
        if self.signum is not None:  # the second signal: the handler installed before, else exit
            previous = self._previous.get(signum)
            if callable(previous):
                previous(signum, frame)
                return
            raise SystemExit(128 + signum)
        self.signum = signum
        name = signal.Signals(signum).name
        self.trainer.request_stop(name)
        if self.message:  # os.write: safe inside a handler (print may be mid-write on the same stream)
            os.write(2, f"\n{name}: stopping after the current batch to save a checkpoint "
                        f"({name} again stops at once, keeping the last round's checkpoint)\n".encode())

    def __enter__(self) -> StopOnSignals:
        try:
            for signum in self.signals:
                self._previous[signum] = signal.signal(signum, self._handle)
        except ValueError:  # not the main thread
            self._restore()
        return self

    def _restore(self) -> None:
        for signum, previous in self._previous.items():
            signal.signal(signum, previous if previous is not None else signal.SIG_DFL)
        self._previous = {}

    def __exit__(self, *exc: Any) -> None:
        self._restore()


def _ignore_sigint_then(factory: Callable[[], Any]) -> Any:
    if multiprocessing.parent_process() is not None:  # a worker process, never the main one
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    return factory()


def ignoring_interrupts(factory: Callable[[], Any]) -> Callable[[], Any]:
    """``factory`` (a collector worker's environment factory), made to ignore SIGINT in the worker
    process that calls it; picklable when ``factory`` is. Called in the main process it only builds.

    Examples:
        >>> ignoring_interrupts(lambda: "env")()
        'env'
    """
    return partial(_ignore_sigint_then, factory)
