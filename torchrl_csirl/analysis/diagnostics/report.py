"""A run's health report: every check of :mod:`~torchrl_csirl.analysis.diagnostics.checks` on one run, written as
``health.json`` and ``health.png`` in its directory.

:func:`health_report` reads a run's ``metrics.jsonl`` and, for a CSIRL run, probes its networks
(:func:`~torchrl_csirl.analysis.diagnostics.probe.probe_learner`); :func:`write_health_report` writes the two files and
returns the report. CSIRL writes it at the end of every run; ``torchrl-csirl diagnose <run dir>``
(:mod:`torchrl_csirl.scripts.diagnose`) writes it for a finished or stopped run from its last checkpoint.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from typing import Any

from torchrl_csirl.analysis.diagnostics.checks import (
    HealthCheck,
    action_saturation,
    critic_calibration,
    demonstrations_share_a_goal,
    expert_transitions_reward,
    learned_reward_share,
    matching_along_demonstrations,
    policy_entropy,
    reward_tracks_the_task,
    route_opening,
    states_off_the_demonstrations,
    subgoal_progress,
    subgoal_share,
    warm_start_kept,
    where_episodes_end,
)
from torchrl_csirl.analysis.diagnostics.probe import LearnerProbe, probe_learner

__all__ = ["HEALTH_FILE", "HEALTH_PICTURE", "HealthReport", "check_line", "health_report", "read_metrics", "write_health_report"]

HEALTH_FILE = "health.json"
HEALTH_PICTURE = "health.png"


@dataclass
class HealthReport:
    """Every check of one run.

    Attributes:
        run_dir: the run directory.
        task: the task's name.
        method: the method (``csirl``, ``csirl-b``, ...).
        checks: the checks, in the order they were made.
        rows: the run's per-round metrics (the picture's curves).
        probe: what the learner's networks measured (None: not probed).
    """

    run_dir: str
    task: str
    method: str
    checks: list[HealthCheck] = field(default_factory=list)
    rows: list[dict[str, Any]] = field(default_factory=list)
    probe: LearnerProbe | None = None

    @property
    def flagged(self) -> list[HealthCheck]:
        """The checks out of range."""
        return [c for c in self.checks if c.ok is False]

    def check(self, name: str) -> HealthCheck:
        """The check called ``name``."""
        for c in self.checks:
            if c.name == name:
                return c
        raise KeyError(f"no check {name!r}; checks: {', '.join(c.name for c in self.checks)}")

    def lines(self) -> list[str]:
        """One line per check (:func:`check_line`)."""
        return [check_line(c.as_dict()) for c in self.checks]

    def as_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (``health.json``)."""
        return {"run_dir": self.run_dir, "task": self.task, "method": self.method,
                "flagged": [c.name for c in self.flagged], "checks": [c.as_dict() for c in self.checks]}


def check_line(check: dict[str, Any]) -> str:
    """A check (a ``health.json`` entry) as one line: ``FLAG``, ``ok`` or ``--`` (too little to say), its name and
    its sentence.

    Examples:
        >>> check_line({"ok": False, "name": "subgoal_progress", "message": "the curriculum never moved"})
        'FLAG subgoal_progress: the curriculum never moved'
    """
    mark = {False: "FLAG", True: "ok  ", None: "--  "}[check["ok"]]
    return f"{mark} {check['name']}: {check['message']}"


def read_metrics(run_dir: str) -> list[dict[str, Any]]:
    """The per-round rows of ``<run_dir>/metrics.jsonl`` (empty when there is none)."""
    path = os.path.join(run_dir, "metrics.jsonl")
    if not os.path.isfile(path):
        return []
    with open(path, encoding="utf-8") as f:
        rows = [json.loads(line) for line in f if line.strip()]
    return [r for r in rows if "round" in r]


def _metrics_checks(rows: list[dict[str, Any]], action_dim: int, curriculum_length: int | None,
                    test: dict[str, Any] | None = None, demonstration_reward: float | None = None
                    ) -> list[HealthCheck]:
    checks = [reward_tracks_the_task(rows, test, demonstration_reward), policy_entropy(rows, action_dim),
              learned_reward_share(rows), warm_start_kept(rows)]
    subgoals = [int(r["subgoal"]) for r in rows if r.get("subgoal") is not None]
    if curriculum_length is not None:
        checks.append(subgoal_progress(subgoals, curriculum_length))
    return checks


def _moving_subgoal_share(run: Any) -> float | None:
    """The curriculum's subgoal, the one the probe scored against, as a share of its trajectory; None where the
    subgoal is fixed at the end from the start (``csirl.fixed_subgoal``: no curriculum to move on)."""
    if run.cfg.csirl.fixed_subgoal:
        return None
    return subgoal_share(run.parts.curriculum.subgoal, run.parts.curriculum.length)


def _demonstration_features(probe: LearnerProbe) -> list[Any]:
    """Every demonstration's matching features (its observations' matched entries; none where they are not the
    path's features)."""
    matched = list(probe.matched_features)
    if len(matched) != probe.path_features.shape[-1]:
        return []
    return [d[:, matched] for d in probe.demo_observations if d.ndim == 2 and d.shape[0]]


def _probe_checks(probe: LearnerProbe, expert_fraction: float, names: list[str] | None = None,
                  subgoal_share: float | None = None) -> list[HealthCheck]:
    return [
        critic_calibration(probe.expert_values, probe.expert_returns, "expert", probe.expert_entropy_returns),
        critic_calibration(probe.policy_values, probe.policy_returns, "policy", probe.policy_entropy_returns),
        matching_along_demonstrations(probe.matching_to_subgoal),
        route_opening(probe.matching_along_routes, probe.matching_target),
        expert_transitions_reward(probe.expert_rewards, probe.policy_rewards, expert_fraction),
        where_episodes_end(probe.final_features, probe.path_features, probe.episode_paths, subgoal_share,
                           _demonstration_features(probe), probe.matching_target),
        demonstrations_share_a_goal(probe.demo_final_features, probe.path_features, probe.goal_conditioned,
                                    probe.goal_gaps),
        states_off_the_demonstrations(probe.observations, probe.demo_observations, probe.matched_features, names),
        action_saturation(probe.actions),
    ]


def health_report(run: Any, method: str, *, episodes: int = 5, metrics_dir: str | None = None,
                  test: dict[str, Any] | None = None) -> HealthReport:
    """The health report of a built CSIRL run (:class:`~torchrl_csirl.run.assembly.Run` with
    :class:`~torchrl_csirl.methods.csirl.CSIRLParts`), from its metrics and its networks as they are now.

    Args:
        run: the run.
        method: its method's name.
        episodes: the policy's probe episodes (seeded from ``eval.seed``).
        metrics_dir: the directory whose ``metrics.jsonl`` holds the run's rounds (default: the run's).
        test: the run's final test (its summary: ``success_rate``, ``return``), where it has one.
    """
    cfg, parts = run.cfg, run.parts
    rows = read_metrics(metrics_dir or run.run_dir)
    report = HealthReport(metrics_dir or run.run_dir, run.spec.name, method, rows=rows)
    run.mirror.sync()
    report.probe = probe_learner(
        env=run.eval_env, policy=run.mirror.policy, loss=parts.modules.sac, transforms=run.online_buffer.transform,
        matching=parts.matching, demos=run.demos, gamma=cfg.csirl.gamma, max_steps=run.spec.max_steps,
        episodes=episodes, seed=cfg.eval.seed, device=run.device)
    to_subgoal = report.probe.matching_to_subgoal
    demonstration_reward = float(to_subgoal.mean()) if to_subgoal.numel() else None
    report.checks += _metrics_checks(rows, run.spec.action_dim, parts.curriculum.length, test, demonstration_reward)
    names = [run.spec.feature_name(i) for i in range(run.spec.obs_dim)]
    report.checks += _probe_checks(report.probe, cfg.replay_buffer.expert_fraction, names, _moving_subgoal_share(run))
    return report


def write_health_report(report: HealthReport, run_dir: str | None = None) -> dict[str, str]:
    """``health.json`` and ``health.png`` in ``run_dir`` (default: the report's); returns their paths."""
    from torchrl_csirl.analysis.visualization import plot_health

    run_dir = run_dir or report.run_dir
    path = os.path.join(run_dir, HEALTH_FILE)
    tmp = f"{path}.tmp"
    with open(tmp, "w", encoding="utf-8") as f:
        json.dump(report.as_dict(), f, indent=1, default=float)
    os.replace(tmp, path)
    picture = plot_health(report, os.path.join(run_dir, HEALTH_PICTURE))
    return {"health": path, "health_picture": os.fspath(picture)}
