"""The health report's calibration, frozen: every threshold of :mod:`~torchrl_csirl.analysis.diagnostics.checks` (and the
probe's measuring settings), its value, and the recorded runs (``docs/runs/<group>/<cell>``) that set it.

A threshold chosen on the runs it then diagnoses says little about runs it was not tuned on: this table
is the calibration set, so that a held-out set can leave it out, and ``tests/test_health_checks.py`` holds every
value, so that a change after the held-out runs shows in review. ``runs`` lists only runs with a record; what else
set a value (runs without a record, planted inputs) is in ``note``. The own-task page's table is
:func:`calibration_table` (``docs/own-task.md``, the calibration).

Examples:
    >>> from torchrl_csirl.analysis.diagnostics.calibration import CALIBRATION, frozen_values
    >>> frozen_values()["OFF_DEMONSTRATION_SD"], len(CALIBRATION["OFF_DEMONSTRATION_SD"].runs)
    (5.0, 9)
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from torchrl_csirl.analysis.diagnostics import checks, probe

__all__ = ["CALIBRATION", "Threshold", "calibration_runs", "calibration_table", "current_values", "frozen_values"]


@dataclass(frozen=True)
class Threshold:
    """One threshold of the health report.

    Attributes:
        name: the constant's name in ``module``.
        value: its frozen value.
        checks: the checks it decides.
        commit: the commit that set it (its value since).
        runs: the record directories under ``docs/runs`` that set it (none: chosen before any record kept a report,
            or on planted inputs alone).
        note: how they set it, and what else did.
        module: ``checks`` or ``probe``.
    """

    name: str
    value: Any
    checks: tuple[str, ...]
    commit: str
    runs: tuple[str, ...]
    note: str
    module: str = "checks"


def _cells(group: str, prefix: str, seeds: range = range(3)) -> tuple[str, ...]:
    """``group/<prefix>-s<seed>`` for each seed.

    Examples:
        >>> _cells("mujoco", "halfcheetah-csirl", range(2))
        ('mujoco/halfcheetah-csirl-s0', 'mujoco/halfcheetah-csirl-s1')
    """
    return tuple(f"{group}/{prefix}-s{seed}" for seed in seeds)


_ANTMAZE = "antmaze-umaze-csirl"
_ANTMAZE_GROUPS = ("antmaze-bc-path", "antmaze-bc-path-critic-warmup", "antmaze-bc-path-fixed-alpha",
                   "antmaze-bc-path-qvalue-scale", "antmaze-noexp", "antmaze-warmstart", "antmaze-warmstart-bc")
_POINTMAZE = tuple(cell for task in ("UMaze", "Medium") for method in ("csirl", "csirl-b", "csirl-nocur")
                   for cell in _cells("pointmaze", f"PointMaze_{task}-v3-{method}"))
_ONE_DEMONSTRATION = (*_cells("pointmaze-onedemo", "PointMaze_UMaze-v3-csirl"),
                      *_cells("pointmaze-onedemo", "PointMaze_Medium-v3-csirl"))
#: every record with a report when SUBGOAL_LEAD_LIMIT was set (e26b1ee): all of today's but AntMaze's published
#: settings, seed 2
_REPORTED_AT_E26B1EE = (*(cell for group in _ANTMAZE_GROUPS for cell in _cells(group, _ANTMAZE)),
                        *_cells("antmaze-paper", _ANTMAZE, range(2)), *_cells("mujoco", "halfcheetah-csirl"),
                        *_cells("halfcheetah-noexp", "halfcheetah-csirl-noexp"), *_POINTMAZE, *_ONE_DEMONSTRATION,
                        *_cells("pointmaze-fixed", "PointMaze_UMazeFixedGoal-v3-csirl"))
_BEFORE_ANY_RECORD = "set with the report before any record kept a report: chosen, not fitted"

_THRESHOLDS = (
    Threshold("HACKING_RISE_SHARE", 0.25, ("reward_tracks_the_task",), "7c03465", (), _BEFORE_ANY_RECORD),
    Threshold("TASK_FLAT_SHARE", 0.05, ("reward_tracks_the_task",), "7c03465", (), _BEFORE_ANY_RECORD),
    Threshold("SOLVED", 0.9, ("reward_tracks_the_task",), "48771c6", (
        *_cells("pointmaze-fixed", "PointMaze_UMazeFixedGoal-v3-csirl"), "pointmaze/PointMaze_UMaze-v3-csirl-b-s1"),
        "added after the one-goal U-maze runs (tests 0.92-1.00), whose matching reward rose at a task solved from the "
        "start, were flagged; the final test's clause (2955907) after CSIRL-B U-maze seed 1 (evaluations 0.6-0.9, "
        "test 0.96)"),
    Threshold("HACKING_RISE_FLOOR", 0.01, ("reward_tracks_the_task",), "32a8f67", (
        f"antmaze-noexp/{_ANTMAZE}-s2", *_ONE_DEMONSTRATION),
        "added so that AntMaze without expert transitions, seed 2 (-0.005 -> 0.009 against 2.94 paid to the "
        "demonstration), stops flagging (its record rewritten by diagnose); kept under the PointMaze runs with one "
        "demonstration, whose rises are 3-17 % of the demonstration's pay"),
    Threshold("WARM_START_KEPT_SHARE", 0.5, ("warm_start_kept",), "6bcca8c", (f"antmaze-warmstart/{_ANTMAZE}-s0",),
              "the one warm-started run recorded then (0.00 after the first round); docs/studies/scripts/warm_start_probe.py's "
              "cloned actors (8, 10, 17 of 50) have no record"),
    Threshold("VALUE_RATIO_LIMIT", 3.0, ("critic_calibration_expert", "critic_calibration_policy"), "7c03465", (),
              _BEFORE_ANY_RECORD + "; the exemption of under-valuation on the expert's states (f6d458d), set on the "
                                   "records docs/studies/scripts/entropy_bonus_records.py re-read, is undone: it could "
                                   "not flag"),
    Threshold("OFF_PATH_SHARE", 0.2, ("where_episodes_end",), "7c03465", (), _BEFORE_ANY_RECORD),
    Threshold("SHORT_PROGRESS", 0.5, ("where_episodes_end",), "7c03465", (), _BEFORE_ANY_RECORD),
    Threshold("SHORTCUT_RATIO", 0.5, ("where_episodes_end",), "67ccb05", (),
              "how an episode ends: planted inputs alone (tests/test_health_checks.py)"),
    Threshold("SUBGOAL_LEAD_LIMIT", 0.5, ("where_episodes_end",), "e26b1ee", _REPORTED_AT_E26B1EE,
              "read on the 56 records with a report then: 23 lead by more, every one failed, none that passed (its "
              "'none passed' holds on the runs it was set on)"),
    Threshold("ENTROPY_FLOOR_PER_DIM", -3.0, ("policy_entropy",), "7c03465", (), _BEFORE_ANY_RECORD),
    Threshold("ACTION_BOUND", 0.99, ("action_saturation",), "7c03465", (), _BEFORE_ANY_RECORD),
    Threshold("SATURATION_LIMIT", 0.5, ("action_saturation",), "7c03465", (), _BEFORE_ANY_RECORD),
    Threshold("LEARNED_REWARD_SHARE_RANGE", (0.01, 0.8), ("learned_reward_share",), "7c03465", (), _BEFORE_ANY_RECORD),
    Threshold("ROUTE_OPENING_SHARE", 0.1, ("route_opening",), "1623fee", _cells("antmaze-warmstart-bc", _ANTMAZE, range(2)),
              "the anchored AntMaze runs whose ants stood at the start, and AntMaze's shipped demonstrations "
              "(tests/test_diagnostics.py: the straight-line target charges over a fifth, the path target under 2 %)"),
    Threshold("SHARED_GOAL_DISTANCE", 0.1, ("demonstrations_share_a_goal",), "0bbc923",
              ("pointmaze-onedemo/PointMaze_UMaze-v3-csirl-s0",),
              "the U-maze run with one demonstration (12 % of the demonstrations end near the first one's end); its "
              "goal-conditioned reading uses the same tenth, set on no run"),
    Threshold("SHARED_GOAL_SHARE", 0.5, ("demonstrations_share_a_goal",), "0bbc923",
              ("pointmaze-onedemo/PointMaze_UMaze-v3-csirl-s0",), "as SHARED_GOAL_DISTANCE"),
    Threshold("OFF_DEMONSTRATION_SD", 5.0, ("states_off_the_demonstrations",), "9aeef0f", (
        *_cells("mujoco", "halfcheetah-csirl"), f"antmaze-bc-path/{_ANTMAZE}-s2", f"antmaze-bc-path-fixed-alpha/{_ANTMAZE}-s0",
        f"antmaze-bc-path-qvalue-scale/{_ANTMAZE}-s1", f"antmaze-warmstart-bc/{_ANTMAZE}-s2",
        f"antmaze-bc-path-critic-warmup/{_ANTMAZE}-s0", f"antmaze-noexp/{_ANTMAZE}-s2"),
        "14 runs of 5 probe episodes (re-measured 01228fa, 97f92ba): only the HalfCheetah's records hold the figures "
        "(the AntMaze runs' come from torchrl-csirl off-demos, not recorded); BC seed 0 on PointMaze U-maze, "
        "Medium, merge, Hopper and Relocate and the held-out demonstrations of six tasks have no record"),
    Threshold("_MAX_STATES", 4000, ("states_off_the_demonstrations",), "97f92ba", (),
              "how many of an episode's states are paired (a measuring setting, not a flag threshold)"),
    Threshold("_HORIZON_WEIGHT", 0.95, ("critic_calibration_expert", "critic_calibration_policy"), "7c03465", (),
              "the share of the discounted horizon a measurable return covers (a measuring setting)", module="probe"),
)

#: every threshold by its constant's name
CALIBRATION: dict[str, Threshold] = {t.name: t for t in _THRESHOLDS}


def frozen_values() -> dict[str, Any]:
    """Each threshold's frozen value, by name."""
    return {name: t.value for name, t in CALIBRATION.items()}


def current_values() -> dict[str, Any]:
    """Each threshold's value in the code now (its module's constant), by name."""
    modules = {"checks": checks, "probe": probe}
    return {name: getattr(modules[t.module], name) for name, t in CALIBRATION.items()}


def calibration_runs() -> list[str]:
    """Every record directory (``<group>/<cell>`` under ``docs/runs``) that set a threshold, sorted: the calibration
    set a held-out set leaves out."""
    return sorted({run for t in _THRESHOLDS for run in t.runs})


def _runs_cell(runs: tuple[str, ...]) -> str:
    """The runs of a threshold in a table cell: grouped by ``group``, its cells' seeds or names.

    Examples:
        >>> _runs_cell(("mujoco/halfcheetah-csirl-s0", "mujoco/halfcheetah-csirl-s1", "antmaze-noexp/antmaze-umaze-csirl-s2"))
        '`mujoco`: halfcheetah-csirl-s0, -s1; `antmaze-noexp`: antmaze-umaze-csirl-s2'
    """
    if not runs:
        return "none"
    groups: dict[str, list[str]] = {}
    for run in runs:
        group, cell = run.split("/", 1)
        groups.setdefault(group, []).append(cell)
    parts = []
    for group, cells in groups.items():
        named, previous = [], None
        for cell in cells:
            stem = cell.rsplit("-s", 1)[0]
            named.append(cell if stem != previous else f"-s{cell.rsplit('-s', 1)[1]}")
            previous = stem
        parts.append(f"`{group}`: " + ", ".join(named))
    return "; ".join(parts)


def calibration_table() -> str:
    """The calibration as a Markdown table (the own-task page's): threshold, value, checks, commit, runs, note."""
    lines = ["| threshold | value | checks | set in | runs that set it (`docs/runs`) | how |", "|---|---|---|---|---|---|"]
    for t in _THRESHOLDS:
        name = t.name if t.module == "checks" else f"{t.module}.{t.name}"
        lines.append(f"| `{name}` | {t.value} | {', '.join(f'`{c}`' for c in t.checks)} | {t.commit} | "
                     f"{_runs_cell(t.runs)} | {t.note} |")
    return "\n".join(lines)
