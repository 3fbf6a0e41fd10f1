"""SIGTERM in a run's first round: a checkpoint at the batch reached, the resume command printed,
exit status 143, and the resumed run finishes with every frame counted once."""
from __future__ import annotations

import json
import os
import shlex
import signal
import subprocess
import sys
import time

import pytest
import torch
from run_logs import metrics_rows

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RECIPE = os.path.join("recipes", "csirl_highway.py")
# 100-frame batches collected in the main process, one round that never ends before 400 frames: no
# round checkpoint before the signal
TINY = [
    "collector.frames_per_batch=100", "collector.cut_episodes=true", "collector.init_random_frames=100", "collector.num_workers=1",
    "collector.main_threads=1", "replay_buffer.warmup_frames=100", "replay_buffer.batch_size=32",
    "csirl.updates_per_round=1000", "csirl.num_qvalue_nets=2", "optim.utd_ratio=0.1", "eval.episodes=1",
    "eval.final_episodes=1", "eval.video=false", "logger.backend=none", "logger.progress_bar=false",
    "collector.total_frames=400",
]
ENV = {**os.environ, "WANDB_MODE": "offline", "MPLBACKEND": "Agg", "RL_WARNINGS": "0"}


def _start_and_wait_for_a_row(command: list[str], run_dir: str, timeout_s: float) -> subprocess.Popen:
    """Starts ``command`` and waits until ``run_dir`` logs its first metrics row (the process still running)."""
    proc = subprocess.Popen(command, cwd=ROOT, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + timeout_s
        while not metrics_rows(run_dir) and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.2)
        assert proc.poll() is None, f"it ended before it could be stopped:\n{proc.stderr.read()[-2000:]}"
    except BaseException:
        proc.kill()
        raise
    return proc


def test_sigterm_in_the_first_round_checkpoints_and_prints_the_resume_command(tmp_path):
    run_dir = os.path.join(tmp_path, "stopped")
    proc = _start_and_wait_for_a_row([sys.executable, RECIPE, *TINY, f"logger.output_dir={tmp_path}",
                                      "logger.exp_name=stopped"], run_dir, 120)
    try:
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == 128 + signal.SIGTERM, err[-2000:]
    state = torch.load(os.path.join(run_dir, "checkpoints", "last", "state.pt"), weights_only=False)
    counters = state["counters"]
    frames = counters["frames"]
    assert 100 <= frames < 400 and counters["rounds"] == 0 and frames == metrics_rows(run_dir)[-1]["frames"]
    resume = [line for line in err.splitlines() if line.startswith("resume with: ")]
    assert resume, err[-2000:]
    command = shlex.split(resume[-1].removeprefix("resume with: "))
    assert command == ["python", RECIPE, f"checkpoint.resume={run_dir}"]

    done = subprocess.run([sys.executable, *command[1:]], cwd=ROOT, env=ENV, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert f"resumed {run_dir} at {frames} frames" in done.stderr
    summary = json.loads(done.stdout.strip().splitlines()[-1])
    assert summary["frames"] == 400 and summary["run_dir"] == run_dir
    assert [r["frames"] for r in metrics_rows(run_dir) if "round" in r] == [100, 200, 300, 400]  # each batch once


def test_sigterm_to_a_sweep_checkpoints_its_running_cell_before_the_sweep_exits(tmp_path):
    from torchrl_csirl.run.processes import StopCellsOnSigterm, SweepBusyError, running_cells
    from torchrl_csirl.scripts import benchmark

    out = str(tmp_path / "bench")
    run_dir = os.path.join(out, "merge-csirl-s0")
    proc = _start_and_wait_for_a_row([sys.executable, os.path.join("recipes", "benchmark.py"), "--methods", "csirl",
                                      "--scenarios", "merge", "--seeds", "0", "--output-dir", out, "--cpus-per-trial", "1",
                                      *TINY], run_dir, 240)
    try:
        assert list(running_cells(out)) == ["merge-csirl-s0"]
        with open(os.path.join(out, "logs", "sweep.pid")) as f:
            assert int(f.read().split()[0]) == proc.pid
        with pytest.raises(SweepBusyError, match="merge-csirl-s0 pid"):  # a second sweep of the same folder
            StopCellsOnSigterm(out).__enter__()
        proc.send_signal(signal.SIGTERM)
        outs, err = proc.communicate(timeout=240)
    finally:
        proc.kill()
    assert proc.returncode == 128 + signal.SIGTERM, outs + err[-3000:]
    assert "SIGTERM: stopping merge-csirl-s0" in err and "every running cell checkpointed" in err, err[-2000:]
    with open(os.path.join(out, "logs", "merge-csirl-s0.log")) as f:
        assert "SIGTERM: training stopped; checkpoint saved" in f.read()
    assert running_cells(out) == {}
    (cell,), _ = benchmark.plan_cells(["csirl"], ["merge"], [0], out, [])
    assert cell.resumed  # the same command continues it
