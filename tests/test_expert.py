"""Tests of the expert driver, the shipped demonstrations and the generation recipe."""
from __future__ import annotations

import importlib.util
import math
import os

import numpy as np
import pytest
import torch

from torchrl_csirl.data.shipped import (
    CURRICULA,
    DATASET_SIZES,
    available_expert_datasets,
    curriculum_trajectory,
    load_expert_demonstrations,
)
from torchrl_csirl.tasks import SCENARIOS, make_gym_env, make_gymnasium_task
from torchrl_csirl.tasks.driving.expert import (
    ExpertDriver,
    clear_traffic,
    make_expert,
    normalize_action,
    rollout_expert,
)

SCENARIO_NAMES = ["highway-fast", "merge", "roundabout", "intersection"]
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

_EPISODES: dict[str, dict] = {}


def _shipped_traffic_seed(scenario: str) -> int:
    """Seed of a successful with-traffic expert episode (trajectory 1 of the shipped file)."""
    return int(load_expert_demonstrations(scenario, 5).metadata["episodes"][1]["seed"])


def _expert_episode(scenario: str) -> dict:
    if scenario not in _EPISODES:
        env = make_gym_env(scenario)
        _EPISODES[scenario] = rollout_expert(
            env, seed=_shipped_traffic_seed(scenario), scenario=scenario, end_at_arrival=True
        )
        env.close()
    return _EPISODES[scenario]


def _load_recipe():
    path = os.path.join(ROOT, "recipes", "generate_experts.py")
    spec = importlib.util.spec_from_file_location("generate_experts", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# ---------------------------------------------------------------------------------------------- expert
@pytest.mark.parametrize("scenario", SCENARIO_NAMES)
def test_expert_completes_route_with_traffic(scenario):
    episode = _expert_episode(scenario)
    assert episode["success"], f"{scenario}: expert failed (accomplish {episode['accomplish_rate']:.3f})"
    assert not episode["crashed"] and not episode["offroad"]
    # merge ends at x > 370 while its finish is x = 400: raw accomplish rate ceiling ~0.92;
    # the recording ends at arrival: roundabout arrives within 5 m of a finish ~145 m away
    floor = {"merge": 0.9, "roundabout": 0.96}.get(scenario, 0.97)
    assert episode["accomplish_rate"] >= floor
    actions = episode["action"]
    assert actions.dtype == np.float32 and actions.shape[1] == 2
    assert np.abs(actions).max() <= 1.0


@pytest.mark.parametrize("scenario", SCENARIO_NAMES)
def test_expert_reproduces_shipped_trajectory(scenario):
    episode = _expert_episode(scenario)
    demos = load_expert_demonstrations(scenario, 5, curriculum="traffic")
    stored = demos.trajectory(1)
    assert stored["action"].shape[0] == episode["length"]
    torch.testing.assert_close(stored["action"], torch.as_tensor(episode["action"]))
    torch.testing.assert_close(stored["observation"], torch.as_tensor(episode["observation"]))


def test_expert_beats_random_policy():
    scenario = "intersection"
    expert_rate = _expert_episode(scenario)["accomplish_rate"]
    env = make_gym_env(scenario)
    rng = np.random.default_rng(0)
    random_rates = []
    for seed in range(3):
        _, info = env.reset(seed=seed)
        distances = [info["distance_to_finish"]]
        while True:
            _, _, terminated, truncated, info = env.step(rng.uniform(-1, 1, size=2).astype(np.float32))
            distances.append(info["distance_to_finish"])
            if terminated or truncated:
                break
        d = np.asarray(distances)
        random_rates.append(float(np.clip((d[0] - d.min()) / d[0], 0, 1)))
    assert expert_rate > np.mean(random_rates) + 0.5


def test_clear_traffic_leaves_only_ego():
    env = make_gym_env("intersection")
    env.reset(seed=0)
    obs = clear_traffic(env)
    assert env.unwrapped.road.vehicles == [env.unwrapped.vehicle]
    rows = obs.reshape(5, -1)
    assert rows[0, 0] == 1 and np.all(rows[1:, 0] == 0)  # presence of the other rows


def _expert_action_with_vehicle_ahead(distance: float | None) -> np.ndarray:
    """The highway-fast expert's first action on an empty road, with one stopped vehicle ``distance`` m ahead."""
    from highway_env.vehicle.kinematics import Vehicle

    env = make_gym_env("highway-fast")
    env.reset(seed=0)
    clear_traffic(env)
    base = env.unwrapped
    ego = base.vehicle
    if distance is not None:
        lane = base.road.network.get_lane(ego.lane_index)
        s, _ = lane.local_coordinates(ego.position)
        base.road.vehicles.append(Vehicle(base.road, lane.position(s + distance, 0.0), lane.heading_at(s), 0.0))
    expert = make_expert("highway-fast")
    expert.reset(env)
    action = expert.act(env)
    env.close()
    return action


def test_expert_controls_with_what_it_perceives():
    """The executing controller sees the vehicles the look-ahead simulates (``perception_radius``), no more.

    A stopped vehicle 70 m ahead (outside highway-fast's 60 m radius, inside the controller's
    80 m reach) used to make the expert brake for a vehicle its plan did not contain; one 50 m
    ahead is perceived and changes the action.
    """
    assert make_expert("highway-fast").config.perception_radius == 60.0
    free = _expert_action_with_vehicle_ahead(None)
    np.testing.assert_array_equal(_expert_action_with_vehicle_ahead(70.0), free)
    assert not np.array_equal(_expert_action_with_vehicle_ahead(50.0), free)


def test_overlaps_lane_counts_a_front_turned_into_the_lane():
    """The junction-clearance rule's overlap test: a vehicle whose centre is clear of a lane but whose
    front is turned into it is on the lane; the same vehicle parallel to the lane is not."""
    from highway_env.road.lane import StraightLane
    from highway_env.road.road import Road, RoadNetwork
    from highway_env.vehicle.kinematics import Vehicle

    from torchrl_csirl.tasks.driving.expert_driver import _overlaps_lane

    network = RoadNetwork()
    lane = StraightLane([0.0, 0.0], [100.0, 0.0], width=4.0)
    network.add_lane("a", "b", lane)
    road = Road(network)
    centre = np.array([50.0, 4.5])  # 4.5 m from the centre line: beyond half the lane + half a car
    turned = Vehicle(road, centre, heading=-math.pi / 2 + 0.3, speed=0.0)
    parallel = Vehicle(road, centre, heading=0.0, speed=0.0)
    assert _overlaps_lane(turned, lane)
    assert not _overlaps_lane(parallel, lane)
    assert _overlaps_lane(Vehicle(road, np.array([50.0, 2.5]), heading=0.0, speed=0.0), lane)


def test_normalize_action_units_and_clipping():
    np.testing.assert_allclose(normalize_action(7.5, math.pi / 4), [0.5, 0.5])
    np.testing.assert_allclose(normalize_action(-100.0, 10.0), [-1.0, 1.0])
    assert normalize_action(0.0, 0.0).dtype == np.float32


def test_make_expert_rejects_unknown_scenario_and_overrides_config():
    with pytest.raises(ValueError, match="Unknown scenario"):
        make_expert("parking")
    with pytest.raises(ValueError, match="Unknown scenario"):
        ExpertDriver("parking")
    assert make_expert("merge", horizon=7).config.horizon == 7
    with pytest.raises(ValueError, match="takes fields of ExpertConfig"):
        make_expert("merge", lookahead=3.0)


def test_the_driving_expert_knows_every_driving_scenario_of_the_registry():
    from torchrl_csirl.tasks import task_names
    from torchrl_csirl.tasks.driving.expert import EXPERT_CONFIGS, expert_tasks

    assert sorted(EXPERT_CONFIGS) == list(task_names(family="driving")) == sorted(SCENARIO_NAMES)
    assert set(task_names(family="driving")) <= set(expert_tasks())


def test_roundabout_exit_approach_lane_is_the_outer_ring_lane():
    env = make_gym_env("roundabout")
    env.reset(seed=0)
    expert = make_expert("roundabout")
    expert.reset(env)
    route = expert._route
    k_exit = route.roads.index(("nx", "nxs"))
    outer = len(route.lanes_of(k_exit - 1)) - 1
    # only the last ring road before the exit forces the lane; progress is measured on the outer lane
    assert route.approach_lane(k_exit - 1) == outer
    assert route.approach_lane(k_exit - 2) is None and route.approach_lane(k_exit) is None
    assert route.reference_lane(k_exit - 2) == outer and route.reference_lane(k_exit) == 0
    lanes = route.path_lanes(env.unwrapped.vehicle.position, lane_id=0, count=len(route.roads))
    assert lanes[k_exit - 1] is route.lanes_of(k_exit - 1)[outer]
    assert lanes[k_exit - 2] is route.lanes_of(k_exit - 2)[0]
    env.close()


def test_intersection_junction_clearance_rule():
    """Slow inside the junction counts as stuck only where crossing traffic drives (not just past the
    stop line, not when moving at ``junction_min_speed`` or faster)."""
    env = make_gym_env("intersection")
    env.reset(seed=0)
    expert = make_expert("intersection")
    expert.reset(env)
    route = expert._route.copy()
    k = route.roads.index(("ir10", "il11"))
    assert route.roads[k - 1] in expert.config.yield_roads
    route.road_index = k
    ego = env.unwrapped.vehicle
    turn = route.lanes_of(k)[0]
    assert any(lane.local_coordinates(turn.position(turn.length / 2, 0.0))[0] >= 0 for lane in route.crossing_lanes(k))
    for longitudinal, speed, stuck in ((turn.length / 2, 0.0, True), (turn.length / 2, 5.0, False), (0.5, 0.0, False)):
        ego.position = turn.position(longitudinal, 0.0)
        ego.heading = turn.heading_at(longitudinal)
        ego.speed = speed
        assert expert._stuck_in_junction(ego, route) is stuck, (longitudinal, speed)
    # the rule is off in the other scenarios
    assert all(make_expert(s).config.junction_min_speed is None for s in ("highway-fast", "merge", "roundabout"))
    env.close()


def test_intersection_expert_does_not_stop_in_crossing_traffic():
    """Seed 20004: without the junction-clearance rule the expert entered the junction, braked to a
    stop on the left-turn path (a vehicle crossing ahead) and was hit by a vehicle turning from the west."""
    env = make_gym_env("intersection")
    episode = rollout_expert(env, seed=20004, scenario="intersection", max_steps=35)  # the crash was at step 30
    assert not episode["crashed"] and not episode["offroad"]
    env.close()


def test_merge_expert_nudges_past_two_slow_vehicles_side_by_side():
    """Seed 10007: the two vehicles ahead slow to 20 m/s in different lanes ~9 m apart (both lanes
    blocked); before nudging the expert stayed behind them and timed out."""
    env = make_gym_env("merge")
    env.reset(seed=10007)
    base = env.unwrapped
    ego_x = base.vehicle.position[0]
    ahead = sorted((v for v in base.road.vehicles if v.position[0] > ego_x), key=lambda v: v.position[0])
    assert {v.lane_index[2] for v in ahead[:2]} == {0, 1} and ahead[1].position[0] - ahead[0].position[0] < 15
    expert = make_expert("merge")
    behaviours = []
    decide = expert.decide

    def recording_decide(road, vehicle):
        behaviours.append(decide(road, vehicle))
        return behaviours[-1]

    expert.decide = recording_decide
    episode = rollout_expert(env, seed=10007, expert=expert, scenario="merge")
    assert episode["success"] and not episode["crashed"]
    assert any(b.nudge for b in behaviours)
    env.close()


# ---------------------------------------------------------------------------------------------- shipped data
def test_all_shipped_datasets_available():
    # the point mazes are tasks once registered (an earlier test in the process may have done it): register them here
    point_mazes = ("PointMaze_UMaze-v3", "PointMaze_Medium-v3")
    for gym_id in point_mazes:
        make_gymnasium_task(gym_id)
    assert available_expert_datasets() == {**{s: list(CURRICULA) for s in SCENARIO_NAMES}, "antmaze-umaze": ["expert"],
                                           "relocate": ["expert"], "halfcheetah": ["expert"], "hopper": ["expert"],
                                           **{gym_id: ["expert"] for gym_id in point_mazes}}


@pytest.mark.parametrize("scenario", SCENARIO_NAMES)
def test_shipped_datasets_counts_shapes_and_nested_prefixes(scenario):
    spec = SCENARIOS[scenario]
    full = {c: load_expert_demonstrations(scenario, 25, curriculum=c) for c in CURRICULA}
    for curriculum, demos in full.items():
        assert demos.num_trajectories == 25
        assert demos.observation_dim == spec.obs_dim and demos.action_dim == 2
        td = demos.transitions()
        assert td["action"].dtype == torch.float32
        assert td["action"].abs().max() <= 1.0
        assert torch.all(td["observation"].abs() <= 1.0)
        assert all(e["success"] for e in demos.metadata["episodes"])
        assert demos.metadata["curriculum"] == curriculum
        for n in DATASET_SIZES:
            small = load_expert_demonstrations(scenario, n, curriculum=curriculum)
            assert small.num_trajectories == n
            # nested prefixes: file N = file 1's trajectory + N - 1 others, in order
            for i in range(n):
                torch.testing.assert_close(small.trajectory(i)["action"], demos.trajectory(i)["action"])
    # both curricula share trajectories 1..24; trajectory 0 differs
    for i in (1, 24):
        torch.testing.assert_close(
            full["empty"].trajectory(i)["observation"], full["traffic"].trajectory(i)["observation"]
        )
    assert not torch.equal(
        full["empty"].trajectory(0)["observation"][:5], full["traffic"].trajectory(0)["observation"][:5]
    )
    # the empty-road curriculum trajectory sees no other vehicle (presence features of rows 1..4)
    empty_obs = curriculum_trajectory(scenario, "empty")["observation"].reshape(-1, 5, spec.obs_dim // 5)
    assert torch.all(empty_obs[:, 1:, 0] <= -1.0 + 1e-6) or torch.all(empty_obs[:, 1:, 0] == 0)
    traffic_obs = curriculum_trajectory(scenario, "traffic")["observation"].reshape(-1, 5, spec.obs_dim // 5)
    assert torch.any(traffic_obs[:, 1:, 0] > 0)


@pytest.mark.parametrize("scenario", SCENARIO_NAMES)
def test_shipped_trajectories_end_at_arrival_without_repeated_states(scenario):
    """Recording stops at arrival: no trailing run of identical (clipped) observations."""
    demos = load_expert_demonstrations(scenario, 25, curriculum="empty")
    for i in range(demos.num_trajectories):
        traj = demos.trajectory(i)
        obs = torch.cat([traj["observation"], traj["next", "observation"][-1:]])
        repeated = (obs[1:] == obs[:-1]).all(-1)
        assert not repeated.any(), f"{scenario} trajectory {i}: identical consecutive observations"
        done = traj["next", "done"].reshape(-1)
        assert done[-1] and not done[:-1].any()
        # every scene ends at the finish: the recording's last transition is a termination
        assert traj["next", "terminated"].reshape(-1)[-1]
        assert traj["action"].shape[0] < SCENARIOS[scenario].max_steps


def test_rollout_end_at_arrival_truncates_highway():
    env = make_gym_env("highway-fast", arrival_terminal=False)  # stock: drives on past the finish
    full = rollout_expert(env, seed=1, empty_road=True)
    cut = rollout_expert(env, seed=1, empty_road=True, end_at_arrival=True)
    assert full["length"] == SCENARIOS["highway-fast"].max_steps and full["success"]
    assert cut["success"] and cut["truncated"][-1] and not cut["terminated"].any()
    assert cut["length"] < full["length"]
    np.testing.assert_array_equal(cut["action"], full["action"][: cut["length"]])
    assert env.unwrapped.vehicle.position[0] >= SCENARIOS["highway-fast"].finish_position[0]


def test_rollout_action_noise_is_seeded_clipped_and_recorded():
    """D4RL-style noisy demonstrations: the executed action is the expert's plus N(0, std^2), clipped,
    recorded as executed (or, DART, the expert's own action), the same for the same seed."""
    env = make_gym_env("merge")
    clean = rollout_expert(env, seed=3, max_steps=6)
    noisy = rollout_expert(env, seed=3, max_steps=6, action_noise=0.3)
    again = rollout_expert(env, seed=3, max_steps=6, action_noise=0.3)
    np.testing.assert_array_equal(noisy["action"], again["action"])
    np.testing.assert_array_equal(noisy["observation"], again["observation"])
    low, high = env.action_space.low, env.action_space.high
    assert ((noisy["action"] >= low) & (noisy["action"] <= high)).all()
    # same reset state, so the first actions differ by the noise alone
    first_noise = noisy["action"][0] - clean["action"][0]
    assert 0 < np.abs(first_noise).max() < 5 * 0.3
    assert noisy["action_noise"] == 0.3 and clean["action_noise"] == 0.0
    # DART: the same perturbed states, labelled with the expert's noise-free action
    dart = rollout_expert(env, seed=3, max_steps=6, action_noise=0.3, record_expert_action=True)
    np.testing.assert_array_equal(dart["observation"], noisy["observation"])
    np.testing.assert_array_equal(dart["action"][0], clean["action"][0])
    assert not np.array_equal(dart["action"], noisy["action"]) and dart["recorded_action"] == "expert"
    with pytest.raises(ValueError, match="action_noise"):
        rollout_expert(env, seed=3, max_steps=2, action_noise=-0.1)


def test_shipped_loader_errors():
    with pytest.raises(ValueError, match="Unknown scenario"):
        load_expert_demonstrations("parking")
    with pytest.raises(ValueError, match="num_trajectories"):
        load_expert_demonstrations("merge", 7)
    with pytest.raises(TypeError):
        load_expert_demonstrations("merge", 5.0)
    with pytest.raises(ValueError, match="curriculum"):
        load_expert_demonstrations("merge", 5, curriculum="busy")


# ---------------------------------------------------------------------------------------------- recipe
def test_generate_experts_same_seed_same_bytes(tmp_path, capsys):
    recipe = _load_recipe()
    paths = [tmp_path / "a.npz", tmp_path / "b.npz"]
    results = []
    for path in paths:
        results.append(
            recipe.main(["--scenario", "merge", "--episodes", "1", "--seed", "3", "--empty-road", "--out", str(path)])
        )
    assert paths[0].read_bytes() == paths[1].read_bytes()
    last_line = capsys.readouterr().out.strip().splitlines()[-1]
    assert '"success_rate"' in last_line and '"accomplish_rate"' in last_line
    assert results[0]["episodes"] == 1 and results[0]["success_rate"] == 1.0
    from torchrl_csirl.data import ExpertDemonstrations

    demos = ExpertDemonstrations.load(paths[0])
    assert demos.num_trajectories == 1 and demos.metadata["empty_road"] is True


@pytest.mark.parametrize("args, message", [
    (["--action-noise", "-0.1"], "--action-noise must be >= 0"),
    (["--record-expert-action"], "--record-expert-action needs --action-noise"),
    (["--action-noise", "0.2", "--shipped"], "--shipped writes the clean expert"),
])
def test_generate_experts_rejects_bad_noise_options(args, message, capsys):
    recipe = _load_recipe()
    with pytest.raises(SystemExit):
        recipe.main(["--scenario", "merge", "--episodes", "1", *args])
    assert message in capsys.readouterr().err
