"""A local sweep's cell processes: found by pid files, stopped at a checkpoint on SIGTERM.

Each running cell of ``recipes/benchmark.py`` keeps ``<output-dir>/logs/<cell>.pid`` (its process id and
start time; a process id alone may be reused) while it runs, and the sweep keeps ``logs/sweep.pid``.
SIGTERM to the sweep (:class:`StopCellsOnSigterm`) marks the sweep as stopping (no further cell
starts), sends SIGTERM to every running cell (each checkpoints at its next batch boundary, as any
recipe does) and waits for them before the sweep exits with status 143.
"""
from __future__ import annotations

import os
import signal
import subprocess
import time
from collections.abc import Callable
from typing import Any

__all__ = ["SweepBusyError", "StopCellsOnSigterm", "cell_pid_path", "process_start_time", "run_cell_process",
           "running_cells", "stop_running_cells"]

SWEEP_PID, STOPPING = "sweep.pid", ".stopping"


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
    """When process ``pid`` started (clock ticks since boot, ``/proc/<pid>/stat``); none if it is gone (or
    without ``/proc``). With the id, it names one process: ids are reused, start times are not.

    Examples:
        >>> process_start_time(os.getpid()) == process_start_time(os.getpid()) is not None
        True
    """
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[19]  # field 22; the name before ")" may hold spaces
    except (OSError, IndexError):
        return None


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
    """Runs one cell's recipe, its stderr appended to ``log_path``, its pid file beside it while it runs;
    returns (exit status, stdout). A sweep that is stopping starts no cell (:class:`RuntimeError`).

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
        proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=log, text=True, env=env, cwd=cwd)
        pid_path = cell_pid_path(log_path)
        _write_pid(pid_path, proc.pid)
        try:
            stdout, _ = proc.communicate()
        finally:
            os.remove(pid_path)
        log.write(stdout)
    return proc.returncode, stdout


def stop_running_cells(output_dir: str, *, timeout_s: float = 1800.0, poll_s: float = 2.0,
                       say: Callable[[str], Any] = print) -> list[str]:
    """SIGTERM to every running cell of the sweep in ``output_dir``, and to any that starts meanwhile (each
    checkpoints at its next batch boundary and exits); waits for them, at most ``timeout_s``.

    Args:
        output_dir: the sweep's output folder.
        timeout_s: the longest wait.
        poll_s: seconds between looks.
        say: where the one-line messages go.

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
            say(f"SIGTERM: stopping {name} (pid {cells[name]}) at its next checkpoint")
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
    ``output_dir`` still run, keeps ``logs/sweep.pid``, and on SIGTERM stops the running cells at a
    checkpoint, then calls ``shutdown`` and exits with status 143 (a second SIGTERM: at once). Enter it
    after ``ray.init``, which installs a handler of its own; the previous handler comes back on exit.

    Args:
        output_dir: the sweep's output folder.
        shutdown: called before the exit (e.g. ``ray.shutdown``).
        timeout_s: the longest wait for the cells.

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

    def __init__(self, output_dir: str, shutdown: Callable[[], Any] = lambda: None, timeout_s: float = 1800.0) -> None:
        self.logs = os.path.join(output_dir, "logs")
        self.output_dir, self.shutdown, self.timeout_s = output_dir, shutdown, timeout_s
        self._previous: Any = None

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
        self._previous = signal.signal(signal.SIGTERM, self._handle)
        return self

    def __exit__(self, *exc: Any) -> None:
        signal.signal(signal.SIGTERM, self._previous)
        for name in (SWEEP_PID, STOPPING):
            if os.path.exists(os.path.join(self.logs, name)):
                os.remove(os.path.join(self.logs, name))

    def _handle(self, signum: int, frame: Any) -> None:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)  # a second SIGTERM: at once
        with open(os.path.join(self.logs, STOPPING), "w"):  # no cell starts from now on
            pass
        left = stop_running_cells(self.output_dir, timeout_s=self.timeout_s, say=_say)
        _say("SIGTERM: sweep stopped" + (f"; still running: {' '.join(left)}" if left else
                                         "; every running cell checkpointed") + "; run the same command again to continue")
        self.shutdown()
        os._exit(128 + signum)  # not SystemExit: a loop the signal interrupted (Ray Tune's) would catch it
