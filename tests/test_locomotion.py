"""gymnasium's MuJoCo locomotion as tasks (``hopper``, ``halfcheetah``): x in the observation for the
matching reward, out of every network's input; the expert script, CSIRL and a baseline on tiny budgets."""
from __future__ import annotations

import json
import math
import os

import locomotion_probe
import pytest
import termination_probe
import torch
from tensordict import TensorDict

from torchrl_csirl._compat import gym_env_of
from torchrl_csirl.methods.csirl import CSIRL_RECIPE
from torchrl_csirl.modules import DropFeatures, load_policy, make_actor, make_input_features, save_policy
from torchrl_csirl.modules.features import feature_map_from_config
from torchrl_csirl.scripts import csirl_robotics, imitation_robotics, off_demos, train_expert
from torchrl_csirl.tasks import TaskSpec, make_env, resolve_scenario
from torchrl_csirl.tasks.driving.expert import make_expert

TINY = [
    "collector.total_frames=400", "collector.frames_per_batch=200", "collector.cut_episodes=true",
    "collector.num_workers=1", "collector.init_random_frames=200", "collector.main_threads=1",
    "replay_buffer.warmup_frames=200", "optim.utd_ratio=0.1", "eval.episodes=1", "eval.final_episodes=2",
    "eval.video=false", "logger.backend=csv", "logger.progress_bar=false",
]


@pytest.mark.parametrize("name, gym_size", [("hopper", 11), ("halfcheetah", 17)])
def test_the_observation_keeps_x_first_and_the_networks_drop_it(name, gym_size):
    spec = resolve_scenario(name)
    assert spec.obs_dim == gym_size + 1 and spec.hidden_feature_indices == (0,)
    assert spec.matching_features == ("x",) and spec.feature_name(1) == "z"
    env = make_env(name, seed=0)
    rollout = env.rollout(5)
    assert rollout["next", "observation"][-1, 0].item() == pytest.approx(float(gym_env_of(env).unwrapped.data.qpos[0]))
    assert not rollout["next", "success"].any()  # no goal: returns are compared
    features = make_input_features(spec, ego_relative=False)
    assert isinstance(features, DropFeatures) and features.out_features == gym_size
    actor = make_actor(spec.obs_dim, spec.action_dim, input_features=features)
    obs = rollout["observation"][:1]
    moved = obs.clone()
    moved[:, 0] += 50.0  # 50 m further on: the same state for the policy
    with torch.no_grad():
        loc = actor.module[0](TensorDict({"observation": obs}, [1]))["loc"]
        loc_moved = actor.module[0](TensorDict({"observation": moved}, [1]))["loc"]
    torch.testing.assert_close(loc, loc_moved, rtol=0, atol=0)


def test_drop_features_keeps_the_rest_in_order_and_round_trips():
    drop = DropFeatures(5, hidden=[3, 1])
    torch.testing.assert_close(drop(torch.arange(5.0)), torch.tensor([0.0, 2.0, 4.0]))
    rebuilt = feature_map_from_config(drop.config())
    assert isinstance(rebuilt, DropFeatures) and rebuilt.keep == (0, 2, 4)
    with pytest.raises(ValueError, match="size 5, got 4"):
        drop(torch.zeros(4))
    with pytest.raises(ValueError, match="keep at least one entry"):
        DropFeatures(2, hidden=[0, 1])
    spec = resolve_scenario("hopper")
    with pytest.raises(ValueError, match="hidden_feature_indices must be indices in \\[0, 12\\)"):
        TaskSpec(**{**{f: getattr(spec, f) for f in ("obs_dim", "action_dim", "max_steps", "finish_position",
                                                      "ego_feature_indices", "position_feature_indices", "matching_scale")},
                    "name": "bad", "hidden_feature_indices": (12,)})


def test_a_saved_policy_keeps_its_input_map(tmp_path):
    spec = resolve_scenario("halfcheetah")
    actor = make_actor(spec.obs_dim, spec.action_dim, input_features=make_input_features(spec, ego_relative=False))
    path = save_policy(actor, str(tmp_path / "policy.pt"), obs_dim=spec.obs_dim, action_dim=spec.action_dim)
    loaded = load_policy(path)
    obs = TensorDict({"observation": torch.randn(3, spec.obs_dim)}, [3])
    with torch.no_grad():
        torch.testing.assert_close(actor.module[0](obs.clone())["loc"], loaded.module[0](obs.clone())["loc"])


def test_valuedice_standardised_states_measure_the_gradient_penalty_in_them():
    """A network reading raw states through a standardisation, its penalty with the scale, equals the same
    network's layers on standardised states with no scale (the authors' code standardises the env), float64."""
    from torchrl_csirl.modules import ConcatMLP, StandardizeFeatures
    from torchrl_csirl.objectives._imitation import gradient_penalty

    torch.manual_seed(0)
    raw = torch.randn(64, 5, dtype=torch.float64) * torch.tensor([0.05, 1.0, 13.0, 2.0, 0.5], dtype=torch.float64) + 3.0
    norm = StandardizeFeatures.from_data(raw).double()
    net = ConcatMLP(5 + 2, (16,), input_features=norm).double()
    inner = ConcatMLP(5 + 2, (16,)).double()
    inner.mlp.load_state_dict(net.mlp.state_dict())
    action = torch.rand(64, 2, dtype=torch.float64)
    standardised = (raw - norm.loc.double()) / norm.scale.double()
    torch.testing.assert_close(net(raw, action), inner(standardised, action))
    torch.testing.assert_close(gradient_penalty(net, [raw, action], scales=[norm.scale.double(), None]),
                               gradient_penalty(inner, [standardised, action]))
    assert not torch.allclose(gradient_penalty(net, [raw, action]), gradient_penalty(inner, [standardised, action]))


def test_valuedice_reads_standardised_states_where_asked_and_says_where_it_cannot(tmp_path):
    from torchrl_csirl.data import load_expert_demonstrations
    from torchrl_csirl.methods.baselines import load_config, make_trainer
    from torchrl_csirl.modules import StandardizeFeatures, find_standardization
    from torchrl_csirl.run import ConfigError

    cfg = load_config([
        "method=valuedice", "env.task=halfcheetah", "valuedice.normalize_states=true", "expert.num_trajectories=1", *TINY,
        f"logger.output_dir={tmp_path}"])
    run = make_trainer(cfg, str(tmp_path / "run"))
    method = run.parts.method
    norm = find_standardization(method.policy)
    assert isinstance(norm, StandardizeFeatures) and norm.in_features == 18  # x too: dropped after it
    observations = load_expert_demonstrations("halfcheetah", 1).transitions()["observation"]
    torch.testing.assert_close(norm.loc, observations.double().mean(0).float())
    loss = method.states["loss"]
    torch.testing.assert_close(loss.observation_scale, norm.scale)
    assert find_standardization(loss.nu_network) is not None
    path = save_policy(method.policy, str(tmp_path / "policy.pt"), obs_dim=18, action_dim=6)
    obs = TensorDict({"observation": observations[:3]}, [3])
    with torch.no_grad():
        torch.testing.assert_close(method.policy.module[0](obs.clone())["loc"], load_policy(path).module[0](obs.clone())["loc"])
    driving = load_config(["method=valuedice", "env.task=merge", "valuedice.normalize_states=true"])
    with pytest.raises(ConfigError, match="valuedice.normalize_states=true: standardised states need an input map .* "
                                          "got EgoRelativeFeatures"):
        make_trainer(driving, str(tmp_path / "driving"))


def test_the_hopper_cells_of_dac_and_valuedice_enter_the_papers_single_absorbing_state(tmp_path):
    """The benchmark's Hopper cells run DAC and ValueDICE with the papers' placeholder (the expert never falls);
    ValueDICE's, on standardised states, is the raw observation its standardisation maps to zero, with its code's
    10 self-loops per learner termination."""
    from torchrl_csirl.methods.baselines import load_config, make_trainer
    from torchrl_csirl.modules import find_standardization
    from torchrl_csirl.scripts.benchmark import split_overrides, table_overrides

    hopper = split_overrides(table_overrides("hopper"), ["dac", "valuedice", "gail"], "hopper")
    assert "dac.absorbing_observation=placeholder" in hopper["dac"]
    assert "valuedice.absorbing_observation=placeholder" in hopper["valuedice"]
    # ValueDICE's code's absorbing_per_episode; DAC keeps its paper's one per termination
    assert "valuedice.self_loops_per_termination=10" in hopper["valuedice"]
    assert not any("self_loops" in o for o in hopper["dac"])
    assert not any("absorbing" in o for o in hopper["gail"])
    cheetah = split_overrides(table_overrides("halfcheetah"), ["dac", "valuedice"], "halfcheetah")
    assert not any("absorbing" in o for o in cheetah["dac"] + cheetah["valuedice"])
    cfg = load_config([
        "method=valuedice", "env.task=hopper", *hopper["valuedice"], *TINY, f"logger.output_dir={tmp_path}"])
    method = make_trainer(cfg, str(tmp_path / "run")).parts.method
    assert method.states["loss"].self_loops_per_termination == 10
    norm = find_standardization(method.states["loss"].nu_network)
    for transform in (*method.online_transforms, *method.expert_transforms):
        torch.testing.assert_close(transform.absorbing_observation, norm.loc)


def test_an_expert_its_demonstrations_then_csirl_and_a_baseline_on_the_hopper(tmp_path, monkeypatch):
    """train_expert.py -> demonstrations (.npz and Minari) -> csirl_robotics.py and imitation_robotics.py; the
    expert row's policy is the trained one (make_expert(policy=...))."""
    import minari

    from torchrl_csirl.data import load_minari_dataset

    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    expert = train_expert.main(["env.task=hopper", *TINY, "demos.episodes=2", "demos.minari_id=csirl/hopper/tiny-v0",
                                f"logger.output_dir={tmp_path}"])
    assert expert["scenario"] == "hopper" and expert["demos_episodes"] == 2
    assert load_minari_dataset("csirl/hopper/tiny-v0").num_trajectories == 2
    recovered = minari.load_dataset("csirl/hopper/tiny-v0").recover_environment()  # x kept, as the task's
    assert recovered.observation_space.shape == (12,)
    demos = expert["demos_path"]
    csirl = csirl_robotics.main(["env.task=hopper", f"expert.path={demos}", "expert.num_trajectories=2",
                                 "csirl.updates_per_round=10", "csirl.num_qvalue_nets=2", "replay_buffer.batch_size=32",
                                 *TINY, f"logger.output_dir={tmp_path}"])
    assert csirl["scenario"] == "hopper" and csirl["frames"] == 400 and csirl["return"] > 0
    critic = locomotion_probe.probe(csirl["run_dir"], critic=True, plot=str(tmp_path / "critic.png"))["critic"]
    assert critic["critics"] == 2 and len(critic["matching_return_to_go_expert"]) == len(critic["q_expert"]) >= 1
    assert critic["plot"] == str(tmp_path / "critic.png") and os.path.getsize(critic["plot"]) > 0  # its picture
    bc = imitation_robotics.main(["method=bc", "env.task=hopper", f"expert.path={demos}", "expert.num_trajectories=2",
                                  *TINY, f"logger.output_dir={tmp_path}"])
    assert bc["updates"] > 0 and bc["success_rate"] == 0.0
    off = off_demos.check_run(bc["run_dir"], episodes=1)  # the baseline's states against the demos
    assert off["name"] == "states_off_the_demonstrations" and off["figures"]["entries"] == 11  # all but the torso's x
    assert off["first_crash_per_episode"] == [None]  # the Hopper reports no `crashed`
    assert off["figures"]["largest_gap_sd"] >= 0 and len(off["figures"]["farthest_features"]) == 3
    assert off_demos.check_run(bc["run_dir"], holdout=True)["ok"] is True  # a demonstration against the other
    dac = imitation_robotics.main(["method=dac", "env.task=hopper", f"expert.path={demos}", "expert.num_trajectories=2",
                                   *TINY, f"logger.output_dir={tmp_path}"])
    ends = termination_probe.main([dac["run_dir"], "--samples", "64"])  # the locomotion run's own configuration
    assert ends["method"] == "dac" and ends["scenario"] == "hopper"
    assert 0.0 <= ends["agent"]["terminal_fraction"] <= 1.0 and math.isfinite(ends["agent"]["step_reward"])
    driver = make_expert("hopper", policy=expert["run_dir"])
    env = make_env("hopper", seed=0)
    env.reset()
    action = driver.act(gym_env_of(env))
    assert action.shape == (3,) and abs(action).max() <= 1


def test_an_expert_run_stops_at_its_target_and_keeps_demonstrations_above_a_return(tmp_path):
    """eval.stop_at_return ends training at the first evaluation that reaches it (the final test and the
    demonstrations follow); demos.min_return keeps only episodes earning that much."""
    budget = [o for o in TINY if not o.startswith("collector.total_frames")]
    summary = train_expert.main(["env.task=hopper", *budget, "collector.total_frames=2000", "updates_per_round=10",
                                 "eval.stop_at_return=-1000000", "demos.episodes=2", "demos.min_return=-1000000",
                                 f"logger.output_dir={tmp_path}"])
    assert summary["frames"] == 200 and summary["demos_episodes"] == 2  # the first evaluation: the first batch's 20 updates
    probed = locomotion_probe.probe(summary["run_dir"])["episodes"][0]  # the probe: where the policy goes
    assert probed["seed"] == 1_000_000 and len(probed["x_every_100"]) >= 2 and probed["length"] <= 1000
    sampled = locomotion_probe.probe(summary["run_dir"], stochastic=True, critic=True)  # the behaviour, the critics
    assert sampled["actions"] == "sampled" and sampled["episodes"][0] != probed, (sampled, probed)
    critic = sampled["critic"]  # SAC's two critics along the shipped demonstration, against its task reward
    assert critic["critics"] == 2 and list(critic["q_expert"]) == list(critic["task_return_to_go_expert"]) == ["0", "250", "500", "750"]
    with pytest.raises(ValueError, match="only 0 of 1 episodes earned at least 1000000.0 in 10 tries"):
        train_expert.main(["env.task=hopper", *budget, "collector.total_frames=200", "demos.episodes=1",
                           "demos.min_return=1000000", f"logger.output_dir={tmp_path}"])


def test_an_expert_run_can_finish_with_its_best_evaluation(tmp_path):
    """eval.keep_best: the final test, policy.pt and the demonstrations use the best validation's weights
    (best_policy.pt); the checkpoint keeps the last weights, to resume from."""
    budget = [o for o in TINY if not o.startswith("collector.total_frames")]
    summary = train_expert.main(["env.task=hopper", *budget, "collector.total_frames=1000", "updates_per_round=10",
                                 "eval.keep_best=true", "demos.episodes=1", f"logger.output_dir={tmp_path}"])
    run_dir = summary["run_dir"]
    rows = [json.loads(line) for line in open(f"{run_dir}/metrics.jsonl")]
    evaluations = [(r["eval_env_return"], r["frames"]) for r in rows if "eval_env_return" in r]
    assert len(evaluations) == 5, evaluations
    best_return, best_frames = max(evaluations, key=lambda e: (e[0], -e[1]))  # the first of equal bests
    assert best_frames < evaluations[-1][1], evaluations  # this seed's last evaluation is not its best
    assert summary["policy_from"]["frames"] == best_frames
    assert summary["policy_from"]["env_return"] == pytest.approx(best_return)
    kept = torch.load(f"{run_dir}/best_policy.pt", weights_only=True)["state_dict"]
    shipped = load_policy(run_dir)
    assert shipped.metadata["frames"] == best_frames
    exported = {k: v for k, v in shipped.state_dict().items() if k in kept}
    assert exported and all(torch.equal(exported[k], kept[k]) for k in exported)


def test_the_collector_refuses_a_batch_that_cuts_a_locomotion_episode():
    from torchrl_csirl.run import ConfigError
    from torchrl_csirl.run.builders import check_whole_episodes

    cfg = CSIRL_RECIPE.load_config(["env.task=hopper"])  # the robotics scripts' 1 400 frames: 700 per worker
    with pytest.raises(ConfigError, match="frames_per_batch >= 2000"):
        check_whole_episodes(cfg.collector, resolve_scenario("hopper"), 1)


def test_the_benchmark_report_normalises_by_the_expert_row_and_shows_the_published_table(tmp_path):
    import torchrl_csirl.scripts.benchmark as bench

    for method, seed, value in [("expert", 0, 3500.0), ("random", 0, 17.5), ("csirl", 0, 1750.0), ("csirl", 1, 2450.0),
                                ("dac", 0, 3150.0), ("dac", 1, 3290.0)]:
        run_dir = tmp_path / f"hopper-{method}-s{seed}"
        run_dir.mkdir()
        frames = 0 if method in bench.REFERENCE_METHODS else bench.TABLE_BUDGETS["hopper"]
        (run_dir / "summary.json").write_text(json.dumps({
            "scenario": "hopper", "method": method, "seed": seed, "return": value, "frames": frames,
            "success_rate": 0.0, "accomplish_rate": 0.0, "total_wall_s": 600.0}))
    rows = bench.table_rows(bench.read_runs([str(tmp_path)]))
    row = {r["method"]: r for r in rows}
    assert row["expert"]["normalized_return_mean"] == 1.0 and row["random"]["normalized_return_mean"] == 0.005
    assert row["csirl"]["normalized_return_mean"] == pytest.approx(0.6)
    assert row["dac"]["vs_csirl"] == pytest.approx(3220.0 - 2100.0)
    table = bench.markdown_table(rows)
    assert "| csirl | 0.60 ± 0.14 (n=2) |" in table and "300 000 frames per run" in table
    assert f"| dac | {3220.0 / 3500.0:.2f} ± 0.03 (n=2) |" in table  # ours, by our expert: no published figure beside

    def gap(ours: float) -> str:  # the published comparison: raw returns, both sides divided by the paper's expert
        return f"{(ours - 3305.1) / 3532.7:+.2f}".replace("-", "−")

    assert "| method | Hopper: paper (expert 3 532.7) | Hopper: ours, final | Hopper: ours, best evaluation |" in table
    assert f"| dac | 3 305.1 | 3 220 ({gap(3220.0)}) | — |" in table
    assert "| gail | 3 252.5 | — | — |" in table  # no run of ours
    assert "Best evaluation during" not in table  # no run evaluated in training
    # the best of each run's evaluations during training, the published rows' protocol, beside the final policy
    for seed, evaluations in ((0, [2800.0, 3430.0, 3100.0]), (1, [3360.0, 3290.0])):
        (tmp_path / f"hopper-dac-s{seed}" / "metrics.jsonl").write_text("".join(
            json.dumps({"frames": 20000 * (i + 1), "eval_env_return": v}) + "\n" + json.dumps({"frames": 1}) + "\n"
            for i, v in enumerate(evaluations)))
    table = bench.markdown_table(bench.table_rows(bench.read_runs([str(tmp_path)])))
    best = "Best evaluation during training" + table.split("Best evaluation during training")[1]
    assert "| dac | 0.97 ± 0.01 (n=2) |" in best and "| expert |" not in best.split("\n\n")[0]
    assert f"| dac | 3 305.1 | 3 220 ({gap(3220.0)}) | 3 395 ({gap(3395.0)}) |" in table
    (tmp_path / "hopper-dac-s1" / "summary.json").write_text(json.dumps({
        "scenario": "hopper", "method": "dac", "seed": 1, "return": 1400.0, "frames": bench.TABLE_BUDGETS["hopper"],
        "success_rate": 0.0, "accomplish_rate": 0.0, "total_wall_s": 600.0}))
    table = bench.markdown_table(bench.table_rows(bench.read_runs([str(tmp_path)])))
    assert f"| dac | 3 305.1 | 2 275 (**{gap(2275.0)}**) | 3 395" in table  # more than 0.2 below
    assert "antmaze" not in table and "accomplish rate" not in table


@pytest.mark.parametrize("name, floor", [
    ("halfcheetah", 5098.3),  # above the published table's expert (IQ-Learn's)
    ("hopper", 3250.0),  # SAC's best at 924 000 frames, below IQ-Learn's 3 532.7 (docs/experts.md)
])
def test_the_shipped_expert_and_its_demonstrations(tmp_path, name, floor):
    """25 whole episodes above ``floor``, running forward; the expert row replays the shipped policy on the
    test episodes and earns what the demonstrations earned."""
    from torchrl_csirl.data.shipped import load_expert_demonstrations

    spec = resolve_scenario(name)
    demos = load_expert_demonstrations(name, 25)
    episodes = demos.metadata["episodes"]
    assert len(episodes) == 25 and all(e["length"] == spec.max_steps for e in episodes)
    assert min(e["return"] for e in episodes) > floor
    first = load_expert_demonstrations(name, 1).transitions()
    assert first["observation"].shape == (spec.max_steps, spec.obs_dim)
    assert first["next", "observation"][-1, 0] > first["observation"][0, 0] + 10  # x: metres run forward
    row = imitation_robotics.main(["method=expert", f"env.task={name}", "eval.final_episodes=1", "eval.video=false",
                                   "logger.backend=csv", f"logger.output_dir={tmp_path}"])
    assert row["return"] == pytest.approx(sum(e["return"] for e in episodes) / 25, rel=0.05)


def test_valuedice_exploration_noise_reaches_the_collector_not_the_evaluation(tmp_path):
    from torchrl_csirl.methods.baselines import load_config, make_trainer
    from torchrl_csirl.modules import MeanActionGaussianNoise

    cfg = load_config([
        "method=valuedice", "env.task=hopper", "valuedice.exploration_noise=0.1", *TINY,
        f"logger.output_dir={tmp_path}"])
    run = make_trainer(cfg, str(tmp_path / "run"))
    try:
        acting = [m for m in run.collector.policy.modules() if isinstance(m, MeanActionGaussianNoise)]
        assert len(acting) == 1 and acting[0].policy is run.mirror.policy and acting[0].sigma == pytest.approx(0.1)
        assert not any(isinstance(m, MeanActionGaussianNoise) for m in run.mirror.policy.modules())
    finally:
        run.close()
