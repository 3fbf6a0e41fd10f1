"""``torchrl-csirl record``: a finished run's record in docs/runs (summary, config, resumes, evaluation rows, the
rows of its rounds, the probes' outputs)."""
from __future__ import annotations

import json
import os
import shutil

import pytest
from test_recipe import TINY

from torchrl_csirl.scripts import csirl_highway, record

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
    target = record.record_run(SHIPPED, str(tmp_path))
    for name in ("summary.json", "config.yaml", "metrics.jsonl"):
        with open(os.path.join(target, name)) as mine, open(os.path.join(SHIPPED, name)) as shipped:
            assert mine.read() == shipped.read(), name
    assert not os.path.exists(os.path.join(target, "resumes.jsonl"))


def test_only_evaluation_rows_are_kept_with_their_position(tmp_path):
    rows = [{"frames": 2000, "updates": 1000, "loss_actor": 0.3, "collect_fps": 700.0},
            {"frames": 20000, "updates": 10000, "round": 4, "eval_env_return": 12.5, "loss_actor": 0.1},
            {"frames": 300000, "updates": 150000, "test_env_return": 40.0}]
    target = record.record_run(_run(tmp_path, rows), str(tmp_path / "docs"))
    with open(os.path.join(target, "metrics.jsonl")) as f:
        kept = [json.loads(line) for line in f]
    assert kept == [{"frames": 20000, "updates": 10000, "round": 4, "eval_env_return": 12.5}]


def test_resumes_are_recorded_and_a_forced_record_keeps_nothing_of_the_old_one(tmp_path):
    run = _run(tmp_path, [])
    with open(os.path.join(run, "resumes.jsonl"), "w") as f:
        f.write(json.dumps({"frames": 100, "changed": {"eval.keep_best": [False, True]}}) + "\n")
    target = record.record_run(run, str(tmp_path / "docs"))
    assert os.path.isfile(os.path.join(target, "resumes.jsonl"))
    with pytest.raises(record.RecordError, match="exists: pass --force"):
        record.record_run(run, str(tmp_path / "docs"))
    os.remove(os.path.join(run, "resumes.jsonl"))
    record.record_run(run, str(tmp_path / "docs"), force=True)
    assert not os.path.exists(os.path.join(target, "resumes.jsonl"))


def test_unfinished_runs_and_broken_logs_are_refused_by_name(tmp_path, capsys):
    unfinished = _run(tmp_path, [], finished=False)
    assert record.main([unfinished, "--into", str(tmp_path / "docs")]) == 1
    assert "has no summary.json: the run has not finished" in capsys.readouterr().err
    assert not os.path.exists(tmp_path / "docs" / "hopper-dac-s0")
    with open(os.path.join(unfinished, "summary.json"), "w") as f:
        f.write("{}")
    with open(os.path.join(unfinished, "metrics.jsonl"), "a") as f:
        f.write('{"frames": 2\n')
    with pytest.raises(record.RecordError, match=r"metrics.jsonl:1 is not a JSON line"):
        record.record_run(unfinished, str(tmp_path / "docs"))


def test_read_rounds_names_a_record_without_its_per_round_table(tmp_path):
    rows = [{"frames": 10, "loss_actor": -1.5}, {"frames": 20, "actor_bc_mse": 0.25}]
    record.write_rounds(str(tmp_path / "rounds.csv"), rows)
    assert record.read_rounds(str(tmp_path)) == [
        {"frames": "10", "loss_actor": "-1.5", "actor_bc_mse": ""}, {"frames": "20", "loss_actor": "", "actor_bc_mse": "0.25"}]
    with pytest.raises(SystemExit, match=r"old-record: no rounds.csv \(records before the per-round table"):
        record.read_rounds(str(tmp_path / "old-record"))


def test_a_real_run_keeps_one_row_per_round_with_what_the_pages_read(tmp_path):
    """A tiny CSIRL run (rounds of two batches): its record keeps, per round, the subgoal at the round's end and
    the round's means of the losses, ``alpha``, ``entropy``, the matching reward's and ``r_w``'s batch means (the
    latter with its extremes), beside
    the evaluation rows; not the timings, the evaluations twice or the final test."""
    summary = csirl_highway.main([*TINY, "optim.utd_ratio=0.1", "csirl.num_qvalue_nets=2", "collector.total_frames=400",
                                  "collector.num_workers=1", "eval.video=false", "logger.backend=none",
                                  f"logger.output_dir={tmp_path / 'runs'}"])  # test_recipe.py's budget, 10 updates a batch
    run_dir = summary["run_dir"]
    with open(os.path.join(run_dir, "metrics.jsonl")) as f:
        logged = [json.loads(line) for line in f]
    batches = [r for r in logged if "round" in r]
    assert [r["round"] for r in batches] == [0, 0, 1, 1]  # 10 updates a batch, 20 a round
    target = record.record_run(run_dir, str(tmp_path / "docs"))
    rounds = record.read_rounds(target)
    assert [(int(r["frames"]), int(r["round"]), int(r["batches"])) for r in rounds] == [(200, 0, 2), (400, 1, 2)]
    columns = set(rounds[0])
    assert {"updates", "subgoal", "subgoal_changed", "alpha", "entropy", "loss_qvalue", "loss_actor", "loss_meta",
            "intrinsic_reward_mean", "intrinsic_reward_mean_min", "intrinsic_reward_mean_max", "matching_reward_mean",
            "reward_mean"} <= columns
    assert not any(c.startswith(("eval_", "test_")) or c in ("collect_fps", "updates_per_s") for c in columns)
    for row, pair in zip(rounds, (batches[:2], batches[2:])):
        assert int(row["subgoal"]) == pair[-1]["subgoal"]  # the subgoal the round's end selected
        for key in ("alpha", "entropy", "intrinsic_reward_mean", "matching_reward_mean"):
            assert float(row[key]) == pytest.approx((pair[0][key] + pair[1][key]) / 2, rel=1e-3), key
        r_w = [b["intrinsic_reward_mean"] for b in pair]
        assert float(row["intrinsic_reward_mean_min"]) == pytest.approx(min(r_w), rel=1e-3)
        assert float(row["intrinsic_reward_mean_max"]) == pytest.approx(max(r_w), rel=1e-3)
    with open(os.path.join(target, "metrics.jsonl")) as f:
        assert [json.loads(line) for line in f] == record.evaluation_rows(logged)
    again = record.record_run(target, str(tmp_path / "again"))  # a record recorded again: the same record
    for name in ("summary.json", "config.yaml", "metrics.jsonl", "rounds.csv"):
        with open(os.path.join(again, name)) as mine, open(os.path.join(target, name)) as first:
            assert mine.read() == first.read(), name


def test_round_rows_bound_the_discriminator_pool_long_runs_and_copy_the_tools_outputs(tmp_path):
    """GAIL's per-batch discriminator loss keeps its round extremes; a long run's rounds are pooled to fit
    ``max_rounds``; a repeated batch counts once; the probes' JSON beside the run goes with the record."""
    rows = [{"frames": 1000 * (i + 1), "updates": 500 * (i + 1), "round": i // 2, "collect_fps": 700.0,
             "loss_discriminator": 0.001 * (i + 1)} for i in range(8)]
    rows.insert(2, dict(rows[2], loss_discriminator=9.0))  # logged, then again after a resume: the last copy counts
    rows[4]["eval_env_return"] = 12.5
    run = _run(tmp_path, rows)
    for name in ("termination_probe.json", "locomotion_probe.json"):
        with open(os.path.join(run, name), "w") as f:
            f.write('{"method": "gail"}\n')
    target = record.record_run(run, str(tmp_path / "docs"), max_rounds=2)
    rounds = record.read_rounds(target)
    assert [(r["frames"], r["round"], r["batches"]) for r in rounds] == [("4000", "1", "4"), ("8000", "3", "4")]
    assert (rounds[0]["loss_discriminator_min"], rounds[0]["loss_discriminator_max"]) == ("0.001", "0.004")
    assert float(rounds[0]["loss_discriminator"]) == pytest.approx(0.0025)
    for name in ("termination_probe.json", "locomotion_probe.json"):
        assert os.path.isfile(os.path.join(target, name)), name
    assert len(record.round_rows(rows)) == 4  # one row a round within the bound
    os.remove(os.path.join(run, "locomotion_probe.json"))
    record.record_run(run, str(tmp_path / "docs"), force=True)
    assert not os.path.exists(os.path.join(target, "locomotion_probe.json"))
