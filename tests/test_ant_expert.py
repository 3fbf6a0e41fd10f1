"""The AntMaze expert's pieces: the ant-goal training task, the waypoint controller, its recipe."""
from __future__ import annotations

import json
import math
import os

import numpy as np
import pytest
import torch
from torchrl.envs.utils import check_env_specs

from torchrl_csirl.modules import make_actor, save_policy
from torchrl_csirl.scripts import generate_experts, train_ant_expert
from torchrl_csirl.tasks import make_env, make_gym_env, resolve_scenario
from torchrl_csirl.tasks.driving.expert import make_expert, rollout_expert
from torchrl_csirl.tasks.robotics import (
    ANTMAZE_UMAZE_MAP,
    WaypointAntExpert,
    maze_cell_route,
    next_waypoint,
    pursuit_waypoint,
)
from torchrl_csirl.tasks.robotics.ant_goal import (
    ARRIVAL_BONUS,
    CHAIN_HOPS,
    GOAL_VECTOR_CLIP,
    ant_goal_observation,
    free_cells,
    heading_of,
    is_flipped,
)


def _yaw_quaternion(yaw: float) -> np.ndarray:
    return np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])


def test_ant_goal_env_specs_and_hops():
    spec = resolve_scenario("ant-goal")
    assert (spec.obs_dim, spec.action_dim, spec.max_steps) == (29, 8, 300)
    check_env_specs(make_env("ant-goal", seed=0))
    env = make_gym_env("ant-goal")
    cells = set(free_cells())
    for seed in range(20):
        obs, info = env.reset(seed=seed)
        start = tuple(int(v) for v in env._inner.maze.cell_xy_to_rowcol(env.position()))
        goal = tuple(int(v) for v in env._inner.maze.cell_xy_to_rowcol(env.goal))
        assert start in cells and goal in cells
        assert len(maze_cell_route(ANTMAZE_UMAZE_MAP, start, goal)) <= 3  # the goal's cell is the start's or next to it
        assert info["distance_to_finish"] > 0.9 and not info["success"] and info["hops"] == 0
        # the goal vector is the goal seen from the torso, clipped
        assert np.linalg.norm(obs[27:]) == pytest.approx(min(info["distance_to_finish"], GOAL_VECTOR_CLIP), rel=1e-5)
    # seeded: the same episode twice
    a, _ = env.reset(seed=7)
    b, _ = env.reset(seed=7)
    np.testing.assert_array_equal(a, b)
    env.close()


def test_ant_goal_observation_is_in_the_heading_frame():
    ant = np.zeros(27)
    ant[1:5] = _yaw_quaternion(math.pi / 2)  # facing +y
    assert heading_of(ant[1:5]) == pytest.approx(math.pi / 2)
    local = ant_goal_observation(ant, np.array([0.0, 0.0]), np.array([0.0, 3.0]))[27:]
    np.testing.assert_allclose(local, [3.0, 0.0], atol=1e-12)  # straight ahead
    local = ant_goal_observation(ant, np.array([0.0, 0.0]), np.array([-30.0, 0.0]))[27:]
    np.testing.assert_allclose(local, [0.0, GOAL_VECTOR_CLIP], atol=1e-12)  # to its left, clipped
    with pytest.raises(ValueError, match="27 values"):
        ant_goal_observation(np.zeros(29), np.zeros(2), np.zeros(2))
    assert not is_flipped(_yaw_quaternion(2.0)) and is_flipped(np.array([0.0, 1.0, 0.0, 0.0]))


def _goal_just_ahead(env) -> None:
    """Put the current goal right next to the ant: the next step arrives."""
    env._set_goal(env.position() + np.array([0.1, 0.0]))


def test_ant_goal_chains_its_hops_and_pays_each_arrival():
    env = make_gym_env("ant-goal")
    _, info = env.reset(seed=3)
    assert info["progress"] == 0.0
    for hop in range(1, CHAIN_HOPS + 1):
        old_goal = env.goal.copy()
        _goal_just_ahead(env)
        obs, reward, terminated, truncated, info = env.step(np.zeros(8))
        assert reward > ARRIVAL_BONUS - 5 and info["hops"] == hop and not truncated
        if hop < CHAIN_HOPS:  # the next goal, 0.9 m or more away, a cell's hop from the ant, in the observation
            assert not terminated and not info["success"] and info["distance_to_finish"] > 0.9
            assert not np.allclose(env.goal, old_goal)
            assert info["progress"] == pytest.approx(hop / CHAIN_HOPS)
            route = maze_cell_route(ANTMAZE_UMAZE_MAP, *(tuple(int(v) for v in env.maze.cell_xy_to_rowcol(p))
                                                         for p in (env.position(), env.goal)))
            assert len(route) <= 2
            assert np.linalg.norm(obs[27:]) == pytest.approx(min(info["distance_to_finish"], GOAL_VECTOR_CLIP), rel=1e-5)
    assert terminated and info["success"] and info["progress"] == 1.0
    # a flipped ant ends its episode
    env.reset(seed=4)
    ant = env._inner.ant_env
    qpos, qvel = ant.data.qpos.copy(), ant.data.qvel.copy()
    qpos[3:7] = (0.0, 1.0, 0.0, 0.0)
    ant.set_state(qpos, qvel)
    _, _, terminated, _, info = env.step(np.zeros(8))
    assert terminated and not info["success"]
    env.close()


def test_waypoints_follow_the_maze_route():
    env = make_gym_env("antmaze-umaze")
    env.reset(seed=0)
    maze, goal = env.maze, env.goal
    centre = lambda cell: maze.cell_rowcol_to_xy(np.array(cell))  # noqa: E731
    # along the U: the centre of the next cell, then the goal itself from the cell before it
    np.testing.assert_allclose(next_waypoint(centre((1, 1)), goal, maze), centre((1, 2)))
    np.testing.assert_allclose(next_waypoint(centre((1, 3)), goal, maze), centre((2, 3)))
    np.testing.assert_allclose(next_waypoint(centre((3, 3)), goal, maze), centre((3, 2)))
    np.testing.assert_allclose(next_waypoint(centre((3, 2)), goal, maze), goal)
    np.testing.assert_allclose(next_waypoint(goal + 0.3, goal, maze), goal)
    env.close()


def test_pursuit_waypoint_turns_corners_on_the_centre_line():
    env = make_gym_env("antmaze-umaze")
    env.reset(seed=0)
    maze, goal = env.maze, env.goal
    centre = lambda cell: maze.cell_rowcol_to_xy(np.array(cell))  # noqa: E731
    # 3 m on along the route from a cell centre: straight on, or round the corner on the centre line
    np.testing.assert_allclose(pursuit_waypoint(centre((1, 1)), goal, maze), centre((1, 1)) + [3.0, 0.0])
    np.testing.assert_allclose(pursuit_waypoint(centre((1, 2)) + [1.5, 0.0], goal, maze, 3.5),
                               centre((1, 3)) + [0.0, -1.0])
    # an ant off the centre line is projected onto it; a route shorter than the look-ahead ends at the goal
    np.testing.assert_allclose(pursuit_waypoint(centre((1, 2)) + [0.0, 1.5], goal, maze, 1.0), centre((1, 2)) + [1.0, 0.0])
    np.testing.assert_allclose(pursuit_waypoint(centre((3, 2)), goal, maze, 10.0), goal)
    # every waypoint along the U lies in a free cell, never beyond a wall's corner
    for x in np.linspace(-5.5, 5.5, 23):
        for y in np.linspace(-5.5, 5.5, 23):
            row, col = (int(v) for v in maze.cell_xy_to_rowcol(np.array([x, y])))
            if ANTMAZE_UMAZE_MAP[row][col] == 1:
                continue
            row, col = (int(v) for v in maze.cell_xy_to_rowcol(pursuit_waypoint(np.array([x, y]), goal, maze)))
            assert ANTMAZE_UMAZE_MAP[row][col] != 1, (x, y)
    with pytest.raises(ValueError, match="lookahead"):
        pursuit_waypoint(centre((1, 1)), goal, maze, 0.0)
    with pytest.raises(ValueError, match="action_gain"):
        WaypointAntExpert(action_gain=1.5)
    with pytest.raises(ValueError, match="lookahead"):
        WaypointAntExpert(lookahead=-1.0)
    env.close()


def test_waypoint_expert_checks_its_policy(tmp_path):
    assert isinstance(make_expert("antmaze-umaze"), WaypointAntExpert)  # the shipped ant
    with pytest.raises(ValueError, match="takes only policy="):
        make_expert("antmaze-umaze", horizon=3)
    first = make_expert("antmaze-umaze", lookahead=None, action_gain=1.0)  # the controller before 2026-11-26
    assert first.lookahead is None and first.action_gain == 1.0
    with pytest.raises(FileNotFoundError):
        make_expert("antmaze-umaze", policy=str(tmp_path / "none.pt"))
    path = tmp_path / "wrong.pt"
    save_policy(make_actor(39, 30), path, obs_dim=39, action_dim=30, scenario="relocate")
    with pytest.raises(ValueError, match="29 inputs and 8 actions, got 39 and 30"):
        WaypointAntExpert(str(path))
    ok = tmp_path / "ant.pt"
    torch.manual_seed(0)
    save_policy(make_actor(29, 8), ok, obs_dim=29, action_dim=8, scenario="ant-goal")
    expert = make_expert("antmaze-umaze", policy=str(ok))
    env = make_gym_env("antmaze-umaze")
    env.reset(seed=0)
    action = expert.act(env)
    assert action.shape == (8,) and np.all(np.abs(action) <= 1.0)
    env.close()
    with pytest.raises(SystemExit):
        generate_experts.main(["--scenario", "relocate", "--ant-policy", str(ok), "--episodes", "1"])


def test_shipped_ant_expert_reaches_the_goal():
    """The shipped goal-reaching ant, driven by waypoints, solves AntMaze on seeds it never saw
    (docs/experts.md, "AntMaze expert", gives its rate over 100-episode ranges)."""
    env = make_gym_env("antmaze-umaze")
    expert = make_expert("antmaze-umaze")
    episodes = [rollout_expert(env, seed=seed, expert=expert, scenario="antmaze-umaze") for seed in range(20000, 20005)]
    env.close()
    reached = [e for e in episodes if e["success"]]
    assert len(reached) >= 4, [e["length"] for e in episodes]
    assert all(e["length"] < resolve_scenario("antmaze-umaze").max_steps for e in reached)  # it ends at the goal


def test_shipped_antmaze_dataset_is_reproduced(tmp_path):
    from torchrl_csirl.data import load_expert_demonstrations

    demos = load_expert_demonstrations("antmaze-umaze", 25)
    assert demos.num_trajectories == 25 and demos.observation_dim == 29 and demos.action_dim == 8
    assert demos.metadata["generator"].endswith("WaypointAntExpert")
    assert demos.metadata["expert_settings"] == {"lookahead": 3.0, "action_gain": 0.6}
    assert all(e["success"] for e in demos.metadata["episodes"])
    # the first trajectory again, with the command that wrote the file (from its seed: failed seeds were skipped)
    seed = demos.metadata["episodes"][0]["seed"]
    result = generate_experts.main(["--scenario", "antmaze-umaze", "--episodes", "1", "--seed", str(seed),
                                    "--out", str(tmp_path / "one.npz")])
    assert result["success_rate"] == 1.0
    again = type(demos).load(tmp_path / "one.npz")
    # Bit for bit only on the CPU that wrote the file: the ant policy's float rounding depends on the
    # CPU's kernels (its first action differs by ~6e-8 on another machine) and the contact dynamics
    # amplify that within a few dozen steps. The first steps agree closely; the episode still succeeds.
    first = 10
    for key in ("observation", "action", ("next", "observation")):
        torch.testing.assert_close(again.trajectory(0)[key][:first], demos.trajectory(0)[key][:first],
                                   rtol=0, atol=1e-4)


def test_train_ant_expert_end_to_end(tmp_path):
    summary = train_ant_expert.main([
        "collector.total_frames=800", "collector.frames_per_batch=400", "collector.num_workers=1",
        "collector.init_random_frames=200", "collector.main_threads=1", "replay_buffer.warmup_frames=200",
        "sac.batch_size=32", "updates_per_round=100", "eval.episodes=1", "eval.final_episodes=1",
        "eval.video=false", "expert_eval.episodes=1", "device=cpu", "logger.backend=none", "logger.progress_bar=false",
        f"logger.output_dir={tmp_path}", "logger.exp_name=ant",
    ])
    assert summary["scenario"] == "ant-goal" and summary["frames"] == 800 and summary["updates"] == 400
    assert 0.0 <= summary["hop_success_rate"] <= 1.0 and 0.0 <= summary["antmaze_success_rate"] <= 1.0
    run_dir = summary["run_dir"]
    for name in ("config.yaml", "metrics.jsonl", "policy.pt", "summary.json", "learning_curve.png"):
        assert os.path.exists(os.path.join(run_dir, name)), name
    with open(os.path.join(run_dir, "summary.json")) as f:
        assert json.load(f)["antmaze_episodes"] == 1
    # the trained policy drives the AntMaze expert (and its datasets) straight from the run directory
    result = generate_experts.main(["--scenario", "antmaze-umaze", "--ant-policy", run_dir, "--episodes", "1",
                                    "--seed", "10000", "--out", str(tmp_path / "ant.npz")])
    assert result["episodes"] == 1 and os.path.exists(result["out"])
