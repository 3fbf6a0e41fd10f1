"""Stopping a local sweep (recipes/benchmark.py) mid-cell: Ctrl-C or SIGTERM checkpoints every running cell
before the sweep exits, and the same command continues the unfinished cells without running a finished one
again (issue 88, item 3)."""
from __future__ import annotations

import json
import os
import shlex
import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Callable

import pytest
import torch
from run_logs import metrics_rows

from torchrl_csirl.run.processes import run_cell_process, running_cells
from torchrl_csirl.scripts import benchmark

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ENV = {**os.environ, "WANDB_MODE": "offline", "MPLBACKEND": "Agg", "RL_WARNINGS": "0"}
# 100-frame batches collected in the main process, every cell on one test episode; CSIRL's cell: one round
# that never ends before its budget (no round checkpoint: the stop writes the only one), 20 batches
TINY = ["collector.frames_per_batch=100", "collector.cut_episodes=true", "collector.init_random_frames=100",
        "collector.num_workers=1", "collector.main_threads=1", "eval.episodes=1", "eval.final_episodes=1",
        "eval.video=false", "logger.backend=none", "csirl:replay_buffer.warmup_frames=100",
        "csirl:replay_buffer.batch_size=32", "csirl:csirl.updates_per_round=10000", "csirl:csirl.num_qvalue_nets=2",
        "csirl:optim.utd_ratio=0.1", "collector.total_frames=2000"]


def _log(out: str, cell: str) -> str:
    with open(os.path.join(out, "logs", f"{cell}.log")) as f:
        return f.read()


def _wait_for(proc: subprocess.Popen, ready: Callable[[], bool], timeout_s: float) -> None:
    """Waits until ``ready()`` with ``proc`` still running (it is killed on a failure)."""
    try:
        deadline = time.monotonic() + timeout_s
        while not ready() and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.1)
        assert proc.poll() is None and ready(), f"it ended before it could be stopped:\n{proc.stderr.read()[-3000:]}"
    except BaseException:
        os.killpg(proc.pid, signal.SIGKILL)
        raise


def _stop(proc: subprocess.Popen, how: str, timeout_s: float = 240) -> tuple[str, str]:
    """Ctrl-C as a terminal sends it (SIGINT to the whole process group), or a signal to the sweep alone."""
    if how == "ctrl-c":
        os.killpg(proc.pid, signal.SIGINT)
    else:
        proc.send_signal(signal.SIGINT if how == "sigint" else signal.SIGTERM)
    try:
        return proc.communicate(timeout=timeout_s)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)


def test_a_cell_runs_in_a_session_of_its_own(tmp_path):
    # neither a terminal's Ctrl-C (its foreground process group) nor Ray's clean-up of a trial worker's process
    # group reaches it: the sweep stops it, with one SIGTERM
    log = str(tmp_path / "cell.log")
    status, stdout = run_cell_process([sys.executable, "-c", "import os; print(os.getsid(0) == os.getpid())"], log,
                                      env=dict(os.environ), cwd=ROOT)
    assert (status, stdout) == (0, "True\n")


# a stand-in for a sweep's driver and one cell, without Ray: the cell counts its signals, checkpoints on the
# first SIGTERM ("stop at once" on a second stop signal, as a recipe does) and the driver waits for it
FAKE_SWEEP = textwrap.dedent("""
    import os, signal, sys, time
    from torchrl_csirl.run.processes import StopCellsOnSigterm, run_cell_process
    out = sys.argv[1]
    cell = ("import signal, sys, time\\n"
            "got = []\\n"
            "def stop(signum, frame):\\n"
            "    got.append(signal.Signals(signum).name)\\n"
            "    if len(got) > 1: sys.exit(9)\\n"
            "signal.signal(signal.SIGINT, stop); signal.signal(signal.SIGTERM, stop)\\n"
            "print('started', file=sys.stderr, flush=True)\\n"
            "while not got: time.sleep(0.05)\\n"
            "time.sleep(1)  # the batch's end\\n"
            "print('checkpoint after', ' '.join(got), file=sys.stderr, flush=True)\\n"
            "sys.exit(128 + signal.SIGTERM)\\n")
    with StopCellsOnSigterm(out, command="python again"):
        run_cell_process([sys.executable, "-c", cell], os.path.join(out, "logs", "cell.log"), env=dict(os.environ), cwd=".")
""")


@pytest.mark.parametrize("how, status", [("ctrl-c", 130), ("sigint", 130), ("sigterm", 143)])
def test_a_stopped_sweep_stops_each_running_cell_once_and_waits_for_its_checkpoint(tmp_path, how, status):
    out = str(tmp_path / "sweep")
    proc = subprocess.Popen([sys.executable, "-c", FAKE_SWEEP, out], cwd=ROOT, env=ENV, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    log = os.path.join(out, "logs", "cell.log")
    _wait_for(proc, lambda: os.path.exists(log) and "\nstarted\n" in _log(out, "cell"), 60)  # its handlers in place
    _, err = _stop(proc, how, timeout_s=60)
    name = "SIGTERM" if how == "sigterm" else "SIGINT"
    assert proc.returncode == status, err[-2000:]
    assert "checkpoint after SIGTERM\n" in _log(out, "cell")  # one stop signal, the sweep's SIGTERM
    stopped = [line for line in err.splitlines() if "sweep stopped" in line]
    assert stopped == [f"{name}: sweep stopped; every running cell checkpointed; continue with: python again"], err[-2000:]
    assert running_cells(out) == {}


@pytest.mark.slow
def test_a_sweep_stopped_mid_cell_resumes_without_running_a_finished_cell_again(tmp_path):
    out = str(tmp_path / "bench")
    finished, stopped = os.path.join(out, "merge-random-s0"), os.path.join(out, "merge-csirl-s0")
    argv = ["--methods", "random", "csirl", "--scenarios", "merge", "--seeds", "0", "--output-dir", out,
            "--cpus-per-trial", "1", *TINY]
    proc = subprocess.Popen([sys.executable, os.path.join("recipes", "benchmark.py"), *argv], cwd=ROOT, env=ENV,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    _wait_for(proc, lambda: os.path.isfile(os.path.join(finished, "summary.json")) and bool(metrics_rows(stopped)), 240)
    _, err = _stop(proc, "ctrl-c")
    assert proc.returncode == 130, err[-3000:]
    last = [line for line in err.splitlines() if "sweep stopped" in line][-1]  # (a leak warning may follow it)
    assert last.startswith("SIGINT: sweep stopped; every running cell checkpointed; continue with: python "), err[-3000:]
    assert "SIGINT: stopping merge-csirl-s0" in err and running_cells(out) == {}
    assert "SIGTERM: training stopped; checkpoint saved" in _log(out, "merge-csirl-s0")
    frames = torch.load(os.path.join(stopped, "checkpoints", "last", "state.pt"), weights_only=False)["counters"]["frames"]
    assert 100 <= frames < 2000 and not os.path.exists(os.path.join(stopped, "summary.json"))

    command = shlex.split(last.split("continue with: ", 1)[1])
    assert command[1:] == [os.path.join("recipes", "benchmark.py"), *argv]  # the same command
    done = subprocess.run([sys.executable, *command[1:]], cwd=ROOT, env=ENV, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "1 cells to run, 1 already done" in done.stderr
    starts = [line for line in _log(out, "merge-random-s0").splitlines() if line.startswith("$ ")]
    assert len(starts) == 1  # the finished cell did not run again
    assert f"resumed {stopped} at {frames} frames" in _log(out, "merge-csirl-s0")
    with open(os.path.join(stopped, "summary.json")) as f:
        assert json.load(f)["frames"] == 2000
    assert [r["frames"] for r in metrics_rows(stopped) if "round" in r] == list(range(100, 2001, 100))  # each batch once
    todo, already = benchmark.plan_cells(["random", "csirl"], ["merge"], [0], out, [])
    assert todo == [] and sorted(already) == ["merge-csirl-s0", "merge-random-s0"]
