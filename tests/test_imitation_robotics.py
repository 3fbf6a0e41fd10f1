"""recipes/imitation_robotics.py: the baselines on the robotics tasks (BC end to end on a tiny
budget, the expert and SAC rows' task-specific parts) and its configuration errors."""
from __future__ import annotations

import csv
import json
import os

import pytest
import torch
from robotics_budget import TINY_ROBOTICS_RUN

from torchrl_csirl.methods import baselines as imitation
from torchrl_csirl.methods.baselines import IMITATION_RECIPE
from torchrl_csirl.run.config import ConfigError
from torchrl_csirl.scripts import benchmark, imitation_robotics
from torchrl_csirl.tasks import make_env, resolve_scenario
from torchrl_csirl.tasks.expert_policy import ExpertDriverPolicy


def load_robotics(overrides):
    """The baselines' configuration, relocate when no task is named (as recipes/imitation_robotics.py runs it)."""
    return IMITATION_RECIPE.load_config(overrides, default_task="relocate")

TINY = [*TINY_ROBOTICS_RUN, "updates_per_round=20"]  # rounds of 20 updates


def test_bc_on_relocate_end_to_end(tmp_path):
    summary = imitation_robotics.main(["method=bc", "env.task=relocate", *TINY, f"logger.output_dir={tmp_path}"])
    assert summary["scenario"] == "relocate" and summary["method"] == "bc"
    # 400 frames at optim.utd_ratio=0.1 (TINY_ROBOTICS_RUN): exactly 40 updates
    assert summary["frames"] == 400 and summary["updates"] == 40 and isinstance(summary["return"], float)
    for name in ("config.yaml", "policy.pt", "summary.json"):
        assert os.path.exists(os.path.join(summary["run_dir"], name)), name
    with open(os.path.join(summary["run_dir"], "summary.json")) as f:
        assert json.load(f)["method"] == "bc"
    # a resume reads the saved robotics configuration back, with the command line's changes
    resumed = IMITATION_RECIPE.load_run_config(summary["run_dir"], ["collector.total_frames=600"])
    assert (resumed.method, resumed.env.task, resumed.collector.total_frames) == ("bc", "relocate", 600)


def test_the_expert_row_drives_the_task_expert():
    env = make_env("relocate", seed=0)
    try:
        rollout = env.rollout(20, ExpertDriverPolicy(env, "relocate"))
    finally:
        env.close()
    # the DAPG hand reaches for the ball: the palm-to-object distance shrinks over 20 steps
    palm_to_object = rollout["observation"][:, 30:33].norm(dim=-1)
    assert rollout["action"].shape == (20, 30) and palm_to_object[-1] < palm_to_object[0]


def test_sac_learns_from_the_task_reward_on_robotics_and_the_progress_reward_on_driving():
    robotics = load_robotics(["method=sac", "env.task=relocate"])
    assert imitation.true_reward_transforms(robotics, resolve_scenario("relocate"), torch.device("cpu")) == []
    driving = imitation.load_config(["method=sac", "env.task=merge"])
    names = [type(t).__name__ for t in imitation.true_reward_transforms(
        driving, resolve_scenario("merge"), torch.device("cpu"))]
    assert names == ["ProgressReward", "CombineRewards"]
    scaled = load_robotics(["method=sac", "env.task=relocate", "sac.reward_scale=2"])
    with pytest.raises(ConfigError, match="sac.reward_scale=2.0: relocate trains SAC on the environment's own reward"):
        imitation.true_reward_transforms(scaled, resolve_scenario("relocate"), torch.device("cpu"))


def test_configuration_errors():
    cfg = load_robotics(["method=dac", "env.task=antmaze-umaze"])
    assert (cfg.env.task, cfg.collector.frames_per_batch, cfg.expert.curriculum) == ("antmaze-umaze", 1400, "expert")
    with pytest.raises(ConfigError, match="method: required"):
        load_robotics(["env.task=relocate"])
    assert load_robotics(["method=bc", "env.task=merge"]).env == {"task": "merge", "scenario": "merge"}  # the driving schema
    with pytest.raises(ConfigError, match="model.ego_relative_features=true"):
        load_robotics(["method=bc", "model.ego_relative_features=true"])
    with pytest.raises(ConfigError, match="model.lane_features=true: lanes exist in driving scenes only"):
        load_robotics(["method=bc", "model.lane_features=true"])
    with pytest.raises(ConfigError, match="method=csirl: CSIRL is trained by recipes/csirl_highway.py"):
        load_robotics(["method=csirl"])


def test_benchmark_sweeps_the_robotics_tasks_with_their_recipes_and_reports_the_return(tmp_path):
    out = str(tmp_path / "bench")
    todo, _ = benchmark.plan_cells(["csirl", "csirl-bc", "sqil"], ["relocate", "merge"], [0], out,
                                   ["csirl_robotics:csirl.delta=3", "csirl_highway:csirl.delta=2"])
    assert all(c.command[1] == "-m" for c in todo)  # the installed package's scripts
    recipes = {c.name: (c.command[2], [a for a in c.command if a.startswith("csirl.")]) for c in todo}
    scripts = "torchrl_csirl.scripts."
    assert recipes == {
        "relocate-csirl-s0": (scripts + "csirl_robotics", ["csirl.delta=3"]),
        "relocate-csirl-bc-s0": (scripts + "csirl_robotics", ["csirl.delta=3", "csirl.actor_bc_coef=10"]),
        "relocate-sqil-s0": (scripts + "imitation_robotics", []),
        "merge-csirl-s0": (scripts + "csirl_highway", ["csirl.delta=2"]),
        "merge-csirl-bc-s0": (scripts + "csirl_highway", ["csirl.delta=2", "csirl.actor_bc_coef=10"]),
        "merge-sqil-s0": (scripts + "imitation_highway", []),
    }
    # one real cell: BC on Relocate through Ray, on the tiny budget
    args = ["--methods", "bc", "--scenarios", "relocate", "--seeds", "0", "--output-dir", out, "--cpus-per-trial", "1",
            *TINY, "logger.backend=csv"]
    assert benchmark.main(args) == 0
    with open(os.path.join(out, "relocate-bc-s0", "summary.json")) as f:
        bc_return = json.load(f)["return"]
    # a finished CSIRL cell beside it (as the sweep leaves one), to compare returns against
    csirl_dir = tmp_path / "bench" / "relocate-csirl-s0"
    csirl_dir.mkdir()
    (csirl_dir / "summary.json").write_text(json.dumps({
        "scenario": "relocate", "method": "csirl", "seed": 0, "return": bc_return + 1000.0, "success_rate": 0.5,
        "accomplish_rate": 0.55, "crash_rate": 0.0, "normalized_accomplish_rate": 0.6, "total_wall_s": 600.0}))
    assert benchmark.main(["report", out]) == 0
    with open(os.path.join(out, "report", "table.csv")) as f:
        rows = {r["method"]: r for r in csv.DictReader(f)}
    assert float(rows["bc"]["return_mean"]) == pytest.approx(bc_return) and rows["bc"]["paper"] == ""
    assert float(rows["csirl"]["return_mean"]) == pytest.approx(bc_return + 1000.0)
    with open(os.path.join(out, "report", "table.md")) as f:
        table = f.read()
    assert table.startswith("Test return on the robotics tasks") and "| method | relocate |" in table
    assert "Expert-normalised" not in table and "| csirl | 0.50 / 0.55 |" in table  # success / progress
    for figure in ("curves_relocate.png", "progress_relocate.png"):  # the return, and the progress
        with open(os.path.join(out, "report", figure), "rb") as f:
            assert f.read(8) == b"\x89PNG\r\n\x1a\n"
