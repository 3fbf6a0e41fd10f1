"""Why a run failed: its health report (``health.json``, ``health.png``).

* :mod:`~torchrl_csirl.analysis.diagnostics.checks`: each check, a named function of plain figures, flagged in plain
  words when out of range (reward hacking, critics over- or under-valued, a curriculum that never moves,
  a collapsed entropy, saturated actions, a learned reward too small or too large, a matching reward that
  punishes the demonstrations or charges their route's first stretch, a reward that pays the policy more than
  the expert, episodes that end short of the goal, demonstrations that do not share the curriculum trajectory's goal,
  a policy whose states the demonstrations never visit).
* :mod:`~torchrl_csirl.analysis.diagnostics.probe`: the figures measured on a learner's own networks.
* :mod:`~torchrl_csirl.analysis.diagnostics.calibration`: every threshold's frozen value and the recorded runs that set it.
* :mod:`~torchrl_csirl.analysis.diagnostics.report`: every check of a run, written at the end of each CSIRL run and by
  ``torchrl-csirl diagnose <run dir>``.

Examples:
    >>> from torchrl_csirl.analysis.diagnostics import learned_reward_share
    >>> check = learned_reward_share([{"intrinsic_reward_mean": 1e-4, "matching_reward_mean": 0.5}])
    >>> check.ok, round(check.figures["share"], 4)
    (False, 0.0002)
"""
from torchrl_csirl.analysis.diagnostics.calibration import CALIBRATION, calibration_runs, calibration_table
from torchrl_csirl.analysis.diagnostics.checks import (
    OFF_DEMONSTRATION_SD,
    SUBGOAL_LEAD_LIMIT,
    HealthCheck,
    action_saturation,
    critic_calibration,
    curriculum_moved_on,
    demonstrations_share_a_goal,
    expert_transitions_reward,
    learned_reward_share,
    matching_along_demonstrations,
    nearest_state_distances,
    policy_entropy,
    reward_tracks_the_task,
    route_opening,
    states_off_the_demonstrations,
    subgoal_progress,
    subgoal_share,
    warm_start_kept,
    where_episodes_end,
)
from torchrl_csirl.analysis.diagnostics.probe import LearnerProbe, discounted_returns, flat_observations, measurable_states, probe_learner
from torchrl_csirl.analysis.diagnostics.report import (
    HEALTH_FILE,
    HEALTH_PICTURE,
    HealthReport,
    check_line,
    health_report,
    read_metrics,
    write_health_report,
)

__all__ = [
    "CALIBRATION",
    "HEALTH_FILE",
    "HEALTH_PICTURE",
    "OFF_DEMONSTRATION_SD",
    "SUBGOAL_LEAD_LIMIT",
    "HealthCheck",
    "HealthReport",
    "LearnerProbe",
    "action_saturation",
    "calibration_runs",
    "calibration_table",
    "check_line",
    "critic_calibration",
    "curriculum_moved_on",
    "demonstrations_share_a_goal",
    "discounted_returns",
    "expert_transitions_reward",
    "flat_observations",
    "health_report",
    "learned_reward_share",
    "matching_along_demonstrations",
    "measurable_states",
    "nearest_state_distances",
    "policy_entropy",
    "probe_learner",
    "read_metrics",
    "reward_tracks_the_task",
    "route_opening",
    "states_off_the_demonstrations",
    "subgoal_progress",
    "subgoal_share",
    "warm_start_kept",
    "where_episodes_end",
    "write_health_report",
]
