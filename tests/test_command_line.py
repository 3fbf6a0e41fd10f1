"""The command line parsed once per run, and ``env.scenario`` read as ``env.task``."""
from __future__ import annotations

import os

import pytest
from omegaconf import OmegaConf

from torchrl_csirl.methods.baselines import IMITATION_RECIPE
from torchrl_csirl.methods.csirl import CSIRL_RECIPE
from torchrl_csirl.run import config


class _Built(Exception):
    pass


def _count_parses(monkeypatch: pytest.MonkeyPatch) -> list[object]:
    calls: list[object] = []
    real = config.parse_command_line

    def counted(argv):
        if not isinstance(argv, config.CommandLine):
            calls.append(argv)
        return real(argv)

    monkeypatch.setattr(config, "parse_command_line", counted)
    for module in ("run.recipes", "run.task_schemas", "methods.baselines"):
        monkeypatch.setattr(f"torchrl_csirl.{module}.parse_command_line", counted)
    monkeypatch.setattr("torchrl_csirl.scripts.csirl_highway.parse_command_line", counted)
    return calls


def _no_trainer(monkeypatch: pytest.MonkeyPatch, recipe) -> list:
    built = []

    def trainer(cfg, run_dir, *args, **kwargs):
        built.append(OmegaConf.load(os.path.join(run_dir, "config.yaml")))
        raise _Built

    object.__setattr__(recipe, "trainer", trainer)  # a frozen record; restored by restore_trainer
    return built


@pytest.fixture
def restore_trainer():
    kept = CSIRL_RECIPE.trainer
    yield
    object.__setattr__(CSIRL_RECIPE, "trainer", kept)


def test_the_raw_command_line_is_parsed_once_per_run(monkeypatch, tmp_path, restore_trainer):
    from torchrl_csirl.scripts import csirl_highway

    calls = _count_parses(monkeypatch)
    built = _no_trainer(monkeypatch, CSIRL_RECIPE)
    argv = ["env.task=roundabout", "seed=2", "collector.total_frames=1000", f"logger.output_dir={tmp_path}",
            "logger.backend=none"]
    with pytest.raises(_Built):
        csirl_highway.main(argv)
    assert len(calls) == 1, f"the raw key=value list was parsed {len(calls)} times: {calls}"
    saved = built[0]  # the run's config.yaml: the setting and its deprecated name's mirror
    assert saved.env.task == "roundabout" and saved.env.scenario == "roundabout"


def test_a_resumed_run_parses_its_command_line_once(monkeypatch, tmp_path, restore_trainer):
    run_dir = tmp_path / "old"
    (run_dir / "checkpoints" / "last").mkdir(parents=True)
    (run_dir / "checkpoints" / "last" / "state.pt").write_bytes(b"")
    cfg = CSIRL_RECIPE.configure(["env.task=roundabout", "collector.total_frames=1000"])
    OmegaConf.save(cfg, run_dir / "config.yaml")
    calls = _count_parses(monkeypatch)
    resumed = CSIRL_RECIPE.configure([f"checkpoint.resume={run_dir}", "collector.total_frames=2000"])
    assert len(calls) == 1
    assert resumed.env.task == "roundabout" and resumed.collector.total_frames == 2000
    assert resumed.checkpoint.resume == str(run_dir)


def test_env_scenario_is_read_as_env_task_with_a_deprecation_notice():
    with pytest.warns(FutureWarning, match="use env.task=roundabout"):
        command = config.parse_command_line(["env.scenario=roundabout", "seed=1"])
    assert command.values == {"env.task": "roundabout", "seed": "1"}
    with pytest.warns(FutureWarning):
        cfg = CSIRL_RECIPE.configure(["env.scenario=hopper"])
    assert cfg.env.task == "hopper" and cfg.model.ego_relative_features is False
    with pytest.warns(FutureWarning), pytest.raises(config.ConfigError, match="the same setting"):
        config.parse_command_line(["env.task=merge", "env.scenario=roundabout"])


def test_a_run_saved_with_env_scenario_only_resumes_as_env_task(tmp_path):
    cfg = IMITATION_RECIPE.configure(["method=bc", "env.task=roundabout"])
    saved = OmegaConf.to_container(cfg)
    del saved["env"]["task"]  # a run directory written before env.task: env.scenario only
    saved["env"]["scenario"] = "roundabout"
    OmegaConf.save(OmegaConf.create(saved), os.path.join(tmp_path, "config.yaml"))
    resumed = IMITATION_RECIPE.load_run_config(str(tmp_path), ["eval.episodes=3"])
    assert resumed.env.task == "roundabout" and resumed.env.scenario == "roundabout"
    assert resumed.eval.episodes == 3
