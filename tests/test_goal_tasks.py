"""Goal-conditioned gymnasium-robotics tasks by id (issue 87): PointMaze found without ``env.module``, its
``Dict`` observation flattened, its waypoint expert, its shipped demonstrations, and CSIRL trained on it."""
from __future__ import annotations

import json
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
import torch
from tensordict import TensorDict
from test_own_task import TINY

from torchrl_csirl.data import load_expert_demonstrations, record_demonstrations
from torchrl_csirl.run.task_schemas import prepare_task
from torchrl_csirl.scripts import csirl_highway
from torchrl_csirl.tasks import TASKS, make_env, make_gymnasium_task
from torchrl_csirl.tasks import registry as task_registry
from torchrl_csirl.tasks.experts import make_expert

UMAZE, MEDIUM = "PointMaze_UMaze-v3", "PointMaze_Medium-v3"
LAYOUT = {"observation": (0, 4), "achieved_goal": (4, 6), "desired_goal": (6, 8)}
CSIRL_TINY = [*(o for o in TINY if not o.startswith(("collector.num_workers", "expert.num_trajectories"))),
              "expert.num_trajectories=5", "csirl.updates_per_round=10", "csirl.num_qvalue_nets=2",
              "replay_buffer.batch_size=32"]


@pytest.fixture(autouse=True, scope="module")
def _unregister_the_mazes():
    """The maze tasks (they have an expert and shipped files) leave the registry after these tests."""
    modules = dict(task_registry._TASK_MODULES)
    yield
    for name in (UMAZE, MEDIUM):
        TASKS.pop(name, None)
        task_registry._FACTORIES.pop(name, None)
    task_registry._TASK_MODULES.clear()
    task_registry._TASK_MODULES.update(modules)


def test_a_gymnasium_robotics_id_is_found_without_env_module():
    """A fresh interpreter: gymnasium_robotics is imported for the id, and recorded for the worker processes."""
    code = ("import sys; from torchrl_csirl.run.task_schemas import prepare_task; from torchrl_csirl.tasks import registry\n"
            "assert 'gymnasium_robotics' not in sys.modules\n"
            f"print(prepare_task(['env.gym_id={UMAZE}'])[-1], list(registry._TASK_MODULES))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip().splitlines()[-1] == f"env.task={UMAZE} ['gymnasium_robotics']"


def test_an_unknown_id_is_one_line():
    with pytest.raises(ValueError, match=r"^env.gym_id=PointMaze_NoSuchMaze-v3: not a registered gymnasium id") as err:
        make_gymnasium_task("PointMaze_NoSuchMaze-v3")
    assert "\n" not in str(err.value)


def test_a_dict_observation_is_flattened_with_matching_on_the_achieved_goal():
    spec = make_gymnasium_task(UMAZE)
    assert dict(spec.observation_layout) == LAYOUT and (spec.obs_dim, spec.action_dim, spec.max_steps) == (8, 2, 300)
    assert spec.position_feature_indices == (4, 5) and spec.matching_features == ("achieved_goal[0]", "achieved_goal[1]")
    assert spec.expert.endswith("point_maze_expert:make_point_maze_expert") and spec.family == "gymnasium"
    assert make_gymnasium_task(UMAZE, features="desired_goal[0],desired_goal[1]").position_feature_indices == (6, 7)
    spec = make_gymnasium_task(UMAZE)  # back to the default
    env = make_env(UMAZE, seed=0)
    rollout = env.rollout(spec.max_steps, make_expert(UMAZE), break_when_any_done=True)
    obs = rollout["observation"]
    assert obs.dtype == torch.float32 and torch.equal(obs[:, 0:2], obs[:, 4:6])  # achieved_goal: the ball's (x, y)
    assert torch.equal(obs[:, 6:8], obs[:1, 6:8].expand(len(obs), 2))  # the goal stays put
    # success from info["success"]; continuing_task=False: reaching the goal ends the episode
    assert rollout["next", "success"][-1] and rollout["next", "terminated"][-1]
    assert not rollout["next", "success"][:-1].any() and rollout.shape[0] < spec.max_steps
    env.close()


@pytest.mark.parametrize("gym_id", [UMAZE, MEDIUM])
def test_the_experts_reach_the_goal(gym_id):
    make_gymnasium_task(gym_id)
    demos = record_demonstrations(gym_id, make_expert(gym_id), episodes=3, seed=5000)
    assert [e["success"] for e in demos.metadata["episodes"]] == [True, True, True]
    # the registry's expert also drives the gymnasium environment itself (reset(env), act(env))
    env, expert = gym.make(gym_id, continuing_task=False), make_expert(gym_id)
    env.reset(seed=5000)
    expert.reset(env)
    for _ in range(env.spec.max_episode_steps):
        _, _, terminated, truncated, info = env.step(expert.act(env))
        if terminated or truncated:
            break
    assert terminated and info["success"]
    env.close()


@pytest.mark.parametrize("gym_id", [UMAZE, MEDIUM])
def test_the_shipped_demonstrations_are_found(gym_id):
    make_gymnasium_task(gym_id)
    demos = load_expert_demonstrations(gym_id, 25)
    assert demos.num_trajectories == 25 and (demos.observation_dim, demos.action_dim) == (8, 2)
    assert all(e["success"] for e in demos.metadata["episodes"])
    assert [e["seed"] for e in demos.metadata["episodes"]][:3] == [0, 1, 2]
    assert np.abs(demos.transitions()["action"].numpy()).max() <= 1.0


def test_csirl_trains_on_point_maze_with_its_shipped_demonstrations(tmp_path):
    summary = csirl_highway.main([f"env.gym_id={UMAZE}", *CSIRL_TINY, "collector.num_workers=1",
                                  f"logger.output_dir={tmp_path}"])
    assert summary["scenario"] == UMAZE and summary["frames"] == 400 and summary["updates"] > 0
    assert summary["accomplish_rate"] == summary["success_rate"]
    with open(f"{summary['run_dir']}/health.json") as f:  # the matching reward follows each episode's goal
        checks = {c["name"]: c for c in json.load(f)["checks"]}
    goals = checks["demonstrations_share_a_goal"]
    assert "demonstration of its goal" in goals["message"]
    # each probe episode's goal against its demonstration's: 5 demonstrations cover few of the U-maze's goals
    assert goals["figures"]["goal_gap_over_path_length"] and goals["ok"] is not None


def test_spawned_collector_workers_find_the_id(tmp_path):
    summary = csirl_highway.main([f"env.gym_id={MEDIUM}", *CSIRL_TINY, "collector.num_workers=2",
                                  f"logger.output_dir={tmp_path}"])
    assert summary["scenario"] == MEDIUM and summary["frames"] == 400


def test_prepare_task_names_the_id_as_the_scenario():
    assert prepare_task([f"env.gym_id={MEDIUM}"]) == [f"env.gym_id={MEDIUM}", f"env.task={MEDIUM}"]
    assert TASKS[MEDIUM].max_steps == 600


def test_sac_from_demonstrations_mixes_the_experts_recorded_reward_into_each_batch():
    """``sac.expert_fraction``: the maze table's "SAC with expert transitions" row, SAC on the sparse reward with a
    quarter of each batch the demonstrations' transitions and their recorded environment reward."""
    from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer

    from torchrl_csirl.methods import baselines as imitation

    args = prepare_task([f"env.gym_id={UMAZE}", "method=sac", "sac.expert_fraction=0.25", "sac.batch_size=64"])
    cfg = imitation.IMITATION_RECIPE.load_config(args)
    spec = TASKS[UMAZE]
    demos = imitation.load_experts(cfg.expert, spec)
    method = imitation.make_sac(cfg, spec, torch.device("cpu"), None)
    online = TensorDictReplayBuffer(storage=LazyTensorStorage(100), batch_size=64)
    env = make_env(UMAZE, seed=0)
    try:
        online.extend(env.rollout(50).exclude("success", ("next", "success")))
    finally:
        env.close()
    expert = demos.as_replay_buffer(batch_size=32)
    batch = method.make_update_step(online, expert).sample(None)
    assert batch.batch_size == (64,)
    expert_part = batch[-16:]  # the expert transitions come last
    recorded = demos.transitions()
    rows = (expert_part["observation"][:, None] == recorded["observation"][None]).all(-1).float().argmax(1)
    assert (recorded["observation"][rows] == expert_part["observation"]).all()
    assert (recorded["next", "reward"][rows] == expert_part["next", "reward"]).all()  # the recorded reward
    assert recorded["next", "reward"].sum() > 0  # the demonstrations reach the goal: a reward of 1 there
    without = demos.transitions().exclude(("next", "reward"))
    bare = TensorDictReplayBuffer(storage=LazyTensorStorage(len(without)), batch_size=32)
    bare.extend(without)
    with pytest.raises(imitation.ConfigError, match=r"sac.expert_fraction=0.25: the demonstrations of .* hold no reward"):
        method.make_update_step(online, bare)


def test_the_matching_reward_follows_the_demonstration_of_each_episodes_goal():
    """PointMaze's matching reward (``csirl.goal_conditioned`` null: on, the observation has a desired_goal): each
    transition is rewarded as the plain matching reward on the demonstration of its goal would, toward the
    curriculum's subgoal as the same share of that demonstration; ``false`` gives the first demonstration's."""
    from torchrl_csirl.methods import csirl
    from torchrl_csirl.transforms import GoalConditionedMatchingReward, SubgoalMatchingReward, subgoal_on_demonstration

    args = prepare_task([f"env.gym_id={UMAZE}"])
    cfg = csirl.CSIRL_RECIPE.load_config(args)
    spec = TASKS[UMAZE]
    demos = csirl.load_experts(cfg.expert, spec)
    first = demos.trajectory_observations(0, include_final=True)
    matching = csirl.make_matching(cfg, spec, first, 10, demos)
    assert isinstance(matching, GoalConditionedMatchingReward) and matching.num_demonstrations == 25
    for k in (0, 3, 7):
        episode = demos.trajectory(k)
        assert (matching.demonstration_of(episode["observation"]) == k).all()
        alone = SubgoalMatchingReward(demos.trajectory_observations(k, include_final=True),
                                      subgoal=subgoal_on_demonstration(10, first.shape[0], matching.lengths[k]),
                                      ego_feature_indices=spec.position_feature_indices,
                                      position_feature_indices=spec.position_feature_indices,
                                      scale=spec.matching_scale, target=cfg.csirl.matching_target)
        assert torch.equal(matching(episode.clone())["next", "matching_reward"],
                           alone(episode.clone())["next", "matching_reward"])
    off = csirl.CSIRL_RECIPE.load_config([*args, "csirl.goal_conditioned=false"])
    assert type(csirl.make_matching(off, spec, first, 10, demos)) is SubgoalMatchingReward
    with pytest.raises(csirl.ConfigError, match="csirl.goal_conditioned=true: merge's observation has no desired_goal"):
        csirl.goal_features(csirl.CSIRL_RECIPE.load_config(["csirl.goal_conditioned=true"]).csirl, TASKS["merge"])


def test_goal_conditioned_matching_reduces_to_the_plain_one_with_one_demonstration_and_checks_its_input():
    from torchrl_csirl.transforms import GoalConditionedMatchingReward, SubgoalMatchingReward

    torch.manual_seed(0)
    path = torch.randn(12, 4, dtype=torch.float64)
    batch = TensorDict({"observation": torch.randn(64, 4, dtype=torch.float64),
                        "next": {"observation": torch.randn(64, 4, dtype=torch.float64)}}, [64])
    for target in ("next", "final", "path"):
        kwargs = dict(subgoal=5, ego_feature_indices=[0, 1], position_feature_indices=[0, 1], scale=3.0, target=target)
        one = GoalConditionedMatchingReward([path], goal_feature_indices=[2, 3], **kwargs)
        assert torch.equal(one(batch.clone())["next", "matching_reward"],
                           SubgoalMatchingReward(path, **kwargs)(batch.clone())["next", "matching_reward"])
    # two demonstrations of different lengths and goals: each transition gets its own demonstration's plain reward,
    # on every target rule and with a failure flag (the potential of its own demonstration's start)
    other = torch.randn(7, 4, dtype=torch.float64)
    path[:, 2:], other[:, 2:] = 1.0, -1.0
    mixed = batch.clone()
    mixed["observation"][:, 2:] = mixed["next", "observation"][:, 2:] = torch.where(
        torch.arange(64)[:, None] % 2 == 0, 1.0, -1.0).double()
    mixed["next", "crashed"] = torch.arange(64)[:, None] % 3 == 0
    for target in ("next", "final", "path"):
        kwargs = dict(ego_feature_indices=[0, 1], position_feature_indices=[0, 1], scale=3.0, target=target,
                      failure_keys=("crashed",))
        both = GoalConditionedMatchingReward([path, other], goal_feature_indices=[2, 3], subgoal=6, **kwargs)
        reward = both(mixed.clone())["next", "matching_reward"]
        for rows, demo, subgoal in ((slice(0, None, 2), path, 6), (slice(1, None, 2), other, 3)):  # 6 of 11 -> 3 of 6
            alone = SubgoalMatchingReward(demo, subgoal=subgoal, **kwargs)(mixed[rows].clone())["next", "matching_reward"]
            torch.testing.assert_close(reward[rows], alone, rtol=1e-6, atol=1e-6)
    with pytest.raises(ValueError, match=r"demonstrations \[1\]: each must have shape \[L, 4\]"):
        GoalConditionedMatchingReward([path, torch.zeros(3, 5)], goal_feature_indices=[2])
    with pytest.raises(ValueError, match="goal_feature_indices .* out of range"):
        GoalConditionedMatchingReward([path], goal_feature_indices=[9])


def test_the_actor_warm_start_clones_the_demonstrations_into_the_learners_actor(capsys):
    """``csirl.actor_pretrain_updates``: behavioural cloning of the actor before training (the AntMaze study's one
    change); the SAC loss acts with the same parameters, and the default does nothing."""
    from torchrl.envs.utils import ExplorationType, set_exploration_type

    from torchrl_csirl.methods import csirl

    args = prepare_task([f"env.gym_id={UMAZE}", "csirl.num_qvalue_nets=2"])
    spec = TASKS[UMAZE]
    for updates in (0, 300):
        cfg = csirl.CSIRL_RECIPE.load_config([*args, f"csirl.actor_pretrain_updates={updates}", "optim.lr=0.001"])
        demos = csirl.load_experts(cfg.expert, spec)
        torch.manual_seed(0)
        modules = csirl.make_loss_modules(cfg, spec, torch.device("cpu"), demos)
        before = [p.detach().clone() for p in modules.actor.parameters()]
        csirl.warm_start_actor(cfg, modules, demos.as_replay_buffer(batch_size=32))
        batch = demos.transitions()
        with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
            error = (modules.actor(batch.select("observation").clone())["action"] - batch["action"]).pow(2).mean()
        moved = any(not torch.equal(a, b.detach()) for a, b in zip(before, modules.actor.parameters()))
        if updates == 0:
            assert not moved and "warm-started" not in capsys.readouterr().err
            untrained = error
        else:
            assert moved and error < 0.5 * untrained
            assert "actor warm-started: 300 behavioural-cloning updates" in capsys.readouterr().err
            sac_params = set(map(id, modules.sac.actor_network_params.values(True, True)))
            assert all(id(p) in sac_params for p in modules.actor.parameters())


def test_the_one_goal_mazes_of_the_example_keep_their_goal_and_start_and_their_expert_reaches_it(monkeypatch):
    """``examples/fixed_goal_mazes.py``, the U-maze study's one change: the goal and the start cell fixed."""
    import os

    monkeypatch.syspath_prepend(os.path.join(os.path.dirname(os.path.dirname(__file__)), "examples"))
    import fixed_goal_mazes

    for gym_id in fixed_goal_mazes.FIXED_GOAL_IDS:
        make_gymnasium_task(gym_id)
        demos = record_demonstrations(gym_id, make_expert(gym_id), episodes=2, seed=7000)
        assert [e["success"] for e in demos.metadata["episodes"]] == [True, True]
        goals = demos.transitions()["observation"][:, 6:8]
        starts = torch.stack([demos.trajectory(k)["observation"][0, :2] for k in range(2)])
        assert (goals - goals[0]).abs().max() <= 0.5 and (starts[0] - starts[1]).abs().max() <= 0.5  # +-0.25 noise
        TASKS.pop(gym_id)
        task_registry._FACTORIES.pop(gym_id, None)
