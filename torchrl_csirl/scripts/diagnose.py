"""Why a run failed: ``python -m torchrl_csirl.scripts.diagnose <run dir> [--episodes 5]`` (``torchrl-csirl diagnose``).

Writes the run's health report (:mod:`torchrl_csirl.analysis.diagnostics`) into its directory, ``health.json`` and
``health.png``, and prints one line per check: ``FLAG`` (out of range, with what it means), ``ok``, or ``--``
(the run gives too little to say). A CSIRL run is rebuilt from a copy of its configuration and last checkpoint
(the run itself is not changed, nor resumed) and its networks probed: the critics against Monte Carlo
returns of the learner's own reward, the matching reward on the demonstrations, where the policy's episodes
end, its actions. Any run's ``metrics.jsonl`` gives the rest (the training reward against the task, alpha and
entropy, the curriculum, the learned reward's share). The last line is the report as JSON.
CSIRL writes the same report at the end of every run (``eval.health_episodes``).
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile

from omegaconf import OmegaConf

from torchrl_csirl.run.config import ConfigError
from torchrl_csirl.run.run import run_script

__all__ = ["diagnose", "main"]


def _is_csirl(run_dir: str) -> bool:
    return "csirl" in OmegaConf.load(os.path.join(run_dir, "config.yaml"))


def _action_dim(cfg) -> int | None:
    """The action size of a saved run's task (None: a task this process cannot resolve, e.g. an unimported module's)."""
    from torchrl_csirl.tasks import resolve_scenario

    try:
        return resolve_scenario(cfg.env.task).action_dim
    except ValueError:
        return None


def _final_test(run_dir: str) -> dict | None:
    """The run's final test (``summary.json``), or None for a run that has not finished."""
    path = os.path.join(run_dir, "summary.json")
    if not os.path.isfile(path):
        return None
    try:
        with open(path, encoding="utf-8") as f:
            return json.load(f)
    except json.JSONDecodeError as e:
        raise ConfigError(f"diagnose {run_dir}: summary.json is not JSON ({e}); move it away to diagnose the run "
                          "from its metrics") from e


def _rebuilt(run_dir: str, workdir: str):
    """The CSIRL run rebuilt from a copy of its configuration and last checkpoint (one in-process collector)."""
    from torchrl_csirl.methods.csirl import CSIRL_RECIPE
    from torchrl_csirl.run.lifecycle import resume_run

    copy = os.path.join(workdir, "run")
    os.makedirs(copy)
    shutil.copy(os.path.join(run_dir, "config.yaml"), copy)
    shutil.copytree(os.path.join(run_dir, "checkpoints", "last"), os.path.join(copy, "checkpoints", "last"))
    cfg = CSIRL_RECIPE.load_run_config(copy, ["collector.num_workers=1", "collector.cut_episodes=true", "logger.backend=none",
                                              "logger.progress_bar=false", "checkpoint.save_buffer=false"])
    return resume_run(cfg, copy, os.path.join(copy, "checkpoints", "last"), CSIRL_RECIPE.trainer)


def diagnose(run_dir: str, episodes: int = 5) -> dict[str, object]:
    """The health report of the run in ``run_dir``, written there; returns it as a dict.

    Raises:
        ConfigError: one line, for a folder that is not a run (no ``config.yaml``) or a CSIRL run without a checkpoint.
    """
    from torchrl_csirl.analysis.diagnostics import (
        HealthReport,
        check_line,
        policy_entropy,
        read_metrics,
        reward_tracks_the_task,
        write_health_report,
    )

    run_dir = os.path.abspath(run_dir)
    if not os.path.isfile(os.path.join(run_dir, "config.yaml")):
        raise ConfigError(f"diagnose {run_dir}: not a run directory (no config.yaml)")
    if not _is_csirl(run_dir):  # a baseline: what its metrics say
        cfg = OmegaConf.load(os.path.join(run_dir, "config.yaml"))
        rows = read_metrics(run_dir)
        checks = [reward_tracks_the_task(rows, _final_test(run_dir))]
        action_dim = _action_dim(cfg)
        if action_dim is not None:
            checks.append(policy_entropy(rows, action_dim))
        report = HealthReport(run_dir, cfg.env.task, str(cfg.get("method")), rows=rows, checks=checks)
        write_health_report(report, run_dir)
        return report.as_dict() | {"lines": report.lines()}
    if not os.path.isfile(os.path.join(run_dir, "checkpoints", "last", "state.pt")):
        raise ConfigError(f"diagnose {run_dir}: no checkpoint to probe (checkpoints/last/state.pt)")
    from torchrl_csirl.methods.csirl import write_health

    with tempfile.TemporaryDirectory() as workdir:
        run = _rebuilt(run_dir, workdir)
        try:
            write_health(run, episodes, metrics_dir=run_dir, out_dir=run_dir, test=_final_test(run_dir))
        finally:
            run.close()
    with open(os.path.join(run_dir, "health.json"), encoding="utf-8") as f:
        report = json.load(f)
    return report | {"lines": [check_line(c) for c in report["checks"]]}


def main(argv: list[str] | None = None) -> dict[str, object]:
    parser = argparse.ArgumentParser(prog="torchrl-csirl diagnose", description=__doc__.split("\n")[0])
    parser.add_argument("run_dir", help="a run directory (recipes/csirl_highway.py, or a baseline's)")
    parser.add_argument("--episodes", type=int, default=5, help="the policy's probe episodes (CSIRL)")
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    report = diagnose(args.run_dir, args.episodes)
    for line in report.pop("lines"):
        print(line, file=sys.stderr)
    print(json.dumps({k: report[k] for k in ("run_dir", "task", "method", "flagged")}))
    return report


if __name__ == "__main__":
    run_script(main)
