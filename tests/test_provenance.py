"""Provenance in every record (issue 110): a run's ``provenance.json``, its record, and ``torchrl-csirl compare``'s
configuration and code differences, with ``--one-change`` refusing a confounded pair, on two real tiny runs that
differ in two keys."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import time

import pytest
from omegaconf import OmegaConf
from test_recipe import TINY

from torchrl_csirl.run import provenance

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
#: test_record_runs.py's tiny budget: 2 rounds of 100 frames, 10 updates a batch
BUDGET = [*TINY, "optim.utd_ratio=0.1", "csirl.num_qvalue_nets=2", "collector.total_frames=200", "collector.num_workers=1",
          "eval.video=false", "logger.backend=none"]
#: the second run's two changes
CHANGES = ["replay_buffer.batch_size=32", "csirl.gamma=0.9"]


def _head() -> str | None:
    done = subprocess.run(["git", "-C", ROOT, "rev-parse", "HEAD"], capture_output=True, text=True, check=False)
    return done.stdout.strip() if done.returncode == 0 else None


@pytest.fixture(scope="module")
def two_runs(tmp_path_factory) -> tuple[str, str]:
    """Two finished tiny CSIRL runs on merge: the budget's defaults, and the same with :data:`CHANGES`."""
    from torchrl_csirl.scripts import csirl_highway

    out = tmp_path_factory.mktemp("runs")
    first = csirl_highway.main([*BUDGET, f"logger.output_dir={out}", "logger.exp_name=merge-a-s0"])
    second = csirl_highway.main([*BUDGET, *CHANGES, f"logger.output_dir={out}", "logger.exp_name=merge-b-s0"])
    return first["run_dir"], second["run_dir"]


def test_a_run_writes_its_provenance_and_its_record_keeps_it(two_runs, tmp_path):
    from torchrl_csirl.scripts import record

    run_dir = two_runs[0]
    prov = provenance.read_provenance(run_dir)
    assert prov["configuration"] == "config.yaml" and os.path.isfile(os.path.join(run_dir, "config.yaml"))
    assert prov["code"]["commit"] == _head()  # None where the tests run outside a checkout
    if prov["code"]["commit"] is not None:
        assert isinstance(prov["code"]["dirty"], bool)
        assert (prov["code"]["diff_sha256"] is not None) == prov["code"]["dirty"]
    versions = prov["versions"]
    assert {"python", "torch", "torchrl", "tensordict", "gymnasium", "highway-env", "gymnasium-robotics",
            "mujoco"} <= set(versions)
    assert versions["torch"] and versions["torchrl"] and versions["highway-env"]
    assert prov["machine"]["torch_threads"] >= 1 and prov["machine"]["cpu"]
    target = record.record_run(run_dir, str(tmp_path / "docs"))
    assert provenance.read_provenance(target) == prov
    from torchrl_csirl.scripts import summarize  # the group's code column: the commit, or 'provenance: unknown' for an older record

    assert summarize.code_of(target).startswith((prov["code"]["commit"] or "not a checkout")[:10])
    os.remove(os.path.join(target, provenance.PROVENANCE_FILE))
    assert summarize.code_of(target) == "provenance: unknown"


def test_provenance_is_cheap_and_never_fails(monkeypatch, tmp_path):
    start = time.perf_counter()
    provenance.collect_provenance()
    assert time.perf_counter() - start < 0.2
    assert provenance.code_state(str(tmp_path)) == provenance.UNKNOWN_CODE  # not a checkout (an installed wheel)

    def no_git(*args, **kwargs):
        raise FileNotFoundError("git")

    monkeypatch.setattr(provenance.subprocess, "run", no_git)
    assert provenance.collect_provenance()["code"] == provenance.UNKNOWN_CODE
    monkeypatch.setattr(provenance.importlib.metadata, "version", lambda name: (_ for _ in ()).throw(
        provenance.importlib.metadata.PackageNotFoundError(name)))
    assert set(provenance.installed_versions().values()) - {None} == {provenance.platform.python_version()}


def test_a_resume_appends_its_own_provenance(tmp_path):
    run_dir = str(tmp_path)
    first = provenance.write_provenance(run_dir)
    resumed = provenance.record_resume_provenance(run_dir, frames=400)
    assert resumed["code"] == first["code"] and [r["frames"] for r in resumed["resumed"]] == [400]
    assert provenance.read_provenance(run_dir) == resumed
    old = str(tmp_path / "old")  # a run started before provenance existed, resumed now
    os.makedirs(old)
    assert provenance.record_resume_provenance(old, frames=100)["code"] is None
    later = dict(resumed, resumed=[{**resumed["resumed"][0], "code": {**first["code"], "commit": "f00"}}])
    assert provenance.code_fields(later)["code.commit"] == f'{json.dumps(first["code"]["commit"])} -> "f00"'


def _copy(run_dir: str, to: str, edit=None) -> str:
    shutil.copytree(run_dir, to, ignore=shutil.ignore_patterns("checkpoints", "*.png", "policy.pt"))
    if edit is not None:
        edit(to)
    return to


def test_compare_runs_prints_every_difference_and_refuses_a_confounded_one_change(two_runs, tmp_path, capsys):
    from torchrl_csirl.scripts import compare

    first, second = two_runs
    result = compare.main([first, "--against", second, "--metrics", "accomplish_rate"])
    err = capsys.readouterr().err
    changed = result["differences"]["configuration"]
    assert set(changed) == {"replay_buffer.batch_size", "csirl.gamma"}, changed
    assert changed["replay_buffer.batch_size"]["first"] == {"64": 1} and changed["csirl.gamma"]["second"] == {"0.9": 1}
    assert result["differences"]["code"] == {} and result["differences"]["provenance_unknown"] == 0
    assert "replay_buffer.batch_size (between the sides)" in err and "csirl.gamma (between the sides)" in err
    assert "code: no difference" in err
    assert result["rows"][0]["test"] is None  # one seed a side: no test, no verdict

    with pytest.raises(SystemExit) as stop:
        compare.main([first, "--against", second, "--one-change", "csirl.gamma"])
    assert stop.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line == "torchrl-csirl compare: --one-change csirl.gamma refused: replay_buffer.batch_size differs between the sides"

    def one_key(run_dir: str) -> None:  # the first run as if it had changed csirl.gamma alone, at the same code
        cfg = OmegaConf.load(os.path.join(run_dir, "config.yaml"))
        cfg.csirl.gamma = 0.9
        OmegaConf.save(cfg, os.path.join(run_dir, "config.yaml"))

    only_gamma = _copy(first, str(tmp_path / "merge-g-s0"), one_key)
    assert compare.main([first, "--against", only_gamma, "--one-change", "csirl.gamma"])["one_change"] == "csirl.gamma"
    capsys.readouterr()

    def other_commit(run_dir: str) -> None:
        prov = provenance.read_provenance(run_dir)
        prov["code"] = {**prov["code"], "commit": "0" * 40}
        with open(os.path.join(run_dir, provenance.PROVENANCE_FILE), "w") as f:
            json.dump(prov, f)

    elsewhere = _copy(only_gamma, str(tmp_path / "merge-c-s0"), other_commit)
    with pytest.raises(SystemExit):
        compare.main([first, "--against", elsewhere, "--one-change", "csirl.gamma"])
    assert capsys.readouterr().err.strip().endswith("code.commit differs between the sides")

    unknown = _copy(second, str(tmp_path / "merge-u-s0"), lambda d: os.remove(os.path.join(d, provenance.PROVENANCE_FILE)))
    with pytest.raises(SystemExit) as stop:
        compare.main([first, "--against", unknown, "--one-change", "csirl.gamma"])
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert stop.value.code == 2
    assert "provenance unknown for 1 run: cannot show a one-change comparison" in line
    # a key set aside by name is no change; the command line's output says so
    kept = compare.main([first, "--against", second, "--one-change", "csirl.gamma", "--ignore", "replay_buffer."])
    assert set(kept["differences"]["configuration"]) == {"csirl.gamma"}
    assert "set aside (--ignore): replay_buffer." in capsys.readouterr().err
