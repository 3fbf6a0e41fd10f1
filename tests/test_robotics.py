"""The robotics tasks (AntMaze U-maze, Adroit Relocate): envs, specs, the DAPG expert, Minari interop."""
from __future__ import annotations

import os

import numpy as np
import pytest
import torch
from torchrl.envs.utils import check_env_specs

from torchrl_csirl.tasks import TASKS, TaskSpec, make_env, make_gym_env, resolve_scenario
from torchrl_csirl.tasks.metrics import (
    accomplish_rate_from_rollout,
    success_from_rollout,
)
from torchrl_csirl.tasks.robotics import (
    ROBOTICS_TASKS,
    maze_cell_route,
    route_remaining_length,
)
from torchrl_csirl.tasks.robotics.tasks import AntMazeUMazeEnv, Route

ROBOTICS = ("antmaze-umaze", "relocate")


@pytest.mark.parametrize("name", ROBOTICS)
def test_env_specs_and_layout(name):
    spec = resolve_scenario(name)
    assert isinstance(spec, TaskSpec) and spec.family == "robotics" and TASKS[name] is spec
    env = make_env(name, seed=0)
    check_env_specs(env)
    assert env.observation_spec["observation"].shape == (spec.obs_dim,)
    assert env.full_action_spec["action"].shape == (spec.action_dim,)
    # the layout covers the observation exactly, in order
    stops = [stop for _, stop in spec.observation_layout.values()]
    starts = [start for start, _ in spec.observation_layout.values()]
    assert starts[0] == 0 and stops[-1] == spec.obs_dim and starts[1:] == stops[:-1]


def test_spec_dimensions_and_matching_features():
    ant, relocate = ROBOTICS_TASKS["antmaze-umaze"], ROBOTICS_TASKS["relocate"]
    assert (ant.obs_dim, ant.action_dim, ant.max_steps) == (29, 8, 700)
    assert (relocate.obs_dim, relocate.action_dim, relocate.max_steps) == (39, 30, 200)
    assert ant.matching_features == ("x", "y")
    assert relocate.matching_features == tuple(
        f"{part}[{k}]" for part in ("palm_to_object", "object_to_target") for k in range(3)
    )
    # the driving scenarios are TaskSpecs too
    assert resolve_scenario("merge").matching_features == ("x",)
    with pytest.raises(ValueError, match="unknown environment options"):
        make_gym_env("relocate", lanes_count=3)


def test_antmaze_state_is_observation_plus_position():
    env = make_gym_env("antmaze-umaze")
    obs, info = env.reset(seed=3)
    np.testing.assert_allclose(obs[27:], env.position(), atol=1e-6)
    assert np.linalg.norm(obs[27:] - np.array([-4.0, 4.0])) <= 0.15  # D4RL's start cell, small noise
    assert np.linalg.norm(env.goal - np.array(ROBOTICS_TASKS["antmaze-umaze"].finish_position)) <= 0.15
    assert info["progress"] == 0.0 and not info["success"]
    assert info["distance_to_finish"] == pytest.approx(24.0, abs=0.5)  # along the U, not 8 m across


def test_maze_route_and_remaining_length():
    route = maze_cell_route([[1, 1, 1], [1, 0, 1], [1, 0, 1], [1, 1, 1]], (1, 1), (2, 1))
    assert route == [(1, 1), (2, 1)]
    with pytest.raises(ValueError, match="No route"):
        maze_cell_route([[0, 1, 0]], (0, 0), (0, 2))
    line = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, -4.0]])
    assert route_remaining_length(line, np.array([4.0, -4.0])) == 0.0
    assert route_remaining_length(line, np.array([0.0, 0.0])) == 8.0


def test_antmaze_leaves_no_model_file_in_the_temp_folder():
    env = AntMazeUMazeEnv()
    path = env._inner.tmp_xml_file_path
    assert path.endswith(".xml") and not os.path.exists(path)  # gymnasium-robotics leaves it otherwise
    env.reset(seed=0)
    env.step(env.action_space.sample())
    env.close()


def test_route_point_ahead_walks_round_corners_and_stops_at_the_end():
    route = Route([(0.0, 0.0), (4.0, 0.0), (4.0, -4.0), (4.0, -4.0)])  # a zero-length last segment
    assert route.point_ahead(1.0, 0.7, 0.0) == (1.0, 0.0)  # the projection itself
    assert route.point_ahead(1.0, 0.7, 2.0) == (3.0, 0.0)
    assert route.point_ahead(3.0, 0.5, 2.0) == (4.0, -1.0)  # round the corner
    assert route.point_ahead(-2.0, 1.0, 4.0) == (4.0, 0.0)  # before the start: from the first point
    assert route.point_ahead(4.0, -3.0, 5.0) == (4.0, -4.0)  # beyond the end: the last point
    with pytest.raises(ValueError, match="distance must be >= 0"):
        route.point_ahead(1.0, 0.0, -1.0)
    assert route.remaining(float("nan"), 0.0) == float("inf")  # not "at the goal"
    for x, y in ((0.5, 0.3), (3.9, -0.2), (4.2, -3.5)):  # consistent with remaining()
        ahead = route.point_ahead(x, y, 1.5)
        assert route.remaining(*ahead) == pytest.approx(max(route.remaining(x, y) - route._project(x, y)[2] - 1.5, 0.0))


@pytest.mark.parametrize("name", ROBOTICS)
def test_seeded_determinism(name):
    def roll(seed):
        env = make_env(name, seed=seed)
        torch.manual_seed(0)
        return env.rollout(30, break_when_any_done=False)

    a, b, c = roll(5), roll(5), roll(6)
    for key in ("observation", ("next", "observation"), ("next", "reward"), ("next", "distance_to_finish")):
        torch.testing.assert_close(a[key], b[key], rtol=0, atol=0)
    assert not torch.equal(a["observation"][0], c["observation"][0])


@pytest.mark.parametrize("name", ROBOTICS)
def test_progress_and_success_hooks(name):
    env = make_env(name, seed=0)
    td = env.rollout(20, break_when_any_done=False)
    progress = td["next", "progress"]
    assert ((progress >= 0) & (progress <= 1)).all()
    assert 0.0 <= float(accomplish_rate_from_rollout(td)) <= 1.0
    assert not bool(success_from_rollout(td))  # random actions do not solve either task in 20 steps
    assert not td["next", "crashed"].any() and not td["next", "offroad"].any()


def test_antmaze_reports_a_flipped_ant_as_crashed_without_ending_the_episode():
    env = AntMazeUMazeEnv()
    env.reset(seed=0)
    ant = env._inner.ant_env
    qpos, qvel = ant.data.qpos.copy(), ant.data.qvel.copy()
    qpos[2], qpos[3:7] = 1.0, (0.0, 1.0, 0.0, 0.0)  # on its back, dropped from 1 m
    ant.set_state(qpos, qvel)
    flags = [env.step(np.zeros(8, dtype=np.float32)) for _ in range(20)]
    assert all(info["crashed"] for *_, info in flags)
    assert not any(terminated or truncated for _, _, terminated, truncated, _ in flags)
    env.close()


def test_headless_rendering():
    env = make_gym_env("relocate", render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    env.close()
    assert frame.ndim == 3 and frame.shape[-1] == 3 and frame.std() > 0


# ---------------------------------------------------------------------------------------------- DAPG expert
def test_dapg_expert_solves_relocate_in_torchrl_rollouts():
    from torchrl_csirl.tasks.robotics.expert import DAPGRelocatePolicy

    policy = DAPGRelocatePolicy().as_tensordict_module()
    for seed in (10000, 10001):
        env = make_env("relocate", seed=seed)
        with torch.no_grad():
            td = env.rollout(200, policy)
        assert td.shape[-1] == 200 and bool(td["next", "truncated"][-1])
        assert bool(success_from_rollout(td))
        assert int(td["next", "success"].sum()) > 25  # D4RL's criterion: at the target > 25 steps
        assert float(td["next", "reward"].sum()) > 1000.0


def test_dapg_weights_checked(tmp_path):
    from torchrl_csirl.tasks.robotics.expert import DAPG_POLICY_PATH, DAPGRelocatePolicy

    arrays = dict(np.load(DAPG_POLICY_PATH))
    arrays["w0"] = arrays["w0"][:, :20]
    np.savez(tmp_path / "bad.npz", **arrays)
    with pytest.raises(ValueError, match="'w0' of shape"):
        DAPGRelocatePolicy(tmp_path / "bad.npz")


def test_shipped_relocate_dataset_is_reproduced(tmp_path):
    from torchrl_csirl.data import load_expert_demonstrations
    from torchrl_csirl.scripts.generate_experts import main

    demos = load_expert_demonstrations("relocate", 25)
    assert demos.num_trajectories == 25 and demos.observation_dim == 39 and demos.action_dim == 30
    assert demos.lengths.tolist() == [200] * 25
    assert demos.transitions()["observation"].dtype == torch.float32
    assert demos.metadata["generator"].endswith("DAPGRelocateExpert")
    assert all(e["success"] for e in demos.metadata["episodes"])
    # the first trajectory again, with the command that wrote the file (seed 0)
    result = main(["--scenario", "relocate", "--episodes", "1", "--seed", "0", "--out", str(tmp_path / "one.npz")])
    assert result["success_rate"] == 1.0
    again = type(demos).load(tmp_path / "one.npz")
    for key in ("observation", "action", ("next", "observation"), ("next", "reward")):
        torch.testing.assert_close(again.trajectory(0)[key], demos.trajectory(0)[key], rtol=0, atol=0)


# ---------------------------------------------------------------------------------------------- Minari interop
def _ant_like_minari_dataset(root, dataset_id, episodes=2, steps=5):
    """A goal-conditioned Minari dataset shaped like D4RL's successors' AntMaze (dict observations)."""
    import gymnasium as gym
    import minari
    from minari.data_collector import EpisodeBuffer

    from torchrl_csirl.data.minari import _minari_root

    rng = np.random.default_rng(0)
    box = lambda n: gym.spaces.Box(-np.inf, np.inf, (n,), np.float64)  # noqa: E731
    space = gym.spaces.Dict({"observation": box(27), "achieved_goal": box(2), "desired_goal": box(2)})
    buffers = [
        EpisodeBuffer(
            id=i,
            observations={k: rng.normal(size=(steps + 1, s.shape[0])) for k, s in space.spaces.items()},
            actions=rng.uniform(-1, 1, (steps, 8)).astype(np.float32),
            rewards=np.zeros(steps),
            terminations=np.zeros(steps, bool),
            truncations=np.arange(steps) == steps - 1,
            infos={},
        )
        for i in range(episodes)
    ]
    with _minari_root(root):
        minari.create_dataset_from_buffers(
            dataset_id, buffers, observation_space=space,
            action_space=gym.spaces.Box(-1, 1, (8,), np.float32), data_format="hdf5",
        )
    return buffers


def test_minari_round_trip_and_torchrl_replay(tmp_path):
    from torchrl_csirl.data import load_expert_demonstrations
    from torchrl_csirl.data.minari import (
        load_minari_dataset,
        minari_experience_replay,
        save_minari_dataset,
    )

    demos = load_expert_demonstrations("relocate", 25).subset(2)
    save_minari_dataset(demos, "csirl/relocate/expert-v0", root=tmp_path, task="relocate")
    back = load_minari_dataset("csirl/relocate/expert-v0", root=tmp_path, task="relocate")
    assert back == demos and back.metadata["generator"].endswith("DAPGRelocateExpert")
    with pytest.raises(ValueError, match="already exists"):
        save_minari_dataset(demos, "csirl/relocate/expert-v0", root=tmp_path)
    one = demos.subset(1)
    save_minari_dataset(one, "csirl/relocate/expert-v0", root=tmp_path, overwrite=True)
    assert load_minari_dataset("csirl/relocate/expert-v0", root=tmp_path).num_trajectories == 1
    with pytest.raises(ValueError, match="needs at least 2"):  # TorchRL 0.14.1 cannot read one episode
        minari_experience_replay("csirl/relocate/expert-v0", 4, root=tmp_path, torchrl_root=tmp_path / "torchrl")
    save_minari_dataset(demos, "csirl/relocate/expert-v0", root=tmp_path, overwrite=True)

    buffer = minari_experience_replay(
        "csirl/relocate/expert-v0", 16, root=tmp_path, torchrl_root=tmp_path / "torchrl", task="relocate"
    )
    data = buffer[:]
    flat = demos.transitions()
    assert len(buffer) == len(flat) == 400
    for key in ("observation", "action", ("next", "observation"), ("next", "reward"), ("next", "truncated")):
        torch.testing.assert_close(data[key], flat[key], rtol=0, atol=0, check_dtype=False)
    assert buffer.sample()["observation"].shape == (16, 39)


def test_minari_dict_observations_and_dimension_mismatch(tmp_path):
    from torchrl_csirl.data import load_expert_demonstrations
    from torchrl_csirl.data.minari import (
        load_minari_dataset,
        minari_experience_replay,
        save_minari_dataset,
    )

    buffers = _ant_like_minari_dataset(tmp_path, "d4rl-like/antmaze/umaze-v0")
    demos = load_minari_dataset("d4rl-like/antmaze/umaze-v0", root=tmp_path, task="antmaze-umaze")
    assert demos.observation_dim == 29 and demos.num_trajectories == 2  # observation + achieved_goal
    expected = np.concatenate([buffers[1].observations["observation"], buffers[1].observations["achieved_goal"]], 1)
    np.testing.assert_allclose(demos.trajectory(1)["observation"].numpy(), expected[:-1], rtol=1e-6)
    assert demos.metadata == {"source": "minari", "dataset_id": "d4rl-like/antmaze/umaze-v0"}
    buffer = minari_experience_replay(
        "d4rl-like/antmaze/umaze-v0", 4, root=tmp_path, torchrl_root=tmp_path / "torchrl", task="antmaze-umaze"
    )
    data = buffer[:]
    np.testing.assert_allclose(data["next", "observation", "achieved_goal"][5:].numpy(), expected[1:, 27:], rtol=1e-6)
    np.testing.assert_allclose(data["action"][5:].numpy(), buffers[1].actions)

    message = "observations of size 29 and actions of size 8, but task 'relocate' has 39 and 30"
    with pytest.raises(ValueError, match=message):
        load_minari_dataset("d4rl-like/antmaze/umaze-v0", root=tmp_path, task="relocate")
    with pytest.raises(ValueError, match="size 39 and actions of size 30, but task 'merge' has 25 and 2"):
        save_minari_dataset(load_expert_demonstrations("relocate", 1), "x/y-v0", root=tmp_path, task="merge")
    save_minari_dataset(load_expert_demonstrations("merge", 5), "csirl/merge/expert-v0", root=tmp_path)
    with pytest.raises(ValueError, match="size 25 and actions of size 2, but task 'antmaze-umaze' has 29 and 8"):
        minari_experience_replay(
            "csirl/merge/expert-v0", 4, root=tmp_path, torchrl_root=tmp_path / "torchrl", task="antmaze-umaze"
        )


def test_torchrl_minari_replay_drops_contents_pinned(tmp_path, monkeypatch):
    """TorchRL 0.14.1's MinariExperienceReplay keeps a contentless memmap copy (all zeros).

    ``minari_experience_replay`` writes the transitions back; when this test fails after a
    TorchRL upgrade, the bug is fixed and ``_restore_minari_contents`` can go.
    """
    from torchrl.data.datasets.minari_data import MinariExperienceReplay

    from torchrl_csirl.data import load_expert_demonstrations
    from torchrl_csirl.data.minari import save_minari_dataset

    save_minari_dataset(load_expert_demonstrations("merge", 5), "csirl/merge/expert-v0", root=tmp_path)
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path))
    raw = MinariExperienceReplay("csirl/merge/expert-v0", 4, root=str(tmp_path / "raw"), load_from_local_minari=True)
    assert len(raw) > 0 and not raw[:]["action"].any() and not raw[:]["observation"].any()


@pytest.mark.parametrize("name", ROBOTICS)
def test_trajectories_are_the_raw_gymnasium_robotics_ones(name):
    """Our env steps exactly as the gymnasium-robotics env it wraps (same seed, same actions)."""
    from bench_envs import raw_robotics_env  # benchmarks/ (pytest's pythonpath)

    ours, raw = make_gym_env(name), raw_robotics_env(name)
    rng = np.random.default_rng(0)
    obs, _ = ours.reset(seed=7)
    raw_obs, _ = raw.reset(seed=7)
    for t in range(60):
        flat = np.concatenate([raw_obs["observation"], raw_obs["achieved_goal"]]) if isinstance(raw_obs, dict) else raw_obs
        np.testing.assert_allclose(obs, flat.astype(np.float32), rtol=0, atol=0, err_msg=f"step {t}")
        action = rng.uniform(-1, 1, ours.action_space.shape).astype(np.float32)
        obs, reward, terminated, _, info = ours.step(action)
        raw_obs, raw_reward, raw_terminated, _, raw_info = raw.step(action)
        assert (reward, terminated, info["success"]) == (raw_reward, raw_terminated, raw_info["success"])
