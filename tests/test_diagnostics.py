"""The health report names what is wrong with a run: planted failures on a real merge learner (a sign-flipped
matching reward, critics with an inflated bias, an actor pinned at its bounds, a curriculum that cannot move), each
check on its own figures, and the report written at the end of a run and by ``torchrl-csirl diagnose`` without touching the run."""
from __future__ import annotations

import csv
import json
import math
import os

import pytest
import torch

from torchrl_csirl.analysis.diagnostics import (
    OFF_DEMONSTRATION_SD,
    action_saturation,
    critic_calibration,
    demonstrations_share_a_goal,
    expert_transitions_reward,
    health_report,
    learned_reward_share,
    policy_entropy,
    reward_tracks_the_task,
    route_opening,
    states_off_the_demonstrations,
    subgoal_progress,
    warm_start_kept,
    where_episodes_end,
)
from torchrl_csirl.methods import csirl
from torchrl_csirl.run.builders import load_experts
from torchrl_csirl.scripts import csirl_highway, diagnose
from torchrl_csirl.tasks import resolve_scenario

TINY = ["collector.frames_per_batch=100", "collector.cut_episodes=true", "collector.init_random_frames=100",
        "collector.num_workers=1", "collector.main_threads=1", "replay_buffer.warmup_frames=100",
        "replay_buffer.batch_size=64", "csirl.updates_per_round=20", "optim.utd_ratio=0.5", "eval.episodes=1",
        "eval.final_episodes=2", "eval.video=false", "eval.health_episodes=2", "logger.progress_bar=false"]


@pytest.fixture(scope="module")
def merge_run(tmp_path_factory):
    """A CSIRL merge learner, built (no training): the probe reads its networks as they are."""
    out = tmp_path_factory.mktemp("learner")
    cfg = csirl.load_config([*TINY, "logger.backend=none", f"logger.output_dir={out}"])
    run = csirl.make_trainer(cfg, str(out))
    yield run
    run.close()


def _critics_output_bias(run) -> list[torch.Tensor]:
    """The output-layer biases of the trained critics (one value per critic)."""
    params = run.parts.modules.sac.qvalue_network_params
    return [t for key, t in params.items(True, True) if key[-1] == "bias" and t.shape[-1] == 1]


def test_a_sign_flipped_matching_reward_is_named(merge_run):
    control = health_report(merge_run, "csirl", episodes=1).check("matching_along_demonstrations")
    assert control.ok is True
    merge_run.parts.matching.sign = -1.0
    try:
        flipped = health_report(merge_run, "csirl", episodes=1)
    finally:
        merge_run.parts.matching.sign = 1.0
    check = flipped.check("matching_along_demonstrations")
    assert check.ok is False and "moving like the expert is punished" in check.message
    assert check.figures["mean"] == pytest.approx(-control.figures["mean"], rel=1e-5)
    assert "matching_along_demonstrations" in flipped.as_dict()["flagged"]


def test_critics_with_an_inflated_bias_are_named_over_valued(merge_run):
    control = health_report(merge_run, "csirl", episodes=1).check("critic_calibration_expert")
    assert "over-value" not in control.message
    biases = _critics_output_bias(merge_run)
    assert biases, "no output-layer bias found in the critics' parameters"
    with torch.no_grad():
        for bias in biases:
            bias += 1e4
    try:
        report = health_report(merge_run, "csirl", episodes=1)
    finally:
        with torch.no_grad():
            for bias in biases:
                bias -= 1e4
    check = report.check("critic_calibration_expert")
    assert check.ok is False and "over-value the expert's states" in check.message
    assert check.figures["value_mean"] > 1e4 - 10
    assert report.check("critic_calibration_policy").ok is False


def test_an_actor_pinned_at_its_bounds_is_named_saturated(merge_run):
    """The actor's output layer shifted far positive: its squashed actions sit at +1, which no recorded run shows."""
    control = health_report(merge_run, "csirl", episodes=1).check("action_saturation")
    assert control.ok is True
    params = merge_run.parts.modules.sac.actor_network_params
    out_bias = [t for key, t in params.items(True, True) if key[-1] == "bias"][-1]
    with torch.no_grad():
        out_bias += 1e3
    try:
        check = health_report(merge_run, "csirl", episodes=1).check("action_saturation")
    finally:
        with torch.no_grad():
            out_bias -= 1e3
    assert check.ok is False and "sit at a bound" in check.message and check.figures["saturated_share"] > 0.9


def test_the_critics_are_read_against_the_return_they_estimate_with_the_entropy_bonus(merge_run):
    """The probe's returns hold SAC's entropy bonus beside the learner's reward: ten times alpha, ten times the
    bonus's part, the reward's part unchanged (the same seeded episodes and draws)."""
    loss = merge_run.parts.modules.sac
    torch.manual_seed(0)  # the same draws of the policy's actions in both probes
    first = health_report(merge_run, "csirl", episodes=1).probe
    with torch.no_grad():
        loss.log_alpha += math.log(10.0)
    try:
        torch.manual_seed(0)
        tenfold = health_report(merge_run, "csirl", episodes=1).probe
    finally:
        with torch.no_grad():
            loss.log_alpha -= math.log(10.0)
    assert first.policy_entropy_returns.shape == first.policy_returns.shape and first.policy_returns.numel() > 0
    assert first.policy_entropy_returns.abs().sum() > 0
    reward_part = first.policy_returns - first.policy_entropy_returns
    torch.testing.assert_close(tenfold.policy_returns - tenfold.policy_entropy_returns, reward_part)
    ratio = tenfold.policy_entropy_returns.mean() / first.policy_entropy_returns.mean()
    assert ratio == pytest.approx(10.0, rel=1e-4)
    assert first.expert_entropy_returns.shape == first.expert_returns.shape


def test_each_check_flags_its_own_failure_and_passes_a_healthy_figure():
    hacked = [{"frames": f, "matching_reward_mean": r, "eval_success_rate": 0.0, "eval_env_return": 1.0}
              for f, r in ((1, 0.1), (2, 0.2), (3, 0.9))]
    healthy = [dict(r, eval_success_rate=s) for r, s in zip(hacked, (0.0, 0.4, 0.9))]
    assert reward_tracks_the_task(hacked).ok is False and reward_tracks_the_task(healthy).ok is True
    assert reward_tracks_the_task(hacked[:2]).ok is None
    solved = [dict(r, eval_success_rate=1.0) for r in hacked]  # flat at the top: the policy got better at the task
    assert reward_tracks_the_task(solved).ok is True
    # the last third's 10-episode evaluations dip while the final test (50 episodes) solves the task: no hacking; a
    # test that confirms the dip still flags
    dipped = [dict(r, eval_success_rate=s) for r, s in zip(hacked, (1.0, 0.9, 0.6))]
    assert reward_tracks_the_task(dipped).ok is False
    held = reward_tracks_the_task(dipped, test={"success_rate": 0.96, "return": 0.96})
    assert held.ok is True and held.figures["test_success"] == 0.96
    assert reward_tracks_the_task(dipped, test={"success_rate": 0.6, "return": 0.6}).ok is False
    returns = torch.full((10,), 30.0)
    over = critic_calibration(torch.full((5, 10), 300.0), returns, "expert").message
    under = critic_calibration(torch.full((5, 10), 3.0), returns, "policy").message
    assert "over-value" in over and "under-value" in under
    # the remedies point the right way: a minimum over more critics lowers the targets, over fewer raises them
    assert "more critics" in over and "expert_fraction" in over and "fewer" in under
    assert critic_calibration(torch.full((5, 10), 33.0), returns, "expert").ok is True
    # Q(s, a) values the policy's continuation: below the demonstration's return on the expert's states, the message
    # names both causes (a policy that leaves the expert's route, critics that under-value) and how to tell them apart
    below = critic_calibration(torch.full((5, 10), 3.0), returns, "expert")
    assert below.ok is False and "does not continue the expert's route" in below.message
    assert "critic_calibration_policy" in below.message
    # soft critics: a return whose entropy bonus is negative (SAC's target entropy -dim(A)) is read with it
    soft = critic_calibration(torch.full((5, 10), -60.0), torch.full((10,), -55.0), "policy", torch.full((10,), -75.0))
    assert soft.ok is True and soft.figures["entropy_return_mean"] == -75.0 and "entropy bonus" in soft.message
    path = torch.stack([torch.arange(11.0), torch.zeros(11)], -1)
    assert where_episodes_end(torch.tensor([[10.0, 0.0], [9.5, 0.1]]), path).ok is True
    short = where_episodes_end(torch.tensor([[1.0, 0.0]]), path)
    assert short.ok is False and short.figures["progress_median"] == pytest.approx(0.1)
    assert "moved on without the policy" not in short.message  # no curriculum given
    # the subgoal far ahead of where the episodes stop: the curriculum moved on without the policy (AntMaze's runs)
    ahead = where_episodes_end(torch.tensor([[1.0, 0.0]]), path, subgoal_share=0.98)
    assert ahead.ok is False and "moved on without the policy" in ahead.message
    assert ahead.figures["subgoal_lead"] == pytest.approx(0.88)
    assert "moved on" not in where_episodes_end(torch.tensor([[1.0, 0.0]]), path, subgoal_share=0.3).message
    assert "without a curriculum" not in ahead.message  # not at the end: the curriculum still sets the subgoal
    at_end = where_episodes_end(torch.tensor([[1.0, 0.0]]), path, subgoal_share=1.0)
    assert "trains as it would without a curriculum" in at_end.message
    assert where_episodes_end(torch.tensor([[10.0, 0.0]]), path, subgoal_share=1.0).ok is True  # level: healthy
    # a goal-conditioned matching reward: each episode against the demonstration of its goal (here, leftward)
    left = -path
    ends = torch.tensor([[10.0, 0.0], [-10.0, 0.0]])
    assert where_episodes_end(ends, path).ok is False  # the second episode is 20 away from the first path's end
    own = where_episodes_end(ends, path, [path, left])
    assert own.ok is True and own.figures["progress"] == [1.0, 1.0] and "of its goal" in own.message
    short_of_goals = where_episodes_end(torch.tensor([[1.0, 0.0], [-1.0, 0.0]]), path, [path, left], subgoal_share=0.9)
    assert short_of_goals.ok is False and "the same share of each goal's demonstration" in short_of_goals.message
    assert subgoal_progress([5, 5, 5, 5], 40).ok is False and subgoal_progress([5, 9, 20], 40).ok is True
    assert policy_entropy([{"entropy": -9.0, "alpha": 1e-4}], action_dim=2).ok is False
    assert action_saturation(torch.ones(10, 2)).ok is False and action_saturation(torch.zeros(10, 2)).ok is True
    assert learned_reward_share([{"intrinsic_reward_mean": 5.0, "matching_reward_mean": 0.1}]).ok is False
    assert learned_reward_share([{"intrinsic_reward_mean": 0.2, "matching_reward_mean": 0.8}]).ok is True
    assert expert_transitions_reward(torch.zeros(3), torch.ones(3), 0.25).ok is False
    same_goal = torch.tensor([[10.0, 0.0], [10.2, 0.1], [9.9, -0.1]])
    assert demonstrations_share_a_goal(same_goal, path).ok is True
    warm = [{"frames": f, "eval_success_rate": v, "eval_accomplish_rate": v} for f, v in ((0, 0.2), (10, 0.0), (20, 0.3))]
    lost = warm_start_kept(warm[:2])
    assert lost.ok is False and "undid the warm start" in lost.message and lost.figures["warm_start"] == 0.2
    assert "csirl.actor_bc_coef keeps cloning" in lost.message  # the remedy a run without the term has not tried
    anchored = warm_start_kept([dict(r, actor_bc_mse=0.01) for r in warm[:2]])  # the term was on: not offered again
    assert anchored.figures["anchored"] and "even with cloning" in anchored.message
    assert warm_start_kept(warm).ok is True and warm_start_kept(warm[1:]).ok is None
    progress = warm_start_kept([dict(r, eval_success_rate=0.0) for r in warm])  # no success: the accomplish rate
    assert progress.ok is True and progress.figures["metric"] == "accomplish rate"
    assert warm_start_kept([dict(r, eval_success_rate=0.0, eval_accomplish_rate=0.0) for r in warm]).ok is None
    spread = demonstrations_share_a_goal(torch.tensor([[10.0, 0.0], [0.0, 5.0], [3.0, -4.0]]), path)
    assert spread.ok is False and "the goal changes from episode to episode" in spread.message


def test_a_near_zero_matching_reward_that_rises_a_little_is_not_called_hacking():
    """A recorded AntMaze run whose ant stands still: its matching reward per step went from -0.005 to 0.009 (a large
    rise against its own near-zero start) where the demonstration is paid about 3 per step."""
    record = os.path.join(os.path.dirname(__file__), "..", "docs", "runs", "antmaze-noexp", "antmaze-umaze-csirl-s2")
    by_frames: dict[int, dict] = {}  # a record keeps its evaluations in metrics.jsonl, its rounds in rounds.csv
    with open(os.path.join(record, "rounds.csv"), newline="", encoding="utf-8") as f:
        for r in csv.DictReader(f):
            by_frames[int(r["frames"])] = {"frames": int(r["frames"]),
                                           "matching_reward_mean": float(r["matching_reward_mean"])}
    with open(os.path.join(record, "metrics.jsonl"), encoding="utf-8") as f:
        for r in map(json.loads, f):
            if r["frames"] in by_frames:
                by_frames[r["frames"]].update(r)
    rows = [by_frames[k] for k in sorted(by_frames)]
    with open(os.path.join(record, "health.json"), encoding="utf-8") as f:
        recorded = {c["name"]: c for c in json.load(f)["checks"]}
    paid = recorded["matching_along_demonstrations"]["figures"]["mean"]
    assert paid > 1.0
    assert reward_tracks_the_task(rows).ok is False  # without the demonstration's scale: the relative rise alone
    check = reward_tracks_the_task(rows, demonstration_reward=paid)
    assert check.ok is True and "too small to be hacking" in check.message
    assert check.figures["demonstration_reward"] == paid
    # the same rise scaled up to a twentieth of the demonstration's pay (the PointMaze runs that chased the wrong
    # goal rose by 3 % to 17 % of it) is hacking again
    scaled = [dict(r, matching_reward_mean=r["matching_reward_mean"] * 0.05 * paid / 0.014) for r in rows]
    assert reward_tracks_the_task(scaled, demonstration_reward=paid).ok is False


def test_a_run_writes_its_report_and_diagnose_rewrites_it_without_touching_the_run(tmp_path, capsys):
    summary = csirl_highway.main([*TINY, "collector.total_frames=300", "logger.backend=csv",
                                  "csirl.actor_pretrain_updates=5", f"logger.output_dir={tmp_path}"])
    run_dir = summary["run_dir"]
    with open(os.path.join(run_dir, "health.json")) as f:
        written = json.load(f)
    # the warm-started actor is evaluated before any update: the learning curve's first point, outside the auc
    with open(os.path.join(run_dir, "metrics.jsonl")) as f:
        evaluated = [row for row in map(json.loads, f) if "eval_accomplish_rate" in row]
    assert evaluated[0]["frames"] == 0 and evaluated[0]["updates"] == 0 and len(evaluated) > 1
    during = [row["eval_accomplish_rate"] for row in evaluated[1:]]
    assert summary["auc"] == pytest.approx(sum(during) / len(during))
    assert "actor warm start, before any update: success_rate" in capsys.readouterr().err
    assert "warm_start_kept" in {c["name"] for c in written["checks"]}
    assert summary["health"] == os.path.join(run_dir, "health.json") and os.path.getsize(summary["health_picture"]) > 0
    assert written["flagged"] == summary["health_flagged"]
    assert {c["name"] for c in written["checks"]} >= {"reward_tracks_the_task", "critic_calibration_expert",
                                                      "matching_along_demonstrations", "where_episodes_end"}
    before = {name: os.path.getmtime(os.path.join(run_dir, name)) for name in ("config.yaml", "metrics.jsonl")}
    os.remove(os.path.join(run_dir, "health.json"))
    report = diagnose.main([run_dir, "--episodes", "2"])
    assert report["run_dir"] == run_dir and os.path.isfile(os.path.join(run_dir, "health.json"))
    assert {c["name"] for c in report["checks"]} == {c["name"] for c in written["checks"]}
    assert before == {name: os.path.getmtime(os.path.join(run_dir, name)) for name in before}
    assert not os.path.exists(os.path.join(run_dir, "resumes.jsonl"))


def test_a_curriculum_that_cannot_move_is_named_in_a_real_run(tmp_path):
    """``csirl.delta=1e12``: no ratio of the critics' dispersion along the demonstration crosses it, so the subgoal
    stays where it starts, which no recorded run shows; the run's own report flags it."""
    summary = csirl_highway.main([*TINY, "collector.total_frames=400", "csirl.delta=1e12", "logger.backend=csv",
                                  f"logger.output_dir={tmp_path}"])
    with open(os.path.join(summary["run_dir"], "health.json")) as f:
        check = next(c for c in json.load(f)["checks"] if c["name"] == "subgoal_progress")
    assert check["ok"] is False and "never moved" in check["message"], check
    assert len(set(check["figures"]["subgoals"])) == 1 and len(check["figures"]["subgoals"]) >= 3


def test_diagnose_refuses_a_folder_that_is_not_a_run(tmp_path):
    from torchrl_csirl.run.config import ConfigError

    with pytest.raises(ConfigError, match="not a run directory"):
        diagnose.diagnose(str(tmp_path))


@pytest.mark.parametrize("target, subgoal, flagged", [("final", -1, True), ("final", 70, False), ("path", -1, False)])
def test_route_opening_names_a_straight_line_target_across_the_antmazes_wall(target, subgoal, flagged):
    """AntMaze U-maze's shipped demonstrations: with the subgoal past the U's turn, the straight line to it (``final``)
    charges the route's first leg (it leads away from the goal); along the expert's path (``path``) it pays."""
    cfg = csirl.load_config(["env.task=antmaze-umaze", f"csirl.matching_target={target}"])
    spec = resolve_scenario("antmaze-umaze")
    demos = load_experts(cfg.expert, spec)
    curriculum = demos.trajectory_observations(0, include_final=True)
    matching = csirl.make_matching(cfg, spec, curriculum, subgoal % len(curriculum))
    routes = [matching(demos.trajectory(k))["next", matching.out_key].reshape(-1) for k in range(1, 6)]
    check = route_opening(routes, target)
    assert check.ok is (not flagged)
    if flagged:
        assert check.figures["opening_share"] > 0.2 and "csirl.matching_target=path" in check.message
    else:
        assert check.figures["opening_share"] < 0.02


def _halfcheetah_demonstration() -> tuple[torch.Tensor, object]:
    """The HalfCheetah's shipped demonstration's observations ``[L, D]`` and the task's spec."""
    spec = resolve_scenario("halfcheetah")
    cfg = csirl.CSIRL_RECIPE.load_config(["env.task=halfcheetah"])
    demos = load_experts(cfg.expert, spec)
    return demos.trajectory(0)["observation"].reshape(-1, spec.obs_dim).float(), spec


def test_a_cheetah_on_its_back_is_named_off_the_demonstrations():
    """The HalfCheetah's demonstration, its second half as the policy's states against its first half: in range; the
    same states with the torso turned half a turn (a cheetah on its back, moving its x as an upright one does):
    flagged, the torso's angle named first."""
    demonstration, spec = _halfcheetah_demonstration()
    half = demonstration.shape[0] // 2
    names = [spec.feature_name(i) for i in range(spec.obs_dim)]
    upright = states_off_the_demonstrations(demonstration[half:], [demonstration[:half]], spec.position_feature_indices,
                                            names)
    assert upright.ok is True and upright.figures["largest_gap_sd"] < 1
    flipped_states = demonstration[half:].clone()
    flipped_states[:, names.index("angle")] += math.pi
    flipped = states_off_the_demonstrations(flipped_states, [demonstration[:half]], spec.position_feature_indices, names)
    assert flipped.ok is False and flipped.figures["farthest_features"][0] == "angle"
    assert flipped.figures["largest_gap_sd"] > OFF_DEMONSTRATION_SD and "never does" in flipped.message
    # one episode on its back among four upright ones is read on its own, not averaged away
    upright_episodes = list(demonstration[half:].chunk(4))
    one_in_five = states_off_the_demonstrations(upright_episodes[:2] + [flipped_states] + upright_episodes[2:],
                                                [demonstration[:half]], spec.position_feature_indices, names)
    assert one_in_five.ok is False and one_in_five.figures["episodes_off"] == 1
    assert one_in_five.figures["worst_episode"] == 2 and "in 1 of 5 episode(s)" in one_in_five.message
    assert one_in_five.figures["largest_gap_sd"] == pytest.approx(flipped.figures["largest_gap_sd"])
    # an empty episode keeps its place; a stacked [E, T, D] tensor is E episodes
    with_empty = states_off_the_demonstrations([torch.zeros(0, spec.obs_dim), flipped_states], [demonstration[:half]],
                                               spec.position_feature_indices, names)
    assert with_empty.figures["worst_episode"] == 1 and with_empty.figures["episode_largest_gaps_sd"][0] is None
    assert "in 1 of 1 episode(s)" in with_empty.message
    stacked = torch.stack([demonstration[half:half + 200], flipped_states[:200]])
    assert states_off_the_demonstrations(stacked, [demonstration[:half]], spec.position_feature_indices,
                                         names).figures["worst_episode"] == 1
    # the matching feature (the torso's x) is not read: moving it anywhere changes nothing
    moved = demonstration[half:].clone()
    moved[:, spec.position_feature_indices[0]] += 1e3
    assert states_off_the_demonstrations(moved, [demonstration[:half]], spec.position_feature_indices).figures[
        "largest_gap_sd"] == pytest.approx(upright.figures["largest_gap_sd"])


def test_off_the_demonstrations_reads_a_long_episode_without_aliasing():
    """An episode longer than the states the check pairs, whose states alternate every step (a policy that flips its
    actions each step): the subset it pairs gives the episode's own mean gap, where every other state would give the
    far half's alone."""
    generator = torch.Generator().manual_seed(0)
    demos = [torch.randn(2000, 3, generator=generator)]
    episode = torch.randn(6000, 3, generator=generator)
    episode[::2, 2] += 3.0  # every other state off in its last entry
    whole = states_off_the_demonstrations(episode, demos)  # more states than it pairs
    halves = states_off_the_demonstrations(list(episode.chunk(2)), demos)  # each paired in full
    exact = sum(halves.figures["episode_largest_gaps_sd"]) / 2
    assert whole.figures["farthest_features"][0] == "obs[2]"
    assert whole.figures["largest_gap_sd"] == pytest.approx(exact, rel=0.05)
    even = states_off_the_demonstrations(episode[::2], demos).figures["largest_gap_sd"]
    assert even > 1.3 * exact  # what a stride of two would have read


def test_off_the_demonstrations_names_a_blown_up_simulation_and_reads_tensor_indices():
    demonstration, spec = _halfcheetah_demonstration()
    half = demonstration.shape[0] // 2
    blown = demonstration[half:].clone()
    blown[3, 2] = float("nan")
    check = states_off_the_demonstrations(blown, [demonstration[:half]], spec.position_feature_indices)
    assert check.ok is False and check.figures["non_finite_entries"] == [2] and "NaN" in check.message
    as_tensor = states_off_the_demonstrations(demonstration[half:], [demonstration[:half]],
                                              torch.tensor(spec.position_feature_indices))
    assert as_tensor.figures["entries"] == spec.obs_dim - len(spec.position_feature_indices)
    narrow = states_off_the_demonstrations(demonstration[half:, :5], [demonstration[:half]])
    assert narrow.ok is None and "nothing to compare" in narrow.message


def test_the_report_sets_the_policys_states_against_the_demonstrations(merge_run):
    check = health_report(merge_run, "csirl", episodes=1).check("states_off_the_demonstrations")
    assert check.ok is not None and check.figures["entries"] > 0 and len(check.figures["farthest_features"]) == 3
