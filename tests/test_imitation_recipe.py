"""recipes/imitation_highway.py (every baseline end to end on a tiny budget, resume, bad input) and
recipes/benchmark.py (a 2-cell sweep on local Ray, then its report)."""
from __future__ import annotations

import csv
import json
import os

import numpy as np
import pytest
import termination_probe
import torch
from omegaconf import OmegaConf

from torchrl_csirl.methods import baselines as imitation
from torchrl_csirl.run.run import run_script
from torchrl_csirl.scripts import benchmark, imitation_highway

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# the tiniest budget that still has two rounds: 100-frame batches, rounds of 20 updates, 1 test episode
TINY = [
    "collector.frames_per_batch=100",
    "collector.cut_episodes=true",  # 50-frame shares of 60-step episodes
    "collector.init_random_frames=100",
    "collector.num_workers=1",
    "collector.main_threads=1",
    "replay_buffer.warmup_frames=100",
    "expert.batch_size=32",
    "updates_per_round=20",
    "eval.episodes=1",
    "eval.final_episodes=1",
    "logger.progress_bar=false",
]
VOLATILE = {"collect_fps", "updates_per_s"}


def small_batches(method: str) -> list[str]:
    """``<method>.<...>batch_size=32`` for every batch size of the method's section."""
    cfg = imitation.load_config([f"method={method}"])
    section = cfg.get(method) or {}
    return [f"{method}.{key}=32" for key in section if key.endswith("batch_size")]


def read_rows(run_dir: str) -> list[dict]:
    with open(os.path.join(run_dir, "metrics.jsonl")) as f:
        return [json.loads(line) for line in f if line.strip()]


def run_main(*args: str) -> dict:
    return imitation_highway.main(list(args))


@pytest.mark.parametrize("method", imitation.TRAINED_METHODS)
def test_trained_baseline_end_to_end(method, tmp_path):
    out = run_main(f"method={method}", *TINY, *small_batches(method), "collector.total_frames=200",
                   f"logger.output_dir={tmp_path}", "logger.exp_name=run", "logger.backend=csv")
    run_dir = str(tmp_path / "run")
    assert out["method"] == method and out["run_dir"] == run_dir
    assert out["frames"] == 200 and out["updates"] == 100 and out["rounds"] == 2
    assert 0.0 <= out["accomplish_rate"] <= 1.0 and out["normalized_accomplish_rate"] is not None
    rows = read_rows(run_dir)
    losses = [v for r in rows for k, v in r.items() if k.startswith("loss_")]
    assert losses and all(torch.isfinite(torch.tensor(v)) for v in losses)
    # BC's rows log its cloning loss; no other baseline's row does
    assert any("loss_bc" in r for r in rows) if method == "bc" else all("loss_bc" not in r for r in rows)
    assert len([r for r in rows if "eval_accomplish_rate" in r]) == 2
    for name in ("summary.json", "metrics.csv", "config.yaml", "policy.pt", "learning_curve.png",
                 os.path.join("checkpoints", "last", "state.pt")):
        assert os.path.isfile(os.path.join(run_dir, name)), name
    with open(os.path.join(run_dir, "summary.json")) as f:
        assert json.load(f)["accomplish_rate"] == out["accomplish_rate"]
    if method in termination_probe.PROBED_METHODS:  # the critic on terminating vs continuing transitions
        stats = termination_probe.main([run_dir, "--samples", "64"])
        continuing = "residual_continuing" if method == "valuedice" else "q_continuing"
        for side in ("agent", "expert"):
            assert 0.0 <= stats[side]["terminal_fraction"] <= 1.0 and stats[side][continuing] is not None
        assert {"dac": "absorbing_reward", "iqlearn": "implicit_reward_continuing"}.get(method, continuing) in stats["agent"]
        with open(os.path.join(run_dir, "termination_probe.json")) as f:
            assert json.load(f)["agent"] == stats["agent"]
    else:
        with pytest.raises(imitation.ConfigError, match="no critic to probe"):
            termination_probe.main([run_dir])


def test_progress_reward_is_the_distance_gained_toward_the_finish():
    from tensordict import TensorDict

    from torchrl_csirl.tasks import SCENARIOS
    from torchrl_csirl.transforms import ProgressReward

    spec = SCENARIOS["roundabout"]  # (x, y) positions, features_range +-100 m
    reward = ProgressReward.from_scenario(spec, scale=1.0)
    finish = torch.tensor(spec.normalize_position(spec.finish_position), dtype=torch.float32)
    obs = torch.zeros(3, spec.obs_dim)
    obs[:, 1:3] = finish + torch.tensor([[0.3, 0.4], [0.0, 0.1], [0.0, 0.0]])  # 0.5, 0.1, 0 away
    next_obs = obs.clone()
    next_obs[:, 1:3] = finish + torch.tensor([[0.0, 0.0], [0.0, 0.3], [0.6, 0.8]])  # 0, 0.3, 1 away
    td = reward(TensorDict({"observation": obs, "next": {"observation": next_obs}}, [3]))
    torch.testing.assert_close(td["next", "progress_reward"].squeeze(-1), torch.tensor([0.5, -0.2, -1.0]))
    with pytest.raises(ValueError, match="one finish coordinate per position feature"):
        ProgressReward([0.1], [1, 2])


def test_sac_trains_on_the_progress_reward(tmp_path):
    cfg = imitation.load_config(["method=sac", *TINY, *small_batches("sac"), "collector.total_frames=200",
                                       "logger.backend=none"])
    run = imitation.make_trainer(cfg, str(tmp_path))
    try:
        run.trainer.train()
        batch = run.online_buffer.sample()
        torch.testing.assert_close(batch["next", "reward"], batch["next", "progress_reward"])
        spec = run.spec
        x, next_x = batch["observation"][:, 1], batch["next", "observation"][:, 1]
        finish = float(spec.normalize_position(spec.finish_position)[0])
        expected = spec.matching_scale * ((x - finish).abs() - (next_x - finish).abs())
        torch.testing.assert_close(batch["next", "reward"].squeeze(-1), expected)
        assert run.parts.method.states["loss"].qvalue_network_params.batch_size[0] == 2  # standard SAC: two critics
    finally:
        run.close()


@pytest.mark.parametrize("method", ["random", "expert"])
def test_reference_rows_are_evaluated_on_the_test_episodes(method, tmp_path):
    out = run_main(f"method={method}", *TINY, f"logger.output_dir={tmp_path}", "logger.exp_name=ref",
                   "logger.backend=csv")
    assert out["frames"] == 0 and out["updates"] == 0 and out["eval_episodes"] == 1
    rows = read_rows(str(tmp_path / "ref"))
    assert rows[-1]["test_accomplish_rate"] == out["accomplish_rate"]
    if method == "expert":  # the shipped demonstrations come from the same driver
        assert out["normalized_accomplish_rate"] > 0.9 and out["success_rate"] == 1.0
    else:
        assert out["accomplish_rate"] < 0.5


def test_resume_gives_the_uninterrupted_metrics(tmp_path):
    common = ["method=sac", *TINY, *small_batches("sac"), f"logger.output_dir={tmp_path}", "logger.backend=csv"]
    full = run_main(*common, "collector.total_frames=200", "logger.exp_name=full")
    run_main(*common, "collector.total_frames=100", "logger.exp_name=part")
    resumed = run_main(f"checkpoint.resume={tmp_path / 'part'}", "collector.total_frames=200")
    assert resumed["accomplish_rate"] == full["accomplish_rate"] and resumed["updates"] == full["updates"]
    a = {r["frames"]: r for r in read_rows(full["run_dir"]) if "loss_qvalue" in r}
    b = {r["frames"]: r for r in read_rows(resumed["run_dir"]) if "loss_qvalue" in r}
    assert sorted(a) == sorted(b)
    for frames in a:
        assert {k: v for k, v in a[frames].items() if k not in VOLATILE} == \
               {k: v for k, v in b[frames].items() if k not in VOLATILE}


@pytest.mark.parametrize("args, message", [
    (["method=gibberish"], "error: method=gibberish: must be one of sac, bc"),
    ([], "error: method: required"),
    (["method=csirl"], "error: method=csirl: CSIRL is trained by recipes/csirl_highway.py"),
    (["method=bc", "expert.num_trajectories=7"], "error: expert.num_trajectories=7: num_trajectories must be one of"),
    (["method=bc", "expert.path=/nonexistent/demos.npz"], "error: expert.path: no such file"),
    (["method=sac", "sac.lr=-1"], "error: sac.*: Invalid learning rate: -1"),
])
def test_bad_input_is_one_error_line(args, message, tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        run_script(lambda: imitation_highway.main([*args, f"logger.output_dir={tmp_path}"]))
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(message), err
    assert os.listdir(tmp_path) == []  # no run directory left behind


def _one_error_line(capsys, args: list[str]) -> str:
    with pytest.raises(SystemExit) as exit_info:
        run_script(lambda: imitation_highway.main(args))
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: "), err
    return err[0]


def test_demonstrations_with_a_nan_stop_at_loading_naming_file_and_field(tmp_path, capsys):
    from torchrl_csirl.data import load_expert_demonstrations

    path = load_expert_demonstrations("merge", 25).save(tmp_path / "demos.npz")
    arrays = dict(np.load(path))
    arrays["action"][10, 0] = np.nan
    np.savez(path, **arrays)
    line = _one_error_line(capsys, ["method=bc", f"expert.path={path}", f"logger.output_dir={tmp_path / 'runs'}"])
    assert path in line and "action holds 1 non-finite value" in line and "transition 10" in line, line
    assert not os.path.exists(tmp_path / "runs") or os.listdir(tmp_path / "runs") == []


def test_a_corrupted_checkpoint_is_one_line_naming_it(tmp_path, capsys):
    run_dir = tmp_path / "merge-sac-s0"
    (run_dir / "checkpoints" / "last").mkdir(parents=True)
    OmegaConf.save(imitation.load_config(["method=sac", *TINY]), run_dir / "config.yaml")
    torch.save({"counters": {"frames": 100}}, run_dir / "checkpoints" / "last" / "state.pt")
    state = run_dir / "checkpoints" / "last" / "state.pt"
    state.write_bytes(state.read_bytes()[:40])  # truncated
    line = _one_error_line(capsys, [f"checkpoint.resume={run_dir}"])
    assert line.startswith(f"error: checkpoint {state} cannot be read") and "no previous checkpoint is kept" in line, line
    # a previous checkpoint left beside it (a run killed while swapping in a new one) is named
    (run_dir / "checkpoints" / "last.old").mkdir()
    torch.save({"counters": {"frames": 50}}, run_dir / "checkpoints" / "last.old" / "state.pt")
    line = _one_error_line(capsys, [f"checkpoint.resume={run_dir}"])
    assert f"the previous checkpoint is kept at {run_dir / 'checkpoints' / 'last.old'}" in line, line


def test_benchmark_sweeps_on_ray_resumes_and_reports(tmp_path, capsys):
    out = str(tmp_path / "bench")
    args = ["--methods", "random", "bc", "sac", "--scenarios", "merge", "--seeds", "0", "--output-dir", out,
            "--cpus-per-trial", "1", *TINY, "collector.total_frames=200", "logger.backend=csv", "sac:sac.lr=-1"]
    assert benchmark.main(args) == 1  # the sac cell fails (bad learning rate), the others finish
    assert json.loads(capsys.readouterr().out.strip().splitlines()[-1])["failed"] == ["merge-sac-s0"]
    with open(os.path.join(out, "logs", "merge-sac-s0.log")) as f:
        assert "error: sac.*: Invalid learning rate" in f.read()
    for cell in ("merge-random-s0", "merge-bc-s0"):
        assert os.path.isfile(os.path.join(out, cell, "summary.json"))
    todo, done = benchmark.plan_cells(["random", "bc", "sac"], ["merge"], [0, 1], out, [])
    assert sorted(done) == ["merge-bc-s0", "merge-random-s0"]
    assert [c.name for c in todo] == ["merge-random-s1", "merge-bc-s1", "merge-sac-s0", "merge-sac-s1"]
    assert benchmark.main(["report", out]) == 0
    with open(os.path.join(out, "report", "table.csv")) as f:
        rows = {r["method"]: r for r in csv.DictReader(f)}
    assert set(rows) == {"random", "bc"} and rows["bc"]["paper"] == "0.13" and rows["bc"]["runs"] == "1"
    with open(os.path.join(out, "report", "table.md")) as f:
        table = f.read()
    assert "| method | merge |" in table and "[0.01]" in table
    with open(os.path.join(out, "report", "curves_merge.png"), "rb") as f:
        assert f.read(8) == b"\x89PNG\r\n\x1a\n"


def test_benchmark_resumes_a_killed_cell_from_its_checkpoint(tmp_path):
    run_dir = tmp_path / "merge-sac-s0" / "checkpoints" / "last"
    run_dir.mkdir(parents=True)
    (run_dir / "state.pt").touch()
    (cell,), _ = benchmark.plan_cells(["sac"], ["merge"], [0], str(tmp_path), ["bc:optim.lr=1"])
    assert cell.resumed and f"checkpoint.resume={tmp_path / 'merge-sac-s0'}" in cell.command
    assert "optim.lr=1" not in cell.command
    assert benchmark.main(["--methods", "dqn"]) == 2
    todo, _ = benchmark.plan_cells(["expert"], ["merge"], [0, 1, 2], str(tmp_path), [])
    assert [c.name for c in todo] == ["merge-expert-s0"]  # deterministic: one seed


def test_benchmark_runs_csirl_ablations_and_tells_which_differences_exceed_seed_noise(tmp_path):
    todo, _ = benchmark.plan_cells(["csirl-nocur", "csirl-noexp", "csirl-b"], ["merge"], [0], str(tmp_path), [])
    switches = {c.method: [a for a in c.command if a.startswith("csirl.") or a.startswith("replay_buffer.")]
                for c in todo}
    assert switches == {"csirl-nocur": ["csirl.fixed_subgoal=true"],
                        "csirl-noexp": ["replay_buffer.expert_fraction=0"], "csirl-b": ["csirl.intrinsic=false"]}
    assert all(c.command[1:3] == ("-m", "torchrl_csirl.scripts.csirl_highway") for c in todo)
    # finished runs as the sweep leaves them: every summary says "csirl", the cell name says which ablation
    scores = {"csirl": [0.93, 0.94, 0.92], "csirl-nocur": [0.97, 0.95, 0.94], "csirl-noexp": [0.67, 0.70, 0.64]}
    for method, values in scores.items():
        for seed, value in enumerate(values):
            run_dir = tmp_path / f"merge-{method}-s{seed}"
            run_dir.mkdir()
            (run_dir / "summary.json").write_text(json.dumps({
                "scenario": "merge", "method": "csirl", "seed": seed, "normalized_accomplish_rate": value,
                "accomplish_rate": value * 0.937, "success_rate": 0.9, "crash_rate": 0.1 * seed,
                "total_wall_s": 1200.0}))
    rows = {r["method"]: r for r in benchmark.table_rows(benchmark.read_runs([str(tmp_path)]))}
    assert list(rows) == ["csirl", "csirl-nocur", "csirl-noexp"] and rows["csirl-nocur"]["runs"] == 3
    assert rows["csirl"]["vs_csirl"] is None
    assert rows["csirl-nocur"]["vs_csirl"] == pytest.approx(0.0233, abs=1e-3)
    assert not rows["csirl-nocur"]["vs_csirl_beyond_noise"]  # +0.023 with these spreads: within noise
    assert rows["csirl-noexp"]["vs_csirl_beyond_noise"] and rows["csirl-noexp"]["vs_csirl"] < -0.2
    table = benchmark.markdown_table(list(rows.values()))
    assert "Difference from csirl" in table and "| csirl-noexp | **-0.260 (t " in table
    assert "| csirl-nocur | 0.90 / 0.10 |" in table  # success / crash, mean over seeds


def test_help_lists_every_key_with_its_help(capsys):
    from torchrl_csirl.run.config import flatten_config

    assert imitation_highway.main(["--help"]) == {}
    keys = [line for line in capsys.readouterr().out.splitlines() if " = " in line]
    assert len(keys) == len(flatten_config(imitation.load_config(["method=bc"]))) - 1  # less the env.scenario mirror
    # sections from a hyperparameter dataclass show the help of its docstring
    assert any(line.strip().startswith("sac.tau = 0.005  # a number; Polyak") for line in keys)


def test_curve_figures_say_which_episodes_their_points_played(tmp_path):
    def run(name: str, evaluation: str) -> str:
        folder = tmp_path / name
        folder.mkdir()
        (folder / "config.yaml").write_text(f"eval:\n{evaluation}")
        return str(folder)

    validation = run("v", "  episodes: 30\n  validation_seed: 2000000\n")
    old = run("o", "  episodes: 10\n")  # recorded before eval.validation_seed
    assert benchmark.evaluation_schedule([validation]) == "30 validation episodes per point"
    assert benchmark.evaluation_schedule([old]) == "10 test episodes per point"
    assert "differing" in benchmark.evaluation_schedule([validation, old])


def test_benchmark_runs_a_baseline_variant_as_its_base_method_with_its_switch_and_a_row_of_its_own(tmp_path):
    """``sac-exp``: SAC with a quarter of each batch expert transitions (issue 87's maze table), run by the
    baselines' recipe as ``method=sac`` with ``sac.expert_fraction=0.25``, its summary saying ``sac``."""
    (cell,), _ = benchmark.plan_cells(["sac-exp"], ["merge"], [0], str(tmp_path), ["sac-exp:sac.lr=0.001"])
    assert cell.command[1:3] == ("-m", "torchrl_csirl.scripts.imitation_highway") and cell.name == "merge-sac-exp-s0"
    args = list(cell.command)
    assert args[3] == "method=sac" and args.index("sac.expert_fraction=0.25") > args.index("sac.lr=0.001")
    for method in ("sac", "sac-exp"):
        run_dir = tmp_path / f"merge-{method}-s0"
        run_dir.mkdir()
        (run_dir / "summary.json").write_text(json.dumps({
            "scenario": "merge", "method": "sac", "seed": 0, "normalized_accomplish_rate": 0.5,
            "accomplish_rate": 0.5, "success_rate": 0.5, "crash_rate": 0.1, "total_wall_s": 600.0}))
    assert sorted(r["method"] for r in benchmark.read_runs([str(tmp_path)])) == ["sac", "sac-exp"]
