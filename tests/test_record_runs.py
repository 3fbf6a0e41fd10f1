"""tools/record_runs.py: a finished run's record in docs/runs (summary, config, resumes, evaluation rows)."""
from __future__ import annotations

import json
import os
import shutil

import pytest
import record_runs

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHIPPED = os.path.join(ROOT, "docs", "runs", "mujoco", "halfcheetah-sac-s0")


def _run(tmp_path, rows: list[dict], finished: bool = True) -> str:
    run = tmp_path / "runs" / "hopper-dac-s0"
    run.mkdir(parents=True)
    shutil.copyfile(os.path.join(SHIPPED, "config.yaml"), run / "config.yaml")
    if finished:
        shutil.copyfile(os.path.join(SHIPPED, "summary.json"), run / "summary.json")
    (run / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    return str(run)


def test_a_record_of_a_record_is_the_same_record(tmp_path):
    target = record_runs.record_run(SHIPPED, str(tmp_path))
    for name in ("summary.json", "config.yaml", "metrics.jsonl"):
        with open(os.path.join(target, name)) as mine, open(os.path.join(SHIPPED, name)) as shipped:
            assert mine.read() == shipped.read(), name
    assert not os.path.exists(os.path.join(target, "resumes.jsonl"))


def test_only_evaluation_rows_are_kept_with_their_position(tmp_path):
    rows = [{"frames": 2000, "updates": 1000, "loss_actor": 0.3, "collect_fps": 700.0},
            {"frames": 20000, "updates": 10000, "round": 4, "eval_env_return": 12.5, "loss_actor": 0.1},
            {"frames": 300000, "updates": 150000, "test_env_return": 40.0}]
    target = record_runs.record_run(_run(tmp_path, rows), str(tmp_path / "docs"))
    with open(os.path.join(target, "metrics.jsonl")) as f:
        kept = [json.loads(line) for line in f]
    assert kept == [{"frames": 20000, "updates": 10000, "round": 4, "eval_env_return": 12.5}]


def test_resumes_are_recorded_and_a_forced_record_keeps_nothing_of_the_old_one(tmp_path):
    run = _run(tmp_path, [])
    with open(os.path.join(run, "resumes.jsonl"), "w") as f:
        f.write(json.dumps({"frames": 100, "changed": {"eval.keep_best": [False, True]}}) + "\n")
    target = record_runs.record_run(run, str(tmp_path / "docs"))
    assert os.path.isfile(os.path.join(target, "resumes.jsonl"))
    with pytest.raises(record_runs.RecordError, match="exists: pass --force"):
        record_runs.record_run(run, str(tmp_path / "docs"))
    os.remove(os.path.join(run, "resumes.jsonl"))
    record_runs.record_run(run, str(tmp_path / "docs"), force=True)
    assert not os.path.exists(os.path.join(target, "resumes.jsonl"))


def test_unfinished_runs_and_broken_logs_are_refused_by_name(tmp_path, capsys):
    unfinished = _run(tmp_path, [], finished=False)
    assert record_runs.main([unfinished, "--into", str(tmp_path / "docs")]) == 1
    assert "has no summary.json: the run has not finished" in capsys.readouterr().err
    assert not os.path.exists(tmp_path / "docs" / "hopper-dac-s0")
    with open(os.path.join(unfinished, "summary.json"), "w") as f:
        f.write("{}")
    with open(os.path.join(unfinished, "metrics.jsonl"), "a") as f:
        f.write('{"frames": 2\n')
    with pytest.raises(record_runs.RecordError, match=r"metrics.jsonl:1 is not a JSON line"):
        record_runs.record_run(unfinished, str(tmp_path / "docs"))
