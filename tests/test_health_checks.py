"""Every check of the health report flags a planted failure and passes its healthy twin (the smallest inputs that
must flag and must not); where_episodes_end tells a shortcut from an end off every demonstration; the thresholds
equal their frozen calibration (issue 110: a change after the held-out runs shows here) and every run that set one
has a record."""
from __future__ import annotations

import glob
import json
import os

import pytest
import torch

from torchrl_csirl.analysis.diagnostics import (
    CALIBRATION,
    LearnerProbe,
    action_saturation,
    calibration_runs,
    calibration_table,
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
    warm_start_kept,
    where_episodes_end,
)
from torchrl_csirl.analysis.diagnostics.calibration import current_values, frozen_values
from torchrl_csirl.analysis.diagnostics.report import _metrics_checks, _probe_checks

ROOT = os.path.join(os.path.dirname(__file__), "..")
#: the frozen thresholds (issue 110): change one only with the held-out runs made again
FROZEN = {"HACKING_RISE_SHARE": 0.25, "TASK_FLAT_SHARE": 0.05, "SOLVED": 0.9, "HACKING_RISE_FLOOR": 0.01,
          "WARM_START_KEPT_SHARE": 0.5, "VALUE_RATIO_LIMIT": 3.0, "OFF_PATH_SHARE": 0.2, "SHORT_PROGRESS": 0.5,
          "SHORTCUT_RATIO": 0.5, "SUBGOAL_LEAD_LIMIT": 0.5, "ENTROPY_FLOOR_PER_DIM": -3.0, "ACTION_BOUND": 0.99,
          "SATURATION_LIMIT": 0.5, "LEARNED_REWARD_SHARE_RANGE": (0.01, 0.8), "ROUTE_OPENING_SHARE": 0.1,
          "SHARED_GOAL_DISTANCE": 0.1, "SHARED_GOAL_SHARE": 0.5, "OFF_DEMONSTRATION_SD": 5.0, "_MAX_STATES": 4000,
          "_HORIZON_WEIGHT": 0.95}
LINE = torch.stack([torch.arange(11.0), torch.zeros(11)], -1)  # a straight path 10 long
#: a detour: down 5, across 2, up 5 to a goal 2 from the start (a wall between start and goal)
DETOUR = torch.cat([torch.stack([torch.zeros(6), -torch.arange(6.0)], -1),
                    torch.tensor([[1.0, -5.0], [2.0, -5.0]]),
                    torch.stack([torch.full((5,), 2.0), -torch.arange(4.0, -1.0, -1.0)], -1)])


def _rows(matching, success, frames=(1, 2, 3)):
    return [{"frames": f, "matching_reward_mean": m, "eval_success_rate": s, "eval_env_return": 1.0}
            for f, m, s in zip(frames, matching, success)]


def _off_the_demonstrations(shift: float):
    generator = torch.Generator().manual_seed(0)
    demos = [torch.randn(200, 3, generator=generator) for _ in range(2)]
    return states_off_the_demonstrations(torch.randn(100, 3, generator=generator) + torch.tensor([0.0, 0.0, shift]),
                                         demos)


RETURNS = torch.full((10,), 30.0)
#: per check: (the planted failure, its healthy twin)
PLANTED = {
    "reward_tracks_the_task": (lambda: reward_tracks_the_task(_rows((0.1, 0.2, 0.9), (0.0, 0.0, 0.0))),
                               lambda: reward_tracks_the_task(_rows((0.1, 0.2, 0.9), (0.0, 0.4, 0.9)))),
    "policy_entropy": (lambda: policy_entropy([{"entropy": -9.0, "alpha": 1e-4}], action_dim=2),
                       lambda: policy_entropy([{"entropy": -1.0, "alpha": 0.1}], action_dim=2)),
    "learned_reward_share": (lambda: learned_reward_share([{"intrinsic_reward_mean": 1e-4, "matching_reward_mean": 1.0}]),
                             lambda: learned_reward_share([{"intrinsic_reward_mean": 0.2, "matching_reward_mean": 0.8}])),
    "warm_start_kept": (lambda: warm_start_kept([{"frames": f, "eval_success_rate": s} for f, s in ((0, 0.4), (1, 0.0))]),
                        lambda: warm_start_kept([{"frames": f, "eval_success_rate": s} for f, s in ((0, 0.4), (1, 0.4))])),
    "subgoal_progress": (lambda: subgoal_progress([5, 5, 5], 40), lambda: subgoal_progress([5, 9, 20], 40)),
    "critic_calibration_expert": (
        lambda: critic_calibration(torch.full((5, 10), 3.0), RETURNS, "expert"),  # a tenth: under-valued
        lambda: critic_calibration(torch.full((5, 10), 33.0), RETURNS, "expert")),
    "critic_calibration_policy": (lambda: critic_calibration(torch.full((5, 10), 300.0), RETURNS, "policy"),
                                  lambda: critic_calibration(torch.full((5, 10), 27.0), RETURNS, "policy")),
    "matching_along_demonstrations": (lambda: matching_along_demonstrations(-torch.ones(5)),
                                      lambda: matching_along_demonstrations(torch.ones(5))),
    "route_opening": (lambda: route_opening([torch.tensor([-1.0, -1.0, 3.0, 3.0])]),
                      lambda: route_opening([torch.ones(4)])),
    "expert_transitions_reward": (lambda: expert_transitions_reward(torch.zeros(3), torch.ones(3), 0.25),
                                  lambda: expert_transitions_reward(torch.ones(3), torch.zeros(3), 0.25)),
    "where_episodes_end": (lambda: where_episodes_end(torch.tensor([[1.0, 0.0]]), LINE),
                           lambda: where_episodes_end(torch.tensor([[10.0, 0.0]]), LINE)),
    "demonstrations_share_a_goal": (
        lambda: demonstrations_share_a_goal(torch.tensor([[10.0, 0.0], [0.0, 5.0], [3.0, -4.0]]), LINE),
        lambda: demonstrations_share_a_goal(torch.tensor([[10.0, 0.0], [10.2, 0.1], [9.9, -0.1]]), LINE)),
    "states_off_the_demonstrations": (lambda: _off_the_demonstrations(12.0), lambda: _off_the_demonstrations(0.0)),
    "action_saturation": (lambda: action_saturation(torch.ones(10, 2)), lambda: action_saturation(torch.zeros(10, 2))),
}


def _probe() -> LearnerProbe:
    """The smallest probe every probe check reads (no network)."""
    return LearnerProbe(
        policy_values=torch.zeros(2, 3), policy_returns=torch.zeros(3), expert_values=torch.zeros(2, 3),
        expert_returns=torch.zeros(3), policy_rewards=torch.zeros(3), expert_rewards=torch.ones(3),
        matching_to_subgoal=torch.ones(3), final_features=LINE[-1:], demo_final_features=LINE[[-1, -1]],
        path_features=LINE, actions=torch.zeros(3, 2), matching_along_routes=(torch.ones(4),),
        observations=(torch.randn(5, 3),), demo_observations=(torch.randn(9, 3), torch.randn(9, 3)),
        matched_features=(0, 1))


def test_every_check_of_the_report_has_a_planted_failure():
    rows = _rows((0.1, 0.2, 0.3), (0.0, 0.5, 1.0))
    names = [c.name for c in (*_metrics_checks(rows, 2, 40), *_probe_checks(_probe(), 0.25))]
    assert sorted(names) == sorted(PLANTED)


@pytest.mark.parametrize("name", sorted(PLANTED))
def test_each_check_flags_its_planted_failure_and_passes_its_healthy_twin(name):
    flagged, healthy = (make() for make in PLANTED[name])
    assert (flagged.name, flagged.ok) == (name, False), flagged.message
    assert (healthy.name, healthy.ok) == (name, True), healthy.message


def test_critics_under_valuing_the_experts_states_name_both_causes():
    check = PLANTED["critic_calibration_expert"][0]()
    assert "does not continue the expert's route" in check.message and "under-value" in check.message
    assert "critic_calibration_policy" in check.message  # how to tell the causes apart


def test_a_goal_conditioned_reward_is_flagged_where_the_demonstrations_do_not_cover_the_episodes_goals():
    """PointMaze with a goal per episode: the check read 'ok' whatever the demonstrations; it now reads whether the
    demonstration each probe episode is matched against leads to its goal."""
    spread = torch.tensor([[10.0, 0.0], [0.0, 5.0], [3.0, -4.0]])  # the demonstrations end apart: a goal per episode
    uncovered = demonstrations_share_a_goal(spread, LINE, goal_conditioned=True, goal_gaps=[0.02, 0.3, 0.6])
    assert uncovered.ok is False and uncovered.figures["covered_share"] == pytest.approx(1 / 3)
    assert "do not cover the goals" in uncovered.message and "expert.num_trajectories" in uncovered.message
    covered = demonstrations_share_a_goal(spread, LINE, goal_conditioned=True, goal_gaps=[0.02, 0.05, 0.6])
    assert covered.ok is True and "demonstration of its goal" in covered.message
    assert demonstrations_share_a_goal(spread, LINE, goal_conditioned=True).ok is None  # no probe episode's goal


def test_where_episodes_end_names_a_shortcut_across_a_wall_and_the_target_that_pays_it():
    """On the detour, an episode stuck at the start's side of the wall, 0.4 below the start: the straight line to the
    goal is 2.04, the route along the demonstration its whole 12: a shortcut the straight-line target pays."""
    end = torch.tensor([[0.0, -0.4]])
    check = where_episodes_end(end, DETOUR, demonstrations=[DETOUR])
    assert check.ok is False and check.figures["episode_ends"] == ["shortcut"]
    assert check.figures["straight_to_target"][0] == pytest.approx(4.16 ** 0.5 / 12)
    assert check.figures["route_to_target"][0] == pytest.approx(1.0)
    assert "wall or a detour" in check.message and "csirl.matching_target=path" in check.message
    along = where_episodes_end(end, DETOUR, target="path")  # the target already measures along the path
    assert "csirl.matching_target=path)" in along.message and "the learner" in along.message
    # the subgoal ahead on the first leg: straight line and route agree, no shortcut, on the route short of the goal
    first_leg = where_episodes_end(end, DETOUR, subgoal_share=4 / 12)
    assert first_leg.figures["episode_ends"] == ["short"] and "short of the goal" in first_leg.message


def test_where_episodes_end_tells_an_end_off_every_demonstration_and_offers_the_anchor():
    """The issue's line, 73 % of the path's length from it, its nearest state the end: off every demonstration."""
    end = torch.tensor([[10.0, 7.3]])
    check = where_episodes_end(end, LINE, demonstrations=[LINE, LINE + torch.tensor([0.0, 0.5])])
    assert check.ok is False and check.figures["episode_ends"] == ["off"]
    assert check.figures["progress_median"] == 1.0 and check.figures["distance_over_path_length"] == pytest.approx(0.73)
    assert "off every demonstration" in check.message and "csirl.actor_pretrain_updates" in check.message
    assert "csirl.actor_bc_coef" in check.message
    # off its own path but on another demonstration's: it follows another route, not nowhere
    other = where_episodes_end(end, LINE, demonstrations=[LINE, LINE + torch.tensor([0.0, 7.3])])
    assert other.figures["episode_ends"] == ["other"] and "near another demonstration's states" in other.message
    # the most common end is named, with its count
    mixed = where_episodes_end(torch.tensor([[10.0, 7.3], [5.0, 8.0], [1.0, 0.0]]), LINE)
    assert mixed.figures["episode_ends"] == ["off", "off", "short"] and "2 of 3 end off" in mixed.message


def test_reward_tracks_the_task_tells_a_short_run_from_a_reward_paying_for_something_else():
    """Flagged either way; the line names the budget while the learner is paid less than the demonstration."""
    rows = _rows((0.1, 0.2, 0.9), (0.0, 0.0, 0.0), frames=(1000, 2000, 3000))
    short = reward_tracks_the_task(rows, demonstration_reward=2.0)
    assert short.ok is False and "collector.total_frames" in short.message and "3000 frames" in short.message
    assert "0.9 against 2" in short.message and not short.message.startswith("reward hacking")
    hacked = reward_tracks_the_task(rows, demonstration_reward=0.5)
    assert hacked.ok is False and hacked.message.startswith("reward hacking") and "collector.total_frames" not in hacked.message
    assert "paid 0.9 per step, the demonstration 0.5" in hacked.message


def test_the_short_held_out_runs_are_told_to_train_longer():
    """The held-out runs at a tenth of the budget (docs/runs/health-short), from their recorded figures (the first
    and last thirds of their rounds): each is flagged, and each line points at the budget, as every one of their
    learners is paid less than its demonstration."""
    keys = ("matching_reward", "success", "accomplish", "env_return")
    columns = ("matching_reward_mean", "eval_success_rate", "eval_accomplish_rate", "eval_env_return")
    runs = sorted(glob.glob(os.path.join(ROOT, "docs/runs/health-short/*")))
    assert len(runs) >= 6
    for run_dir in runs:
        with open(os.path.join(run_dir, "health.json"), encoding="utf-8") as f:
            recorded = next(c for c in json.load(f)["checks"] if c["name"] == "reward_tracks_the_task")
        with open(os.path.join(run_dir, "summary.json"), encoding="utf-8") as f:
            frames = json.load(f)["frames"]
        fig = recorded["figures"]
        first, last = ({c: fig[f"{k}_{when}"] for k, c in zip(keys, columns) if fig[f"{k}_{when}"] is not None}
                       for when in ("first", "last"))
        rows = [{"frames": frames, **first}, {**first}, {"frames": frames, **last}]
        check = reward_tracks_the_task(rows, demonstration_reward=fig["demonstration_reward"])
        assert check.ok is recorded["ok"] is False, run_dir
        assert "train longer (collector.total_frames)" in check.message and f"{frames} frames" in check.message, run_dir


def test_the_thresholds_are_frozen_at_their_calibration():
    assert frozen_values() == FROZEN
    assert current_values() == FROZEN


def test_every_run_that_set_a_threshold_has_a_record():
    runs = calibration_runs()
    assert runs and all(run.count("/") == 1 for run in runs)
    missing = [run for run in runs if not os.path.isfile(os.path.join(ROOT, "docs", "runs", run, "summary.json"))]
    assert not missing
    assert all(t.checks and set(t.checks) <= set(PLANTED) for t in CALIBRATION.values())


def test_the_own_task_page_shows_the_calibration():
    with open(os.path.join(ROOT, "docs", "own-task.md"), encoding="utf-8") as f:
        assert calibration_table() in f.read()
