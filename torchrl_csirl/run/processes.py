"""A local sweep's cell processes: found by pid files, stopped at a checkpoint on SIGTERM or Ctrl-C.

Each running cell of ``recipes/benchmark.py`` keeps ``<output-dir>/logs/<cell>.pid`` (its process id and
start time; a process id alone may be reused) while it runs, and the sweep keeps ``logs/sweep.pid``.
SIGTERM or SIGINT to the sweep (:class:`StopCellsOnSigterm`) marks the sweep as stopping (no further cell
starts), sends SIGTERM to every running cell (each checkpoints at its next batch boundary, as any
recipe does) and waits for them before the sweep exits with status 143 (130 for Ctrl-C).

Each cell runs in a session of its own (:func:`run_cell_process`): Ray puts a trial's worker in a process
group of its own and signals that whole group when the worker goes (a stopped trial, a raylet shutting
down), which would kill a cell in it before its checkpoint, and a terminal's Ctrl-C does not reach it either.
The sweep's one SIGTERM is the only stop a cell gets (a second signal would stop it at once, without a
checkpoint).
"""
from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import time
from collections.abc import Callable, Iterator
from typing import Any

__all__ = ["SweepBusyError", "StopCellsOnSigterm", "cell_pid_path", "process_start_time", "run_cell_process",
           "running_cells", "stop_running_cells", "tune_sigint_handler_off"]

SWEEP_PID, STOPPING = "sweep.pid", ".stopping"
#: Ray Tune's switch for its own SIGINT handler (``ray.tune.tune._setup_signal_catching``)
TUNE_SIGINT = "TUNE_DISABLE_SIGINT_HANDLER"


class SweepBusyError(RuntimeError):
    """Cells of a previous sweep of the same output folder still run (one line)."""


def cell_pid_path(log_path: str) -> str:
    """Where a running cell's process id is kept: beside its log (``logs/<cell>.pid``), while it runs.

    Examples:
        >>> cell_pid_path("runs/bench/logs/merge-bc-s0.log")
        'runs/bench/logs/merge-bc-s0.pid'
    """
    return os.path.splitext(log_path)[0] + ".pid"


def process_start_time(pid: int) -> str | None:
    """When process ``pid`` started (clock ticks since boot, ``/proc/<pid>/stat``); none if it is gone, a
    zombie (exited, not yet reaped: a cell whose Ray worker died first) or without ``/proc``. With the id, it
    names one process: ids are reused, start times are not.

    Examples:
        >>> process_start_time(os.getpid()) == process_start_time(os.getpid()) is not None
        True
    """
    try:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()  # the name before ")" may hold spaces
    except OSError:
        return None
    return fields[19] if len(fields) > 19 and fields[0] not in ("Z", "X") else None  # fields 3 and 22


def _write_pid(path: str, pid: int) -> None:
    tmp = f"{path}.tmp"
    with open(tmp, "w") as f:
        f.write(f"{pid} {process_start_time(pid)}\n")
    os.replace(tmp, path)


def _read_alive_pid(path: str) -> int | None:
    """The process id of a pid file if that process still runs, else None."""
    try:
        with open(path) as f:
            pid, started = f.read().split()
    except (OSError, ValueError):  # gone or half-written
        return None
    return int(pid) if process_start_time(int(pid)) == started else None


def running_cells(output_dir: str) -> dict[str, int]:
    """The cells of the sweep in ``output_dir`` running on this machine: cell name -> process id (Linux).

    Examples:
        >>> running_cells("no/such/sweep")
        {}
    """
    logs, cells = os.path.join(output_dir, "logs"), {}
    for name in sorted(os.listdir(logs)) if os.path.isdir(logs) else ():
        if name.endswith(".pid") and name != SWEEP_PID:
            pid = _read_alive_pid(os.path.join(logs, name))
            if pid is not None:
                cells[name[:-len(".pid")]] = pid
    return cells


def run_cell_process(command: list[str], log_path: str, *, env: dict[str, str], cwd: str) -> tuple[int, str]:
    """Runs one cell's recipe in a session of its own, its stderr appended to ``log_path``, its pid file
    beside it while it runs; returns (exit status, stdout). A sweep that is stopping starts no cell
    (:class:`RuntimeError`). Its own session keeps the signals of its Ray worker's process group and of a
    terminal's Ctrl-C away from it: the sweep stops it (:func:`stop_running_cells`).

    Examples:
        >>> import sys, tempfile
        >>> log = os.path.join(tempfile.mkdtemp(), "logs", "demo.log")
        >>> os.makedirs(os.path.dirname(log))
        >>> run_cell_process([sys.executable, "-c", "print(42)"], log, env=dict(os.environ), cwd=".")
        (0, '42\\n')
    """
    if os.path.exists(os.path.join(os.path.dirname(log_path), STOPPING)):
        raise RuntimeError(f"{log_path}: not started, the sweep is stopping")
    with open(log_path, "a") as log:
        log.write("$ " + " ".join(command) + "\n")
        log.flush()
        proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=log, text=True, env=env, cwd=cwd,
                                start_new_session=True)
        pid_path = cell_pid_path(log_path)
        _write_pid(pid_path, proc.pid)
        try:
            stdout, _ = proc.communicate()
        finally:
            os.remove(pid_path)
        log.write(stdout)
    return proc.returncode, stdout


def stop_running_cells(output_dir: str, *, timeout_s: float = 1800.0, poll_s: float = 2.0,
                       say: Callable[[str], Any] = print, reason: str = "SIGTERM") -> list[str]:
    """SIGTERM, once, to every running cell of the sweep in ``output_dir``, and to any that starts meanwhile
    (each checkpoints at its next batch boundary and exits); waits for them, at most ``timeout_s``.

    Args:
        output_dir: the sweep's output folder.
        timeout_s: the longest wait.
        poll_s: seconds between looks.
        say: where the one-line messages go.
        reason: what stops the sweep (the messages' first word: ``SIGTERM``, ``SIGINT``).

    Returns:
        the names of the cells still running.

    Examples:
        >>> stop_running_cells("no/such/sweep")
        []
    """
    signalled: set[str] = set()
    deadline = time.monotonic() + timeout_s
    while True:
        cells = running_cells(output_dir)
        for name in sorted(set(cells) - signalled):
            say(f"{reason}: stopping {name} (pid {cells[name]}) at its next checkpoint")
            try:
                os.kill(cells[name], signal.SIGTERM)
            except OSError:
                pass
            signalled.add(name)
        if not cells or time.monotonic() >= deadline:
            return sorted(cells)
        time.sleep(poll_s)


def _say(message: str) -> None:
    """One line on stderr without Python's buffered streams (safe in a signal handler)."""
    os.write(2, (message + "\n").encode())


class StopCellsOnSigterm:
    """Context manager around a local sweep: refuses to start while cells of an earlier sweep of
    ``output_dir`` still run, keeps ``logs/sweep.pid``, and on SIGTERM or SIGINT (Ctrl-C) stops the running
    cells at a checkpoint (:func:`stop_running_cells`), calls ``shutdown``, says in one line how to continue
    and exits with status 128 + the signal: 143, 130 (a second signal of either kind: at once).

    Enter it after ``ray.init``, which installs a SIGTERM handler of its own, and keep Ray Tune's SIGINT
    handler off (``TUNE_DISABLE_SIGINT_HANDLER=1``, :func:`tune_sigint_handler_off`): Tune's stops the
    trials, and Ray then kills their processes. The previous handlers come back on exit.

    Args:
        output_dir: the sweep's output folder.
        shutdown: called before the exit (e.g. ``ray.shutdown``).
        timeout_s: the longest wait for the cells.
        command: the command that continues the sweep, for the last line (default: "the same command").

    Raises:
        SweepBusyError: cells of an earlier sweep of ``output_dir`` still run.

    Examples:
        >>> import tempfile
        >>> out = tempfile.mkdtemp()
        >>> with StopCellsOnSigterm(out):
        ...     os.path.isfile(os.path.join(out, "logs", "sweep.pid"))
        True
        >>> os.path.exists(os.path.join(out, "logs", "sweep.pid"))
        False
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self, output_dir: str, shutdown: Callable[[], Any] = lambda: None, timeout_s: float = 1800.0,
                 command: str | None = None) -> None:
        self.logs = os.path.join(output_dir, "logs")
        self.output_dir, self.shutdown, self.timeout_s, self.command = output_dir, shutdown, timeout_s, command
        self._previous: dict[int, Any] = {}

    def __enter__(self) -> StopCellsOnSigterm:
        busy = running_cells(self.output_dir)
        if busy:
            raise SweepBusyError(f"{self.output_dir}: cells of an earlier sweep still run ("
                                 + ", ".join(f"{n} pid {p}" for n, p in busy.items())
                                 + "); stop them with SIGTERM (they checkpoint) or wait for them")
        os.makedirs(self.logs, exist_ok=True)
        for name in os.listdir(self.logs):  # pid files of processes gone (a killed worker leaves its own)
            if name.endswith(".pid") or name == STOPPING:
                os.remove(os.path.join(self.logs, name))
        _write_pid(os.path.join(self.logs, SWEEP_PID), os.getpid())
        self._previous = {signum: signal.signal(signum, self._handle) for signum in self.SIGNALS}
        return self

    def __exit__(self, *exc: Any) -> None:
        for signum, previous in self._previous.items():
            signal.signal(signum, previous if previous is not None else signal.SIG_DFL)
        for name in (SWEEP_PID, STOPPING):
            if os.path.exists(os.path.join(self.logs, name)):
                os.remove(os.path.join(self.logs, name))

    def _handle(self, signum: int, frame: Any) -> None:
        for other in self.SIGNALS:  # a second signal of either kind: at once
            signal.signal(other, signal.SIG_DFL)
        with open(os.path.join(self.logs, STOPPING), "w"):  # no cell starts from now on
            pass
        name = signal.Signals(signum).name
        left = stop_running_cells(self.output_dir, timeout_s=self.timeout_s, say=_say, reason=name)
        for pid in (pid for cell, pid in running_cells(self.output_dir).items() if cell in left):
            with contextlib.suppress(OSError):  # the second SIGTERM: at once (Ray's shutdown would kill it anyway)
                os.kill(pid, signal.SIGTERM)
        done = (f"not checkpointed within {self.timeout_s:.0f} s, stopped at once (the last round's checkpoint "
                f"kept): {' '.join(left)}" if left else "every running cell checkpointed")
        again = f"continue with: {self.command}" if self.command else "run the same command again to continue"
        _say(f"{name}: sweep stopped; {done}; {again}")
        self.shutdown()
        os._exit(128 + signum)  # not SystemExit: a loop the signal interrupted (Ray Tune's) would catch it


@contextlib.contextmanager
def tune_sigint_handler_off() -> Iterator[None]:
    """Ray Tune installs no SIGINT handler of its own inside (``TUNE_DISABLE_SIGINT_HANDLER=1``): on Ctrl-C
    Tune would stop its trials, and Ray kill their processes, before :class:`StopCellsOnSigterm` could
    checkpoint the cells.

    Examples:
        >>> with tune_sigint_handler_off():
        ...     os.environ["TUNE_DISABLE_SIGINT_HANDLER"]
        '1'
    """
    before = os.environ.get(TUNE_SIGINT)
    os.environ[TUNE_SIGINT] = "1"
    try:
        yield
    finally:
        if before is None:
            os.environ.pop(TUNE_SIGINT, None)
        else:
            os.environ[TUNE_SIGINT] = before
