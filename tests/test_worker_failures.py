"""A run whose collector workers die stops at once, in one line, with its checkpoint kept; a user's
module in the working directory (``env.module=``) registers a gymnasium id that the workers and a
resume find.

Each test runs a recipe as a user does, in a process of its own, from a temporary working directory
holding the user's module (``python recipes/imitation_robotics.py env.gym_id=... env.module=...``).
"""
from __future__ import annotations

import os
import shlex
import signal
import subprocess
import sys
import textwrap
import time

import pytest
import torch

from torchrl_csirl.data import record_demonstrations
from torchrl_csirl.tasks import make_gymnasium_task

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RECIPE = os.path.join(REPO, "recipes", "imitation_robotics.py")
MODULE = "user_point_tasks"
GYM_ID = "UserPoint-v0"
#: the user's module: a point that must reach (0.8, 0.8), registered as a gymnasium id; the variables
#: POINT_FAIL_AFTER (steps of one env) and POINT_FAIL_IN_WORKER plant the failures
USER_MODULE = textwrap.dedent('''
    import multiprocessing
    import os

    import gymnasium as gym
    import numpy as np


    class UserPoint(gym.Env):
        def __init__(self):
            if os.environ.get("POINT_FAIL_IN_WORKER") and multiprocessing.parent_process() is not None:
                raise OSError("the point's track file is missing")
            self.observation_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
            self.action_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
            self.fail_after = int(os.environ.get("POINT_FAIL_AFTER", 0)) or None
            self.steps = 0

        def reset(self, *, seed=None, options=None):
            super().reset(seed=seed)
            self.pos = np.zeros(2, np.float32)
            return self.pos.copy(), {}

        def step(self, action):
            self.steps += 1
            if self.fail_after is not None and self.steps > self.fail_after:
                raise RuntimeError(f"the point left its arena after {self.fail_after} steps")
            self.pos = np.clip(self.pos + 0.1 * np.asarray(action, np.float32), -1.0, 1.0)
            done = bool(np.abs(self.pos - 0.8).max() < 0.1)
            return self.pos.copy(), float(done), done, False, {}


    gym.register("UserPoint-v0", entry_point=UserPoint, max_episode_steps=50)
''')
#: BC on tiny batches: a round (and a checkpoint) every batch of 200 frames, two worker processes
BUDGET = ["method=bc", f"env.gym_id={GYM_ID}", f"env.module={MODULE}", "expert.path=demos.npz",
          "expert.num_trajectories=3", "collector.frames_per_batch=200", "collector.cut_episodes=true",
          "collector.num_workers=2", "collector.init_random_frames=0", "collector.main_threads=1",
          "replay_buffer.warmup_frames=200", "optim.utd_ratio=0.1", "updates_per_round=20", "eval.episodes=1",
          "eval.final_episodes=2", "eval.video=false", "logger.backend=csv", "logger.progress_bar=false",
          "logger.output_dir=runs"]


def go_to_goal(td):
    td["action"] = (5.0 * (0.8 - td["observation"])).clamp(-1.0, 1.0)
    return td


@pytest.fixture
def user_dir(tmp_path, monkeypatch):
    """A working directory with the user's module and 3 demonstrations (not on this process's path after)."""
    (tmp_path / f"{MODULE}.py").write_text(USER_MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, MODULE, raising=False)
    __import__(MODULE)
    make_gymnasium_task(GYM_ID)
    record_demonstrations(GYM_ID, go_to_goal, episodes=3, seed=0).save(str(tmp_path / "demos.npz"))
    return tmp_path


def start(cwd, *overrides, **env) -> subprocess.Popen:
    """The recipe as a user runs it from ``cwd`` (``python recipes/....py``: the script's folder on the path)."""
    environ = {k: v for k, v in os.environ.items() if not k.startswith("POINT_")}
    environ.pop("PYTHONPATH", None)  # the module must be found from the working directory alone
    return subprocess.Popen([sys.executable, RECIPE, *BUDGET, *overrides], cwd=cwd, env={**environ, **env},
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def finish(proc: subprocess.Popen, timeout: float) -> tuple[int, str, str]:
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
        pytest.fail(f"the run did not stop within {timeout} s:\n{err[-3000:]}")
    return proc.returncode, out, err


def collector_workers(pid: int) -> list[int]:
    """The spawned collector worker processes of process ``pid`` (Linux ``/proc``; not the resource tracker)."""
    found = []
    for name in filter(str.isdigit, os.listdir("/proc")):
        try:
            with open(f"/proc/{name}/stat") as f:
                parent = int(f.read().rsplit(")", 1)[1].split()[1])
            with open(f"/proc/{name}/cmdline", "rb") as f:
                command = f.read().replace(b"\0", b" ").decode()
        except (OSError, ValueError, IndexError):
            continue
        if parent == pid and "spawn_main" in command and "resource_tracker" not in command:
            found.append(int(name))
    return sorted(found)


def last_line(stderr: str) -> str:
    return [line for line in stderr.splitlines() if line.strip()][-1]


def run_dir_of(cwd) -> str:
    (name,) = os.listdir(os.path.join(cwd, "runs"))
    return os.path.join(cwd, "runs", name)


def test_a_worker_raising_in_step_stops_the_run_in_one_line_and_the_printed_resume_continues_it(user_dir):
    # 2 workers x 2 envs, 50 steps each a batch: the envs raise in the third batch
    code, _, err = finish(start(user_dir, "collector.total_frames=1000", POINT_FAIL_AFTER="120"), timeout=240)
    line = last_line(err)
    assert code == 2, err[-3000:]
    assert line.startswith("error: collector worker ") and "failed: RuntimeError: the point left its arena after 120 " \
        "steps. Training stopped; the last checkpoint is kept at " in line, line
    run_dir = run_dir_of(user_dir)
    assert os.path.isfile(os.path.join(run_dir, "checkpoints", "last", "state.pt"))
    printed = line.split("resume with: ")[1]
    assert printed.startswith("python ") and "checkpoint.resume=" in printed
    # the command as printed, from the same folder (its `python` is this interpreter), once the env is mended
    proc = subprocess.Popen([sys.executable, *shlex.split(printed)[1:]], cwd=user_dir, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env={k: v for k, v in os.environ.items()
                                                                   if k != "PYTHONPATH" and not k.startswith("POINT_")})
    code, out, err = finish(proc, timeout=240)
    assert code == 0, err[-3000:]
    assert f"resumed {run_dir} at 400 frames" in err
    assert '"frames": 1000' in out.splitlines()[-1]


def test_a_killed_worker_stops_the_run_in_one_line_with_its_checkpoint_kept(user_dir):
    proc = start(user_dir, "collector.total_frames=1000000")
    try:
        deadline = time.monotonic() + 180
        checkpoint = None
        while checkpoint is None and time.monotonic() < deadline and proc.poll() is None:
            runs = os.path.join(user_dir, "runs")
            names = os.listdir(runs) if os.path.isdir(runs) else []
            found = [os.path.join(runs, n, "checkpoints", "last", "state.pt") for n in names]
            checkpoint = next((p for p in found if os.path.isfile(p)), None)
            time.sleep(0.5)
        assert checkpoint is not None, "no checkpoint within 180 s"
        workers = collector_workers(proc.pid)
        assert len(workers) == 2, workers
        os.kill(workers[1], signal.SIGKILL)
        killed_at = time.monotonic()
        code, _, err = finish(proc, timeout=60)
        assert time.monotonic() - killed_at < 60
    finally:
        if proc.poll() is None:
            proc.kill()
    line = last_line(err)
    assert code == 2, err[-3000:]
    assert "was killed by SIGKILL" in line and "the last checkpoint is kept at" in line and "resume with: " in line, line
    assert os.path.isfile(checkpoint)


def test_a_worker_failing_to_start_stops_the_run_in_one_line(user_dir):
    started = time.monotonic()
    code, _, err = finish(start(user_dir, "collector.total_frames=1000", POINT_FAIL_IN_WORKER="1"), timeout=120)
    assert code == 2, err[-3000:]
    assert last_line(err) == ("error: a collector worker failed to start: OSError: the point's track file is missing"), \
        err[-3000:]
    assert time.monotonic() - started < 120
    assert not os.listdir(os.path.join(user_dir, "runs"))  # a new run that never started keeps no directory


def test_env_factory_imports_the_task_modules_in_a_worker(user_dir, monkeypatch):
    """What a spawned worker runs: the module that registers the gymnasium id imported before the build."""
    from torchrl_csirl.tasks import env_factory, import_task_module, registry

    monkeypatch.chdir(user_dir)
    monkeypatch.setattr(registry, "_TASK_MODULES", {})
    import_task_module(MODULE)
    factory = env_factory(GYM_ID)
    assert registry._TASK_MODULES == {MODULE: str(user_dir)}
    import gymnasium as gym

    monkeypatch.delitem(gym.registry, GYM_ID)  # as in a fresh worker process
    monkeypatch.delitem(sys.modules, MODULE)
    assert factory().rollout(3)["observation"].shape == torch.Size([3, 2])


def _exit_killed_after(seconds: float) -> None:
    time.sleep(seconds)
    os.kill(os.getpid(), signal.SIGKILL)


def test_a_broken_pipe_from_a_worker_still_exiting_is_named_as_its_death():
    """A worker's pipe breaks while its process is still exiting (a race the killed-worker test can lose): on a
    broken pipe the log watches the workers before concluding that none failed; on any other error it does not wait."""
    import multiprocessing
    from types import SimpleNamespace

    from torchrl_csirl.trainers import WorkerErrorLog

    log = WorkerErrorLog()
    proc = multiprocessing.get_context("fork").Process(target=_exit_killed_after, args=(0.5,))
    proc.start()
    try:
        collector = SimpleNamespace(procs=[proc])
        started = time.monotonic()
        assert log.describe(collector, ValueError("not a worker's")) is None  # alive, not a pipe error: at once
        assert time.monotonic() - started < 0.4
        line = log.describe(collector, ConnectionResetError(104, "Connection reset by peer"))
        assert line == f"collector worker 0 (pid {proc.pid}) was killed by SIGKILL; no error of its own", line
    finally:
        proc.join(5)
        log.close()
