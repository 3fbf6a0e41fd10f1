"""recipes/csirl_robotics.py end to end on a tiny budget (both tasks from their shipped data), and its
configuration and data errors."""
from __future__ import annotations

import json
import os

import pytest
from robotics_budget import TINY_ROBOTICS_RUN

from torchrl_csirl.data import load_expert_demonstrations
from torchrl_csirl.methods.csirl import CSIRL_RECIPE
from torchrl_csirl.run import builders
from torchrl_csirl.run.config import ConfigError
from torchrl_csirl.run.run import ExpertDataError
from torchrl_csirl.scripts import csirl_robotics
from torchrl_csirl.tasks import resolve_scenario


def load_robotics(overrides):
    """The CSIRL recipe's configuration, relocate when no task is named (as recipes/csirl_robotics.py runs it)."""
    return CSIRL_RECIPE.load_config(overrides, default_task="relocate")

# rounds of 10 updates of a 2-critic ensemble on 32-transition batches
TINY = [*TINY_ROBOTICS_RUN, "replay_buffer.batch_size=32", "csirl.updates_per_round=10", "csirl.num_qvalue_nets=2"]


def _check_run(summary: dict, task: str) -> None:
    # 400 frames at optim.utd_ratio=0.1 (TINY_ROBOTICS_RUN): exactly 40 updates
    assert summary["scenario"] == task and summary["frames"] == 400 and summary["updates"] == 40
    assert 0.0 <= summary["accomplish_rate"] <= 1.0 and isinstance(summary["return"], float)
    run_dir = summary["run_dir"]
    for name in ("config.yaml", "metrics.jsonl", "policy.pt", "summary.json", "curriculum.png", "subgoals.png"):
        assert os.path.exists(os.path.join(run_dir, name)), name
    assert os.path.isdir(os.path.join(run_dir, "checkpoints", "last"))
    with open(os.path.join(run_dir, "summary.json")) as f:
        assert json.load(f)["return"] == summary["return"]


def test_relocate_end_to_end_from_the_shipped_dapg_data(tmp_path):
    summary = csirl_robotics.main(["env.task=relocate", *TINY, f"logger.output_dir={tmp_path}"])
    _check_run(summary, "relocate")
    assert summary["curriculum_length"] == 201  # the first DAPG trajectory: 200 steps + its last state


def test_antmaze_end_to_end_from_the_shipped_ant_data(tmp_path):
    summary = csirl_robotics.main(["env.task=antmaze-umaze", *TINY, f"logger.output_dir={tmp_path}"])
    _check_run(summary, "antmaze-umaze")
    first = load_expert_demonstrations("antmaze-umaze", 1)
    assert summary["curriculum_length"] == int(first.lengths[0]) + 1  # the first trajectory and its last state


def test_configuration_and_data_errors(tmp_path):
    with pytest.raises(ConfigError, match="model.ego_relative_features=true"):
        load_robotics(["model.ego_relative_features=true"])
    # a driving scene, named either way, is configured by the driving schema (one CSIRL script for every task)
    assert load_robotics(["env.task=merge"]).env == {"task": "merge", "scenario": "merge"}
    with pytest.warns(FutureWarning, match="env.scenario"):
        assert load_robotics(["env.scenario=merge"]).env == {"task": "merge", "scenario": "merge"}
    with pytest.raises(ConfigError, match="env.task=mergee: unknown task \\(did you mean merge\\?\\)"):
        load_robotics(["env.task=mergee"])
    with pytest.raises(ConfigError, match="env.task=relocate and env.scenario=antmaze-umaze: the same setting"):
        load_robotics(["env.task=relocate", "env.scenario=antmaze-umaze"])
    assert load_robotics(["env.task=relocate"]).env.task == "relocate"
    # a dataset of another task: one error naming both dimensions
    relocate_data = os.path.join(os.path.dirname(builders.__file__), "..", "..", "torchrl_csirl", "data", "experts",
                                 "relocate", "expert_25.npz")
    cfg = load_robotics(["env.task=antmaze-umaze", f"expert.path={os.path.abspath(relocate_data)}"])
    with pytest.raises(ExpertDataError, match="observations of size 39 and actions of size 30, but 'antmaze-umaze' has 29 and 8"):
        builders.load_experts(cfg.expert, resolve_scenario("antmaze-umaze"))
