"""Tests of the CSIRL driving scenarios, their TorchRL wrapper and the accomplish-rate metric."""
from __future__ import annotations

import functools
import math
import pickle

import numpy as np
import pytest
import torch
from highway_env.envs.common.observation import KinematicObservation
from highway_env.envs.intersection_env import IntersectionEnv
from tensordict import TensorDict
from torchrl.envs.utils import check_env_specs

from torchrl_csirl._compat import gym_env_of
from torchrl_csirl.tasks import (
    INFO_KEYS,
    SCENARIOS,
    accomplish_rate,
    accomplish_rate_from_rollout,
    area_under_curve,
    make_env,
    make_gym_env,
    normalized_accomplish_rate,
    success_from_rollout,
)
from torchrl_csirl.tasks.driving._observation import FastKinematicObservation

NAMES = list(SCENARIOS)


# ----------------------------------------------------------------------------- specs
@pytest.mark.parametrize("name", NAMES)
def test_spec_matches_environment(name):
    spec = SCENARIOS[name]
    env = make_gym_env(name)
    obs, info = env.reset(seed=0)
    assert spec.gym_id == f"csirl/{name}-v0"
    assert obs.shape == (spec.obs_dim,) == env.observation_space.shape
    assert obs.dtype == np.float32
    assert spec.obs_dim == spec.vehicles_count * len(spec.features)
    assert env.action_space.shape == (spec.action_dim,)
    assert spec.ego_feature_indices == tuple(range(len(spec.features)))
    expected = ("x",) if name in ("highway-fast", "merge") else ("x", "y")
    assert spec.position_features == expected
    assert spec.finish_position == tuple(env.unwrapped.config["finish_position"])
    # the ego's normalised position in the observation is what normalize_position computes
    ego_xy = env.unwrapped.vehicle.position
    np.testing.assert_allclose(
        obs[list(spec.position_feature_indices)],
        np.clip(spec.normalize_position(ego_xy), -1, 1),
        rtol=0,
        atol=1e-6,
    )
    assert set(INFO_KEYS) <= set(info)
    assert info["distance_to_finish"] == pytest.approx(
        float(np.linalg.norm(ego_xy - np.asarray(spec.finish_position)))
    )


def test_scene_parameters():
    hw = make_gym_env("highway-fast").unwrapped
    hw.reset(seed=0)
    assert hw.vehicle.speed == 35.0
    assert len(hw.road.network.lanes_list()) == 3
    assert len(hw.road.vehicles) == 21
    assert all(lane.speed_limit == 25.0 for lane in hw.road.network.lanes_list())

    rb = make_gym_env("roundabout").unwrapped
    rb.reset(seed=0)
    np.testing.assert_allclose(rb.vehicle.position, [2.0, 70.0])
    assert rb.vehicle.speed == 8.0
    assert rb.vehicle.heading == pytest.approx(-math.pi / 2)
    assert len(rb.road.vehicles) == 7  # ego + 6
    radii = sorted({lane.radius for lane in rb.road.network.lanes_list() if hasattr(lane, "radius")})
    assert radii == [20.0, 24.0, 28.0, 32.0]

    it = make_gym_env("intersection").unwrapped
    it.reset(seed=0)
    left_turns = [it.road.network.get_lane((f"ir1{c}", f"il1{(c + 1) % 4}", 0)) for c in range(4)]
    assert all(lane.radius == 17.0 for lane in left_turns)
    assert it.vehicle.lane_index[:2] == ("o10", "ir10")


# ----------------------------------------------------------------------------- TorchRL
@pytest.mark.parametrize("name", NAMES)
def test_check_env_specs(name):
    env = make_env(name, seed=0)
    check_env_specs(env)
    td = env.rollout(5)
    assert td["observation"].dtype == torch.float32
    for key in INFO_KEYS:
        assert ("next", key) in td.keys(True)
    assert td["next", "crashed"].dtype == torch.bool
    env.close()


def _fixed_actions(n: int, seed: int) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    # mild steering so that episodes last a while
    return torch.stack([torch.rand(n, generator=g) * 2 - 1, 0.05 * torch.randn(n, generator=g)], -1)


@pytest.mark.parametrize("name", NAMES)
def test_seeded_determinism(name):
    actions = _fixed_actions(25, seed=3)

    def run(seed):
        env = make_env(name, seed=seed, offroad_terminal=False)
        td = env.reset()
        observations = [td["observation"]]
        for a in actions:
            td = env.step(td.set("action", a))
            observations.append(td["next", "observation"])
            if td["next", "done"]:
                break
            td = td["next"]
        env.close()
        return torch.stack(observations)

    first, second, other = run(7), run(7), run(8)
    assert torch.equal(first, second)
    assert not (first.shape == other.shape and torch.equal(first, other))


def test_factory_is_picklable():
    factory = functools.partial(make_env, "merge", seed=1)
    restored = pickle.loads(pickle.dumps(factory))
    env = restored()
    assert env.rollout(2)["observation"].shape[-1] == SCENARIOS["merge"].obs_dim
    env.close()


# ----------------------------------------------------------------------------- fast paths
def _lockstep(name: str, episodes: int, max_steps: int, seed: int = 0, action_seed: int = 1):
    """Run stock and fast variants side by side; yield (fast_env, fast_obs, stock_obs)."""
    fast = make_gym_env(name, offroad_terminal=False)
    stock = make_gym_env(name, fast=False, offroad_terminal=False)
    rng = np.random.default_rng(action_seed)
    for episode in range(episodes):
        obs_f, _ = fast.reset(seed=seed + episode)
        obs_s, _ = stock.reset(seed=seed + episode)
        yield fast, stock, obs_f, obs_s
        for _ in range(max_steps):
            action = np.array([rng.uniform(-1, 1), rng.normal(0, 0.05)], np.float32)
            obs_f, r_f, term_f, trunc_f, _ = fast.step(action)
            obs_s, r_s, term_s, trunc_s, _ = stock.step(action)
            assert (term_f, trunc_f, r_f) == (term_s, trunc_s, r_s)
            yield fast, stock, obs_f, obs_s
            if term_f or trunc_f:
                break


@pytest.mark.parametrize("name", NAMES)
def test_fast_scene_identical_to_stock(name):
    """Fast observation, ego prediction and regulation give bit-identical episodes."""
    steps = clipped = absent = yielding = 0
    n_features = len(SCENARIOS[name].features)
    # intersection: seed 0 with these actions makes vehicles yield within ~20 steps
    episodes, max_steps = (2, 40) if name == "intersection" else (3, 70)
    for fast, stock, obs_f, obs_s in _lockstep(name, episodes=episodes, max_steps=max_steps):
        assert isinstance(fast.observation_type, FastKinematicObservation)
        assert type(stock.observation_type) is KinematicObservation
        assert np.array_equal(obs_f, obs_s)
        assert len(fast.road.vehicles) == len(stock.road.vehicles)
        for v_f, v_s in zip(fast.road.vehicles, stock.road.vehicles):
            assert np.array_equal(v_f.position, v_s.position)
            assert v_f.heading == v_s.heading and v_f.speed == v_s.speed
        steps += 1
        clipped += int(np.any(np.abs(obs_f) == 1.0))
        absent += int(np.any(obs_f.reshape(-1, n_features)[:, 0] == 0))
        yielding += sum(hasattr(v, "is_yielding") for v in fast.road.vehicles)
    assert steps > 40
    assert clipped > 0  # far vehicles / fast speeds hit the feature ranges
    if name == "merge":
        assert absent > 0  # fewer than 4 vehicles in perception range
    if name == "intersection":
        assert yielding > 0  # the cached regulation pass did make vehicles yield


@pytest.mark.parametrize(
    "name,options",
    [
        ("highway-fast", {"see_behind": True, "vehicles_count": 8}),
        ("highway-fast", {"absolute": False}),
        ("merge", {"include_obstacles": True, "vehicles_count": 10}),
        ("roundabout", {"features": ["presence", "x", "y", "heading", "long_off", "lat_off"]}),
        ("intersection", {"order": "shuffled"}),
        ("intersection", {"clip": False, "normalize": True}),
    ],
)
def test_fast_observation_options_match_stock(name, options):
    env = make_gym_env(name, offroad_terminal=False)
    env.reset(seed=1)
    config = {**env.config["observation"], **options}
    fast = FastKinematicObservation(env, **config)
    stock = KinematicObservation(env, **config)
    rng = np.random.default_rng(0)
    absent = 0
    for _ in range(15):
        state = env.np_random.bit_generator.state
        expected = stock.observe()
        env.np_random.bit_generator.state = state  # "shuffled" draws from the env generator
        got = fast.observe()
        assert got.dtype == expected.dtype == np.float32
        assert np.array_equal(got, expected)
        absent += int(np.any(got[:, 0] == 0))
        _, _, terminated, truncated, _ = env.step(
            np.array([rng.uniform(-1, 1), rng.normal(0, 0.05)], np.float32)
        )
        if terminated or truncated:
            env.reset(seed=2)
    if config["vehicles_count"] >= 10:
        assert absent > 0  # zero rows for missing vehicles


# ----------------------------------------------------------------------------- episode ends
def _drive_slowly(env, max_steps: int):
    """Hold ~1 m/s straight ahead on an empty road; return the (terminated, truncated, step)."""
    base = env.unwrapped
    for step in range(1, max_steps + 5):
        accel = np.clip((1.0 - base.vehicle.speed) / 15.0, -1, 1)
        _, _, terminated, truncated, info = env.step(np.array([accel, 0.0], np.float32))
        if terminated or truncated:
            return terminated, truncated, step, info
    return False, False, max_steps + 5, info


@pytest.mark.parametrize("name", NAMES)
def test_episode_limit_is_truncation(name):
    spec = SCENARIOS[name]
    env = make_gym_env(name, spawn_probability=0.0) if name == "intersection" else make_gym_env(name)
    env.reset(seed=0)
    env.unwrapped.road.vehicles = [env.unwrapped.vehicle]  # nobody to crash into
    terminated, truncated, step, info = _drive_slowly(env, spec.max_steps)
    assert (terminated, truncated, step) == (False, True, spec.max_steps)
    assert not info["crashed"] and not info["offroad"]


def test_merge_truncates_at_60_steps_in_torchrl():
    env = make_env("merge", seed=0)
    base = gym_env_of(env).unwrapped
    td = env.reset()
    base.road.vehicles = [base.vehicle]
    for step in range(1, 61):
        accel = float(np.clip((1.0 - base.vehicle.speed) / 15.0, -1, 1))
        td = env.step(td.set("action", torch.tensor([accel, 0.0])))
        if td["next", "done"]:
            break
        td = td["next"]
    assert step == 60
    assert td["next", "truncated"].item() and not td["next", "terminated"].item()


def test_crash_and_offroad_terminate():
    env = make_gym_env("highway-fast")
    env.reset(seed=0)
    for _ in range(50):  # steering right leaves the road
        _, _, terminated, truncated, info = env.step(np.array([0.0, 0.2], np.float32))
        if terminated or truncated:
            break
    assert terminated and not truncated
    assert info["offroad"] or info["crashed"]

    merge = make_gym_env("merge")
    merge.reset(seed=0)
    base = merge.unwrapped
    front = [v for v in base.road.vehicles if v is not base.vehicle]
    front[0].position = base.vehicle.position + np.array([3.0, 0.0])  # overlap: collision
    _, _, terminated, truncated, info = merge.step(np.zeros(2, np.float32))
    assert terminated and not truncated and info["crashed"] and not info["success"]


@pytest.mark.parametrize("name", ["roundabout", "intersection"])
def test_other_vehicles_collide_option(name):
    """Scene deviation: non-ego vehicles ignore each other (as highway-fast-v0), not the ego."""
    # defaults: the intersection deviates from stock, the roundabout keeps stock collisions
    assert SCENARIOS[name].config["other_vehicles_collide"] is (name == "roundabout")
    env = make_gym_env(name, other_vehicles_collide=False)
    env.reset(seed=0)
    base = env.unwrapped
    others = [v for v in base.road.vehicles if v is not base.vehicle]
    assert base.vehicle.check_collisions and not any(v.check_collisions for v in others)
    # two overlapping non-ego vehicles do not crash; one overlapping the ego does
    a, b = others[0], others[1]
    b.position = a.position.copy()
    b.heading = a.heading
    base.road.step(0.01)
    assert not a.crashed and not b.crashed
    a.position = base.vehicle.position.copy()
    base.road.step(0.01)
    assert base.vehicle.crashed
    if name == "intersection":  # vehicles spawned during the episode too
        for _ in range(10):
            env.step(np.zeros(2, np.float32))
        assert not any(v.check_collisions for v in base.road.vehicles if v is not base.vehicle)
    # the stock behaviour is one option away
    stock = make_gym_env(name, other_vehicles_collide=True)
    stock.reset(seed=0)
    assert all(v.check_collisions for v in stock.unwrapped.road.vehicles)


def test_merge_ends_past_370():
    env = make_gym_env("merge")
    env.reset(seed=0)
    base = env.unwrapped
    base.road.vehicles = [base.vehicle]
    base.vehicle.position = np.array([369.0, 4.0])
    _, _, terminated, truncated, info = env.step(np.zeros(2, np.float32))
    assert terminated and not truncated
    assert info["arrived"] and info["success"]


def _drive_one_step_from(env, lane_index: tuple, longitudinal: float, speed: float):
    """Put the ego alone on ``lane_index`` at ``longitudinal`` m and step once (zero action)."""
    base = env.unwrapped
    lane = base.road.network.get_lane(lane_index)
    base.road.vehicles = [base.vehicle]
    base.vehicle.position = lane.position(longitudinal, 0.0)
    base.vehicle.heading = lane.heading_at(longitudinal)
    base.vehicle.speed = speed
    base.vehicle.on_state_update()
    return env.step(np.zeros(2, np.float32))


@pytest.mark.parametrize(
    "name, lane_index, longitudinal, speed",
    [("highway-fast", ("0", "1", 2), 645.0, 35.0), ("roundabout", ("nxs", "nxr", 0), 14.0, 10.0)],
)
def test_episode_ends_at_the_finish_in_scenes_that_drive_on(name, lane_index, longitudinal, speed):
    """highway-fast and roundabout end on arrival, as merge and intersection do; stock drives on."""
    env = make_gym_env(name)
    env.reset(seed=0)
    _, _, terminated, truncated, info = _drive_one_step_from(env, lane_index, longitudinal, speed)
    assert info["arrived"] and info["success"] and terminated and not truncated
    stock = make_gym_env(name, arrival_terminal=False)
    stock.reset(seed=0)
    _, _, terminated, truncated, info = _drive_one_step_from(stock, lane_index, longitudinal, speed)
    assert info["arrived"] and info["success"] and not terminated and not truncated


def test_intersection_arrival_only_at_intended_destination():
    env = make_gym_env("intersection", spawn_probability=0.0)
    env.reset(seed=0)
    base = env.unwrapped
    network = base.road.network
    exits = [
        (a, b, i)
        for a, targets in network.graph.items()
        for b, lanes in targets.items()
        for i in range(len(lanes))
        if a.startswith("il") and b.startswith("o")
    ]
    assert len(exits) == 8  # 4 exits x 2 lanes
    arrivals = []
    for lane_index in exits:
        lane = network.get_lane(lane_index)
        base.vehicle.position = lane.position(35.0, 0.0)
        base.vehicle.heading = lane.heading_at(35.0)
        base.vehicle.on_state_update()
        assert base.vehicle.lane_index == lane_index
        assert IntersectionEnv.has_arrived(base, base.vehicle)  # upstream: any exit counts
        if base.has_arrived(base.vehicle):
            arrivals.append(lane_index)
    assert arrivals == [("il11", "o11", 0)]  # the left turn's exit lane only
    # before the finish (30 m along the exit lane, x = -45) it has not arrived yet
    lane = network.get_lane(("il11", "o11", 0))
    base.vehicle.position = lane.position(20.0, 0.0)
    base.vehicle.on_state_update()
    assert not base.has_arrived(base.vehicle)
    # a step from just before the finish ends the episode with success
    base.road.vehicles = [base.vehicle]
    base.vehicle.position = lane.position(29.0, 0.0)
    base.vehicle.heading = lane.heading_at(29.0)
    base.vehicle.speed = 9.0
    base.vehicle.on_state_update()
    _, _, terminated, truncated, info = env.step(np.zeros(2, np.float32))
    assert terminated and not truncated and info["arrived"] and info["success"]
    assert info["distance_to_finish"] < 2.0


@pytest.mark.parametrize("name", ["merge", "roundabout"])
def test_continuous_actions_construct_and_step(name):
    # upstream merge-v0 / roundabout-v0 raise here (reward evaluates `action in [0, 2]`)
    env = make_gym_env(name)
    env.reset(seed=0)
    obs, reward, terminated, truncated, info = env.step(np.array([0.3, -0.1], np.float32))
    assert np.isfinite(reward) and obs.shape == (SCENARIOS[name].obs_dim,)
    assert env.unwrapped.action_type.acceleration_range == [-15.0, 15.0]
    assert env.unwrapped.action_type.steering_range == pytest.approx([-math.pi / 2, math.pi / 2])


@pytest.mark.parametrize("name", NAMES)
def test_random_policy_accomplish_rate_is_low(name):
    # Measured over 10 episodes (seeds 0..9): highway 0.016, merge 0.016, roundabout 0.026,
    # intersection 0.079 -- the paper's Random row reads 0.02 / 0.01 / 0.04 / 0.16.
    env = make_gym_env(name)
    rates = []
    for episode in range(4):
        rng = np.random.default_rng(episode)
        _, info = env.reset(seed=episode)
        distances = [info["distance_to_finish"]]
        while True:
            _, _, terminated, truncated, info = env.step(rng.uniform(-1, 1, 2).astype(np.float32))
            distances.append(info["distance_to_finish"])
            if terminated or truncated:
                break
        rates.append(accomplish_rate(distances))
        assert info["progress"] <= rates[-1] + 1e-12  # progress is per step, the rate its max
    assert 0.0 <= np.mean(rates) < 0.3


# ----------------------------------------------------------------------------- metric
def test_accomplish_rate_values():
    assert accomplish_rate([100.0, 80.0, 30.0, 50.0]) == pytest.approx(0.7)
    assert accomplish_rate([10.0, 12.0, 11.0]) == 0.0  # never closer: clipped at 0
    assert accomplish_rate([10.0, 5.0, 0.0]) == 1.0
    assert accomplish_rate([10.0]) == 0.0
    assert accomplish_rate([0.0, 3.0]) == 1.0  # started at the finish
    assert accomplish_rate(np.array([4.0, float("nan"), 1.0])) == pytest.approx(0.75)
    batch = accomplish_rate(torch.tensor([[4.0, 2.0, 3.0], [8.0, 8.0, 0.0]]))
    assert torch.allclose(batch, torch.tensor([0.5, 1.0], dtype=torch.float64))
    with pytest.raises(ValueError):
        accomplish_rate([])
    with pytest.raises(ValueError):
        accomplish_rate([-1.0, 2.0])


def test_accomplish_rate_from_rollout_uses_first_episode():
    td = TensorDict(
        {
            "distance_to_finish": torch.tensor([[10.0, 9.0, 6.0, 100.0], [10.0, 8.0, 8.0, 8.0]]),
            "next": {
                "distance_to_finish": torch.tensor([[9.0, 6.0, 100.0, 0.0], [8.0, 8.0, 8.0, 8.0]]),
                "done": torch.tensor([[False, False, True, False], [False] * 4]).unsqueeze(-1),
                "success": torch.tensor([[False, False, False, True], [False] * 4]).unsqueeze(-1),
            },
        },
        batch_size=[2, 4],
    )
    rates = accomplish_rate_from_rollout(td)
    # row 0: the reset after the first done (distance 0 at the end) is ignored
    assert torch.allclose(rates, torch.tensor([0.4, 0.2], dtype=torch.float64))
    assert success_from_rollout(td).tolist() == [False, False]
    with pytest.raises(KeyError):
        accomplish_rate_from_rollout(td.exclude("distance_to_finish"))


def test_accomplish_rate_on_real_rollout():
    env = make_env("merge", seed=0)
    td = env.rollout(60)
    distances = torch.cat([td["distance_to_finish"][:1], td["next", "distance_to_finish"]])
    assert accomplish_rate_from_rollout(td).item() == pytest.approx(accomplish_rate(distances))
    assert accomplish_rate_from_rollout(td).item() == pytest.approx(
        td["next", "progress"].max().item(), abs=1e-5
    )


def test_normalized_rate_and_auc():
    assert normalized_accomplish_rate(0.45, 0.9) == pytest.approx(0.5)
    assert torch.allclose(
        normalized_accomplish_rate(torch.tensor([0.5, 1.0]), 0.5),
        torch.tensor([1.0, 2.0], dtype=torch.float64),
    )
    with pytest.raises(ValueError):
        normalized_accomplish_rate(0.5, 0.0)
    assert area_under_curve([0.0, 0.5, 1.0]) == pytest.approx(0.5)
    with pytest.raises(ValueError):
        area_under_curve([])
