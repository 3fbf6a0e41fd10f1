"""Numbers pinned: a tiny seed-0 run of CSIRL and of one baseline (SQIL) gives the losses and metrics
recorded in ``tests/data/regression_seed0.json``, so no refactor changes them silently.

The recorded values were produced by the code before the run layer moved into the package
(commit cb13bdb, ``recipes/*.py``) and reproduced after it. A change meant to alter the numbers
re-records them, saying why in its commit: ``python tests/test_regression.py --record``.
CSIRL's job pins ``optim.precision=fp32``: the default, ``auto``, is bfloat16 on a CPU with native bfloat16,
whose numbers are not float32's.
"""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile

import pytest

DATA = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "regression_seed0.json")
COMMON = [
    "seed=0", "collector.frames_per_batch=100", "collector.init_random_frames=100", "collector.total_frames=300",
    "replay_buffer.warmup_frames=100", "optim.utd_ratio=0.5", "eval.episodes=2", "eval.final_episodes=2",
    "eval.video=false", "logger.backend=none", "logger.progress_bar=false", "collector.main_threads=1",
]
#: job -> (script, its own overrides)
JOBS = {
    "csirl": ("csirl_highway", ["replay_buffer.batch_size=64", "csirl.updates_per_round=20", "optim.precision=fp32"]),
    "sqil": ("imitation_highway", ["method=sqil", "sqil.batch_size=64", "expert.batch_size=32", "updates_per_round=20"]),
}
#: per-batch row entries and summary entries compared (timings and paths are not)
ROW_KEYS = ("frames", "updates", "round", "loss_qvalue", "loss_actor", "loss_alpha", "alpha", "entropy", "loss_meta",
            "loss_imitation", "loss_reward_l1", "eval_accomplish_rate", "eval_env_return", "subgoal")
SUMMARY_KEYS = ("accomplish_rate", "success_rate", "crash_rate", "return", "frames", "updates", "rounds", "auc",
                "final_subgoal", "curriculum_length")
#: same machine, same threads: the numbers repeat exactly. Another CPU's kernels round differently in the last
#: bits and a few updates amplify that (measured: up to 8e-5 relative, an AMD EPYC against the recording machine);
#: a change in what is computed moves them by far more
RTOL = 1e-3


def run_job(job: str, out: str, command: list[str] | None = None) -> dict:
    """Runs ``job`` (``python -m torchrl_csirl.scripts.<script>``, or ``command``) and returns its pinned values."""
    script, extra = JOBS[job]
    command = command or [sys.executable, "-m", f"torchrl_csirl.scripts.{script}"]
    # today's keys: 50-frame shares of 60-step merge episodes are allowed explicitly
    extra = [*extra, "collector.cut_episodes=true"] if "-m" in command else extra
    env = {**os.environ, "WANDB_MODE": "offline", "MPLBACKEND": "Agg", "RL_WARNINGS": "0"}
    proc = subprocess.run([*command, *COMMON, *extra, f"logger.output_dir={out}", f"logger.exp_name={job}"],
                          capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    summary = json.loads(proc.stdout.strip().splitlines()[-1])
    with open(os.path.join(out, job, "metrics.jsonl")) as f:
        rows = [json.loads(line) for line in f if line.strip()]
    return {"rows": [{k: r[k] for k in ROW_KEYS if k in r} for r in rows],
            "summary": {k: summary[k] for k in SUMMARY_KEYS if k in summary}}


def _close(a, b) -> bool:
    if isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
        return math.isclose(a, b, rel_tol=RTOL, abs_tol=1e-9)
    return a == b


@pytest.mark.parametrize("job", sorted(JOBS))
def test_a_tiny_seed0_run_gives_the_recorded_numbers(job, tmp_path):
    with open(DATA) as f:
        recorded = json.load(f)[job]
    got = run_job(job, str(tmp_path))
    assert len(got["rows"]) == len(recorded["rows"])
    for i, (row, want) in enumerate(zip(got["rows"], recorded["rows"])):
        assert row.keys() == want.keys(), f"row {i}"
        bad = {k: (row[k], want[k]) for k in want if not _close(row[k], want[k])}
        assert not bad, f"{job}, metrics row {i}: (got, recorded) {bad}"
    bad = {k: (got["summary"].get(k), v) for k, v in recorded["summary"].items() if not _close(got["summary"].get(k), v)}
    assert not bad, f"{job}, summary: (got, recorded) {bad}"


if __name__ == "__main__":  # python tests/test_regression.py --record [--command python /old/recipes/{script}.py]
    if "--record" not in sys.argv:
        sys.exit("usage: python tests/test_regression.py --record [--command <python> <path with {script}>]")
    base = sys.argv[sys.argv.index("--command") + 1:] if "--command" in sys.argv else None
    values = {}
    for name, (script_name, _) in JOBS.items():
        with tempfile.TemporaryDirectory() as out:
            command = [part.format(script=script_name) for part in base] if base else None
            values[name] = run_job(name, out, command)
    with open(DATA, "w") as f:
        json.dump(values, f, indent=1)
        f.write("\n")
    print(f"recorded {DATA}")
