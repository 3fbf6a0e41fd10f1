"""The components composed on the real driving scenarios, as a user would compose them."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from functools import partial

import pytest
import torch
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
from torchrl.envs import Compose, SerialEnv, TransformedEnv
from torchrl.envs.utils import check_env_specs

from torchrl_csirl.data import load_expert_demonstrations
from torchrl_csirl.modules import make_reward_network
from torchrl_csirl.tasks import SCENARIOS, make_env
from torchrl_csirl.transforms import (
    CombineRewards,
    IntrinsicReward,
    SubgoalMatchingReward,
)
from torchrl_csirl.transforms.subgoal_matching import matching_reward

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _matching_transform(scenario: str, subgoal: int) -> SubgoalMatchingReward:
    spec = SCENARIOS[scenario]
    demos = load_expert_demonstrations(scenario, num_trajectories=1)
    return SubgoalMatchingReward(
        demos.trajectory_observations(0, include_final=True),
        subgoal=subgoal,
        ego_feature_indices=spec.ego_feature_indices,
        position_feature_indices=spec.position_feature_indices,
        scale=spec.matching_scale,
    )


@pytest.mark.parametrize("scenario", ["merge", "roundabout"])
def test_local_reward_in_serial_scenario_env(scenario: str) -> None:
    """r = r_m + r_w lands in ("next", "reward") of a batched real scenario env."""
    torch.manual_seed(0)
    spec = SCENARIOS[scenario]
    matching = _matching_transform(scenario, subgoal=3)
    reward_net = make_reward_network(spec.obs_dim)
    env = TransformedEnv(
        SerialEnv(2, partial(make_env, scenario)),
        Compose(
            matching,
            IntrinsicReward(reward_net),
            CombineRewards(["matching_reward", "intrinsic_reward"]),
        ),
    )
    env.set_seed(0)
    check_env_specs(env)
    rollout = env.rollout(8)
    nxt = rollout["next"]
    torch.testing.assert_close(
        nxt["reward"], nxt["matching_reward"] + nxt["intrinsic_reward"]
    )
    # the matching reward is the published one, recomputed independently
    expected = matching_reward(
        rollout["observation"],
        nxt["observation"],
        matching.expert_observations,
        3,
        ego_feature_indices=spec.ego_feature_indices,
        position_feature_indices=spec.position_feature_indices,
        scale=spec.matching_scale,
    )
    torch.testing.assert_close(nxt["matching_reward"].squeeze(-1), expected)
    assert nxt["matching_reward"].abs().sum() > 0
    env.close()


def test_subgoal_change_visible_on_replayed_transitions() -> None:
    """The same stored transitions get a new matching reward right after set_subgoal."""
    scenario = "roundabout"  # a 2-D potential: heading for another state changes the reward
    matching = _matching_transform(scenario, subgoal=1)
    buffer = TensorDictReplayBuffer(storage=LazyTensorStorage(100), batch_size=10)
    # the expert's own first 10 transitions, replayed in order
    transitions = load_expert_demonstrations(scenario, num_trajectories=1).transitions()[:10]
    buffer.extend(transitions)
    buffer.append_transform(matching)
    first = buffer[:10]["next", "matching_reward"]
    matching.set_subgoal(matching.length - 1)
    second = buffer[:10]["next", "matching_reward"]
    # heading for the next expert state vs. for the last one: different rewards
    assert not torch.allclose(first, second)
    assert (first > 0).all()


def test_demo_runs_end_to_end(tmp_path) -> None:
    """recipes/demo_components.py: parallel workers, buffer transforms, losses, curriculum, eval."""
    out = subprocess.run(
        [sys.executable, os.path.join(ROOT, "recipes", "demo_components.py"),
         "--frames", "200", "--frames-per-batch", "100", "--updates-per-batch", "3"],
        capture_output=True, text=True, timeout=600, cwd=tmp_path,
        env={**os.environ, "RL_WARNINGS": "0"},
    )
    assert out.returncode == 0, out.stderr[-3000:]
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result["updates"] == 6 and result["frames"] == 200
    assert 0.0 <= result["accomplish_rate"] <= 1.0
    assert all(a <= b for a, b in zip(result["subgoals"], result["subgoals"][1:]))


def test_velocity_in_the_matching_search_penalises_forward_driving_on_merge() -> None:
    """Why ``csirl.matching_features=position`` exists (docs/algorithm.md, "matching features").

    Driving straight on at the initial 30 m/s (the empty-road expert accelerates to 40 m/s), the
    nearest expert state found on the whole ego row (velocities included) stays an early one while
    the car moves on, so the target lies *behind* it and moving forward earns a negative matching
    reward. Searching on the position alone, forward progress is always rewarded.
    """
    spec = SCENARIOS["merge"]
    env = make_env("merge", seed=3)
    rollout = env.rollout(40, lambda td: td.set("action", torch.zeros(2)), break_when_any_done=False)
    env.close()
    x, next_x = rollout["observation"][:, 1], rollout["next", "observation"][:, 1]
    assert (next_x > x).all()  # the car moves forward at every step
    curriculum = load_expert_demonstrations("merge", num_trajectories=1).trajectory_observations(0, include_final=True)
    rewards = {}
    for name, search in (("ego", spec.ego_feature_indices), ("position", spec.position_feature_indices)):
        transform = SubgoalMatchingReward(curriculum, subgoal=1, ego_feature_indices=search,
                                          position_feature_indices=spec.position_feature_indices,
                                          scale=spec.matching_scale)
        rewards[name] = transform(rollout.clone())["next", "matching_reward"].flatten()
    assert (rewards["ego"] < 0).sum() >= 10
    assert (rewards["position"] > 0).all()


def _constant_speed_matching_reward(speed: float, search: str, target: str, steps: int = 40) -> float:
    """Mean matching reward per step on merge for an ego driving straight on at ``speed`` [m/s]."""
    spec = SCENARIOS["merge"]
    curriculum = load_expert_demonstrations("merge", num_trajectories=1).trajectory_observations(0, include_final=True)
    obs = curriculum[0].repeat(steps + 1, 1)
    x_range = spec.features_range["x"]
    x = 30.0 + speed * spec.dt * torch.arange(steps + 1, dtype=obs.dtype)
    obs[:, 1] = -1.0 + (x - x_range[0]) * 2.0 / (x_range[1] - x_range[0])
    obs[:, 3] = speed / spec.features_range["vx"][1]
    indices = spec.ego_feature_indices if search == "ego" else spec.position_feature_indices
    r = matching_reward(obs[:-1], obs[1:], curriculum, 1, ego_feature_indices=indices,
                        position_feature_indices=spec.position_feature_indices,
                        scale=spec.matching_scale, target=target)
    return r.mean().item()


def test_matching_reward_per_step_against_speed_on_merge() -> None:
    """What each search / target pair pays for driving at a constant speed (docs/algorithm.md, section 3).

    With the search on the position and the paper's target (the final state past the subgoal) the
    reward is the progress itself (1 per metre on merge); with the published ``next`` target it
    grows much less than the speed; with the search on the whole ego row, following traffic at
    20 m/s is paid negatively, so ending the episode (a crash) is worth more than following.
    """
    progress_per_step = {v: v * SCENARIOS["merge"].dt for v in (20.0, 39.0)}  # 1 reward per metre
    for v, metres in progress_per_step.items():
        assert _constant_speed_matching_reward(v, "position", "final") == pytest.approx(metres, rel=0.02)
    slow, fast = (_constant_speed_matching_reward(v, "position", "next") for v in (20.0, 39.0))
    assert 0 < slow and fast / slow < 0.8 * 39.0 / 20.0
    slow, fast = (_constant_speed_matching_reward(v, "ego", "next") for v in (20.0, 39.0))
    assert slow < 0 < fast
