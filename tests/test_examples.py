"""The examples of ``examples/`` run end to end on a tiny budget (issue 90)."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TINY = ["--frames", "400", "--frames-per-batch", "200", "--init-random-frames", "200", "--updates-per-round", "50",
        "--eval-episodes", "2", "--test-episodes", "2"]


@pytest.mark.parametrize("extras", [False, True], ids=["paper", "extras"])
def test_csirl_torchrl_loop_ends_with_its_json_line(tmp_path, extras):
    cmd = [sys.executable, str(ROOT / "examples" / "csirl_torchrl_loop.py"), *TINY, "--seed", "0", "--out", str(tmp_path)]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    proc = subprocess.run(cmd + (["--extras"] if extras else []), capture_output=True, text=True, timeout=120, env=env,
                          cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert result["extras"] is extras and result["frames"] == 400 and result["updates"] == 200
    assert 0.0 <= result["accomplish_rate"] <= 1.0 and 0 <= result["final_subgoal"] < result["curriculum_length"]
    scalars = Path(result["log_dir"]) / "scalars"  # TorchRL's CSVLogger, one file per scalar
    assert {"subgoal.csv", "eval_accomplish_rate.csv", "loss_meta.csv", "loss_qvalue.csv"} <= {p.name for p in scalars.iterdir()}
    with open(Path(result["log_dir"]) / "summary.json") as f:
        summary = json.load(f)
    assert summary == result and summary["scenario"] == "merge"
    assert summary["method"] == ("csirl-torchrl-loop-extras" if extras else "csirl-torchrl-loop")
    assert summary["normalized_accomplish_rate"] >= summary["accomplish_rate"]  # over the expert's rate (below 1)
