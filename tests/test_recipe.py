"""recipes/csirl_highway.py end to end on a tiny budget: artefacts, resume, CSIRL-B, bad input."""
from __future__ import annotations

import copy
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

from torchrl_csirl.methods import csirl
from torchrl_csirl.run import assembly, builders, config, run
from torchrl_csirl.trainers import (
    TrainingDivergedError,
    load_checkpoint,
    shutdown_collector,
)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RECIPES = os.path.join(ROOT, "recipes")
RECIPE = os.path.join(RECIPES, "csirl_highway.py")

# a tiny budget: 100-frame batches, rounds of 20 updates, 2 evaluation episodes
TINY = [
    "collector.frames_per_batch=100",
    "collector.cut_episodes=true",  # 50-frame shares of 60-step episodes
    "collector.init_random_frames=100",
    "replay_buffer.warmup_frames=100",
    "replay_buffer.batch_size=64",
    "csirl.updates_per_round=20",
    "optim.utd_ratio=0.5",
    "eval.episodes=2",
    "eval.final_episodes=2",
    "logger.progress_bar=false",
]
VOLATILE = {"collect_fps", "updates_per_s"}  # timings differ between runs


def run_recipe(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    env = {**os.environ, "WANDB_MODE": "offline", "MPLBACKEND": "Agg", "RL_WARNINGS": "0"}
    proc = subprocess.run([sys.executable, RECIPE, *args], capture_output=True, text=True, env=env, timeout=400)
    if check and proc.returncode != 0:
        raise AssertionError(f"recipe failed ({proc.returncode}):\n{proc.stderr[-3000:]}")
    return proc


def last_json(proc: subprocess.CompletedProcess) -> dict:
    return json.loads(proc.stdout.strip().splitlines()[-1])


def read_rows(run_dir: str) -> list[dict]:
    with open(os.path.join(run_dir, "metrics.jsonl")) as f:
        return [json.loads(line) for line in f if line.strip()]


@pytest.fixture(scope="module")
def full_run(tmp_path_factory):
    """600 frames in one go, W&B offline (the default backend)."""
    out = tmp_path_factory.mktemp("runs")
    proc = run_recipe(*TINY, "collector.total_frames=600", f"logger.output_dir={out}", "logger.exp_name=full")
    return last_json(proc)


def test_recipe_artefacts(full_run):
    run_dir = full_run["run_dir"]
    for key in ("accomplish_rate", "success_rate", "frames", "updates", "wall_s", "run_dir"):
        assert key in full_run
    assert 0.0 <= full_run["accomplish_rate"] <= 1.0
    assert full_run["frames"] == 600 and full_run["updates"] == 300  # utd 0.5
    assert full_run["frames_per_s"] > 0 and full_run["updates_per_s"] > 0
    rows = read_rows(run_dir)
    evals = [r["eval_accomplish_rate"] for r in rows if "eval_accomplish_rate" in r]
    assert len(evals) == full_run["rounds"] > 0
    assert all(0.0 <= v <= 1.0 for v in evals)
    assert all(math.isfinite(r["loss_qvalue"]) for r in rows if "loss_qvalue" in r)
    assert any("loss_meta" in r for r in rows)
    with open(os.path.join(run_dir, "metrics.csv")) as f:
        header = f.readline().strip().split(",")
    assert {"frames", "loss_qvalue", "eval_accomplish_rate", "subgoal"} <= set(header)
    for name in ("learning_curve.png", "subgoals.png", "curriculum.png"):
        with open(os.path.join(run_dir, name), "rb") as f:
            assert f.read(8) == b"\x89PNG\r\n\x1a\n"
    assert os.path.isfile(os.path.join(run_dir, "checkpoints", "last", "state.pt"))
    assert os.path.isdir(os.path.join(run_dir, "wandb"))  # offline W&B run
    with open(os.path.join(run_dir, "summary.json")) as f:
        summary = json.load(f)
    assert summary["accomplish_rate"] == full_run["accomplish_rate"]
    assert summary["precision"] == csirl.learner_precision(csirl.load_config([])).name  # what auto resolved to


def test_final_evaluation_is_filmed_and_logged_to_wandb(full_run):
    import glob

    run_dir = full_run["run_dir"]
    assert full_run["videos"] == [os.path.join(run_dir, "videos", os.path.basename(full_run["videos"][0]))]
    assert os.path.basename(full_run["videos"][0]) in ("test-episode-0.mp4", "test-episode-0.gif")
    assert os.path.getsize(full_run["videos"][0]) > 0
    assert glob.glob(os.path.join(run_dir, "wandb", "*", "files", "media", "videos", "test_episode_*"))


def test_watch_films_the_final_evaluation_episodes(full_run, tmp_path):
    from PIL import Image

    proc = subprocess.run([sys.executable, os.path.join(RECIPES, "watch.py"), full_run["run_dir"], "--episodes", "2",
                           "--format", "gif", "--out", str(tmp_path)], capture_output=True, text=True, timeout=300,
                          env={**os.environ, "MPLBACKEND": "Agg"})
    assert proc.returncode == 0, proc.stderr[-2000:]
    lines = proc.stdout.strip().splitlines()
    assert [line.split()[0] for line in lines] == [str(tmp_path / f"test-episode-{i}.gif") for i in range(2)]
    # the same episodes as the final evaluation: their mean accomplish rate is the reported one
    rates = [float(line.split("accomplish rate ")[1].split(",")[0]) for line in lines]
    assert abs(sum(rates) / 2 - full_run["accomplish_rate"]) < 1e-3
    steps = int(lines[0].split(": ")[1].split(" steps")[0])
    with Image.open(tmp_path / "test-episode-0.gif") as gif:
        assert gif.n_frames == steps + 1  # the reset and every step (driving: at most 25 steps a second)


def test_saved_policy_rolls_out_in_two_lines(full_run):
    from torchrl_csirl.modules import load_policy
    from torchrl_csirl.tasks import make_env

    policy = load_policy(full_run["run_dir"])
    rollout = make_env(policy.metadata["scenario"], seed=0).rollout(10, policy)
    assert rollout["action"].shape[-1] == 2 and policy.metadata["frames"] == 600


def test_resume_gives_the_uninterrupted_metrics(full_run, tmp_path):
    out = str(tmp_path)
    run_recipe(*TINY, "collector.total_frames=400", f"logger.output_dir={out}", "logger.exp_name=part",
               "logger.backend=csv")
    with open(os.path.join(out, "part", "summary.json")) as f:
        part_summary = json.load(f)
    resumed = last_json(run_recipe(f"checkpoint.resume={out}/part", "collector.total_frames=600"))
    assert resumed["run_dir"] == os.path.join(out, "part")
    # the changed setting is the run's now (the next resume keeps it), the one before stays on record
    assert OmegaConf.load(os.path.join(out, "part", "config.yaml")).collector.total_frames == 600
    with open(os.path.join(out, "part", "resumes.jsonl")) as f:
        assert [json.loads(line) for line in f] == [{"frames": 400, "changed": {"collector.total_frames": [400, 600]}}]
    with open(os.path.join(out, "part", "provenance.json")) as f:  # the resuming process's code beside the start's
        provenance = json.load(f)
    assert [r["frames"] for r in provenance["resumed"]] == [400] and provenance["resumed"][0]["code"] == provenance["code"]
    # the total wall time counts the first process (up to its checkpoint) as well as this one
    assert part_summary["wall_s"] <= resumed["earlier_wall_s"] <= part_summary["total_wall_s"]
    assert resumed["total_wall_s"] > resumed["earlier_wall_s"] and resumed["total_wall_s"] >= resumed["wall_s"]
    assert resumed["accomplish_rate"] == full_run["accomplish_rate"]
    full = {r["frames"]: r for r in read_rows(full_run["run_dir"]) if "loss_qvalue" in r}
    part = {r["frames"]: r for r in read_rows(resumed["run_dir"]) if "loss_qvalue" in r}
    assert sorted(full) == sorted(part) and max(full) == 600
    for frames, row in full.items():
        a = {k: v for k, v in row.items() if k not in VOLATILE}
        b = {k: v for k, v in part[frames].items() if k not in VOLATILE}
        assert a == b, f"metrics differ at {frames} frames"


def _tiny_cfg(tmp_path, *extra):
    return csirl.load_config(TINY + ["collector.num_workers=1", "logger.backend=none",
                                           f"logger.output_dir={tmp_path}", *extra])


def test_a_csirl_run_moves_its_actor_critics_and_reward_network(tmp_path):
    """Every parameter tensor of the actor, of each critic of the ensemble and of ``r_w`` changes in a tiny
    CSIRL run (150 updates, a meta-gradient step every 2nd); the target critics follow by Polyak averaging."""
    cfg = _tiny_cfg(tmp_path, "collector.total_frames=300")
    run = csirl.make_trainer(cfg, str(tmp_path))
    try:
        modules = run.parts.modules
        groups = {
            "actor": dict(modules.actor.named_parameters()),
            "critics": {k: v for k, v in modules.sac.named_parameters() if k.startswith("qvalue_network_params")},
            "target critics": {k: v for k, v in modules.sac.named_buffers() if k.startswith("target_qvalue_network_params")},
            "reward network": dict(modules.reward_network.named_parameters()),
        }
        assert all(groups.values()), {name: len(p) for name, p in groups.items()}
        before = {name: {k: v.detach().clone() for k, v in params.items()} for name, params in groups.items()}
        run.trainer.train()
        assert run.trainer.updates == 150 and any("loss_meta" in r for r in run.logger.rows)
        for name, params in groups.items():
            unchanged = [k for k, v in params.items() if torch.equal(v, before[name][k])]
            assert not unchanged, f"{name}: {unchanged} did not move"
    finally:
        run.close()


def test_csirl_b_switch_trains_without_the_reward_network(tmp_path):
    cfg = _tiny_cfg(tmp_path, "csirl.intrinsic=false", "collector.total_frames=300")
    run = csirl.make_trainer(cfg, str(tmp_path))
    try:
        assert run.parts.modules.meta is None
        reward_before = [p.clone() for p in run.parts.modules.reward_network.parameters()]
        run.trainer.train()
        sample = run.online_buffer.sample()
        assert "intrinsic_reward" not in sample["next"].keys()
        torch.testing.assert_close(sample["next", "reward"], sample["next", "matching_reward"])
        rows = run.logger.rows
        assert run.trainer.updates == 150 and not any("loss_meta" in r for r in rows)
        assert all(torch.equal(a, b) for a, b in zip(reward_before, run.parts.modules.reward_network.parameters()))
    finally:
        run.close()


@pytest.mark.parametrize("override, expected", [((), 2_000_000), (("eval.validation_seed=null",), 1_000_000)])
def test_learning_curve_evaluates_validation_episodes_apart_from_the_test_ones(tmp_path, monkeypatch, override,
                                                                              expected):
    """The periodic evaluation (the curve) plays seeds ``eval.validation_seed + i``; the final test
    evaluation keeps ``eval.seed + i``; ``eval.validation_seed=null`` is the old behaviour."""
    seeds = []

    def fake_evaluate(env, policy, *, episodes, max_steps, seed):
        seeds.append(seed)
        return {"accomplish_rate": 0.0, "success_rate": 0.0, "crash_rate": 0.0, "env_return": 0.0}

    monkeypatch.setattr(assembly, "evaluate_policy", fake_evaluate)
    cfg = _tiny_cfg(tmp_path, "csirl.intrinsic=false", "collector.total_frames=300", *override)
    run = csirl.make_trainer(cfg, str(tmp_path))
    try:
        run.trainer.train()
        run.evaluate(2)
    finally:
        run.close()
    assert seeds[:-1] and set(seeds[:-1]) == {expected} and seeds[-1] == 1_000_000


def test_fixed_subgoal_switch_keeps_the_subgoal_at_the_last_curriculum_state(tmp_path):
    cfg = _tiny_cfg(tmp_path, "csirl.fixed_subgoal=true", "collector.total_frames=300")
    run = csirl.make_trainer(cfg, str(tmp_path))
    try:
        last = run.parts.curriculum.length - 1
        assert run.parts.curriculum.subgoal == last
        run.trainer.train()
        history = run.parts.selection.history
        assert len(history) >= 2 and all(entry["subgoal"] == last for entry in history)
        assert run.parts.matching.subgoal == last
    finally:
        run.close()


def test_matching_scale_defaults_to_the_scenario_and_can_be_overridden(tmp_path):
    from torchrl_csirl.tasks import SCENARIOS

    spec = SCENARIOS["merge"]
    curriculum = torch.zeros(5, spec.obs_dim)
    curriculum[:, spec.position_feature_indices[0]] = torch.linspace(0.0, 0.4, 5)
    default = csirl.make_matching(_tiny_cfg(tmp_path), spec, curriculum, 2)
    scaled = csirl.make_matching(_tiny_cfg(tmp_path, "csirl.matching_scale=10"), spec, curriculum, 2)
    assert default.scale == spec.matching_scale and scaled.scale == 10.0
    with pytest.raises(config.ConfigError, match="matching_scale"):
        _tiny_cfg(tmp_path, "csirl.matching_scale=0")


def test_automatic_temperature_is_trained_and_logged(tmp_path):
    cfg = _tiny_cfg(tmp_path, "csirl.fixed_alpha=false", "collector.total_frames=300")
    run = csirl.make_trainer(cfg, str(tmp_path))
    try:
        log_alpha = run.parts.modules.sac.log_alpha
        assert log_alpha.requires_grad
        assert any(p is log_alpha for g in run.parts.optimizers["optim_sac"].param_groups for p in g["params"])
        before = log_alpha.detach().clone()
        run.trainer.train()
        assert not torch.equal(before, log_alpha.detach())
        rows = [r for r in run.logger.rows if "alpha" in r]
        assert rows and rows[-1]["alpha"] == pytest.approx(log_alpha.exp().item(), rel=0.1)
    finally:
        run.close()


def test_demonstrations_in_the_batch_and_actor_cloning_are_wired_and_logged(tmp_path):
    cfg = _tiny_cfg(tmp_path, "replay_buffer.expert_fraction=0.25", "csirl.actor_bc_coef=0.4",
                    "collector.total_frames=300")
    run = csirl.make_trainer(cfg, str(tmp_path))
    try:
        update = run.trainer.update_step.sac_update
        assert update.actor_bc.coef == 0.4 and update.actor_bc.bc_loss.actor_network is run.parts.modules.actor
        run.trainer.train()
        batch = update.sample(run.trainer)
        assert batch.batch_size == (64,)
        expert_obs = run.demos.transitions()["observation"]
        from_expert = torch.cdist(batch["observation"], expert_obs, compute_mode="donot_use_mm_for_euclid_dist").min(-1).values < 1e-6
        assert from_expert[48:].all() and from_expert.sum() >= 16
        assert ("next", "matching_reward") in batch.keys(True) and ("next", "intrinsic_reward") in batch.keys(True)
        rows = [r for r in run.logger.rows if "loss_actor_bc" in r]
        assert rows and all(r["actor_bc_mse"] > 0 and r["loss_actor_bc"] > 0 for r in rows)
        assert all(r["actor_bc_weight"] > 0 for r in rows)
    finally:
        run.close()


@pytest.mark.parametrize("warmup, scale", [(100, "qvalue"), (1000, "actor_loss")])
def test_the_critics_warm_up_holds_the_actor_its_cloning_and_alpha_then_lets_them_learn(tmp_path, warmup, scale):
    """``csirl.critic_warmup_updates``: the first updates (joint meta steps included) step the critics' loss only;
    the actor's losses are still logged. 150 updates in all: held throughout at 1000, moving after 100 (with the
    cloning term weighted by the critics' values, ``csirl.actor_bc_scale=qvalue``)."""
    cfg = _tiny_cfg(tmp_path, f"csirl.critic_warmup_updates={warmup}", "csirl.actor_bc_coef=0.4",
                    f"csirl.actor_bc_scale={scale}", "collector.total_frames=300")
    run = csirl.make_trainer(cfg, str(tmp_path))
    try:
        modules = run.parts.modules
        critic = run.trainer.update_step.sac_update.actor_bc.critic
        assert critic is (modules.sac if scale == "qvalue" else None)
        actor = [p.detach().clone() for p in modules.actor.parameters()]
        critics = {k: v.detach().clone() for k, v in modules.sac.named_parameters() if k.startswith("qvalue_network")}
        log_alpha = modules.sac.log_alpha.detach().clone()
        run.trainer.train()
        assert run.trainer.updates == 150 and any("loss_meta" in r for r in run.logger.rows)
        params = dict(modules.sac.named_parameters())
        assert all(not torch.equal(v, params[k]) for k, v in critics.items())
        held = warmup >= run.trainer.updates
        assert all(torch.equal(a, b) for a, b in zip(actor, modules.actor.parameters())) == held
        assert torch.equal(log_alpha, modules.sac.log_alpha.detach()) == held
        assert any("loss_actor_bc" in r for r in run.logger.rows) != held  # the cloning term is not computed while held
        assert all(r["actor_bc_weight"] > 0 for r in run.logger.rows if "actor_bc_weight" in r)
        assert all("loss_actor" in r for r in run.logger.rows if "loss_qvalue" in r)
    finally:
        run.close()
    with pytest.raises(config.ConfigError, match="critic_warmup_updates"):
        _tiny_cfg(tmp_path, "csirl.critic_warmup_updates=-1")


def test_nan_stops_training_and_keeps_the_last_checkpoint(tmp_path):
    cfg = _tiny_cfg(tmp_path, "collector.total_frames=400")
    run = csirl.make_trainer(cfg, str(tmp_path))

    def poison(batch):
        if run.trainer.frames >= 200:  # after the first rounds were checkpointed
            batch = batch.clone()
            batch["observation"][:] = float("nan")
        return batch

    run.trainer.register_op("batch_process", poison, "poison")
    try:
        with pytest.raises(TrainingDivergedError, match="non-finite loss at update .*loss_qvalue=nan"):
            run.trainer.train()
    finally:
        run.close()
    saved = torch.load(os.path.join(run.checkpoint.path, "state.pt"), weights_only=False)
    assert saved["counters"]["frames"] == 200
    params = saved["states"]["loss"]
    assert all(torch.isfinite(v).all() for v in params.values() if v.is_floating_point())
    # the kept checkpoint loads into a fresh run
    fresh = csirl.make_trainer(cfg, str(tmp_path / "fresh"))
    try:
        load_checkpoint(fresh.trainer, run.checkpoint.path, fresh.online_buffer)
        assert fresh.trainer.frames == saved["counters"]["frames"]
        assert len(fresh.online_buffer) == saved["counters"]["frames"]
    finally:
        fresh.close()


def test_missing_expert_file_is_a_clear_error(tmp_path):
    proc = run_recipe(f"expert.path={tmp_path}/nope.npz", f"logger.output_dir={tmp_path}", check=False)
    assert proc.returncode == 2
    assert "expert.path: no such file" in proc.stderr and "nope.npz" in proc.stderr
    assert "Traceback" not in proc.stderr


@pytest.mark.parametrize("content", ["garbage", "npz-missing-members", "wrong-size"])
def test_malformed_expert_file_is_a_clear_error(tmp_path, content):
    path = tmp_path / ("demo.npz" if content != "garbage" else "demo.pkl")
    if content == "garbage":
        path.write_bytes(b"not a pickle at all")
    elif content == "npz-missing-members":
        np.savez(path, observation=np.zeros((3, 25), np.float32))
    else:
        from torchrl_csirl.data import ExpertDemonstrations

        ep = {"observation": torch.zeros(4, 7), "action": torch.zeros(4, 2), "next_observation": torch.zeros(4, 7),
              "terminated": torch.zeros(4, dtype=torch.bool)}
        ExpertDemonstrations.from_episodes([ep] * 25).save(path)
    cfg = _tiny_cfg(tmp_path, f"expert.path={path}")
    with pytest.raises(csirl.ExpertDataError, match=str(path.name)):
        builders.load_experts(cfg.expert, csirl.SCENARIOS["merge"])


@pytest.mark.parametrize("curriculum, expected", [("empty", 0), ("traffic", 1)])
def test_published_file_drives_the_run(tmp_path, curriculum, expected):
    """expert.path=<published file> builds the run; expert.curriculum picks the curriculum trajectory."""
    from published_fixtures import write_published_files

    from torchrl_csirl.data import import_published

    path = write_published_files(tmp_path / "published", "merge", sizes=(5,))[5]
    stored = import_published(path)
    cfg = _tiny_cfg(tmp_path, f"expert.path={path}", f"expert.curriculum={curriculum}",
                    "expert.num_trajectories=5")
    run = csirl.make_trainer(cfg, str(tmp_path / "run"))
    try:
        assert run.demos.num_trajectories == 5 and run.demos.metadata["curriculum_trajectory"] == expected
        assert run.demos.lengths.tolist() == [60] * 5
        curriculum_obs = stored.trajectory_observations(expected, include_final=True)
        torch.testing.assert_close(run.parts.curriculum.expert_observations.cpu(), curriculum_obs)
        assert run.parts.curriculum.length == 61 and len(run.parts.expert_buffer) == 5 * 60
    finally:
        run.close()


def test_published_file_without_traffic_is_a_clear_error(tmp_path):
    from published_fixtures import write_published_files

    path = write_published_files(tmp_path, "merge", sizes=(1,))[1]
    cfg = _tiny_cfg(tmp_path, f"expert.path={path}", "expert.curriculum=traffic", "expert.num_trajectories=1")
    with pytest.raises(csirl.ExpertDataError, match="expert.curriculum=traffic: no trajectory of .*merge_1.npy"):
        builders.load_experts(cfg.expert, csirl.SCENARIOS["merge"])


def test_expert_end_at_cuts_a_published_file_where_our_scene_ends(tmp_path):
    """expert.end_at=termination: merge's recording past 370 m is cut where our episode ends."""
    from published_fixtures import write_published_files

    from torchrl_csirl.data import import_published
    from torchrl_csirl.data.published import END_AT

    assert config.PUBLISHED_END_AT == END_AT  # the schema's choices are the importer's
    path = write_published_files(tmp_path / "published", "merge", sizes=(5,))[5]
    spec = csirl.SCENARIOS["merge"]
    cfg = _tiny_cfg(tmp_path, f"expert.path={path}", "expert.end_at=termination", "expert.num_trajectories=5")
    demos = builders.load_experts(cfg.expert, spec)
    expected = import_published(path, end_at="termination", scenario="merge")
    assert demos.lengths.tolist() == expected.lengths.tolist()
    assert max(demos.lengths.tolist()) < 60 and demos.metadata["end_at"] == "termination"
    npz = tmp_path / "demos.npz"
    expected.save(npz)
    with pytest.raises(csirl.ExpertDataError, match="expert.end_at=termination applies to published files"):
        builders.load_experts(_tiny_cfg(tmp_path, f"expert.path={npz}", "expert.end_at=termination").expert, spec)


@pytest.mark.parametrize(
    "override, message",
    [
        (["env.task=mars"], "env.task=mars: unknown task; one of .*highway-fast, hopper, intersection, merge"),
        (["collector.total_frames=abc"], "collector.total_frames=abc: must be an integer > 0 or null"),
        (["collector.total_frames=1.5"], "collector.total_frames=1.5: must be an integer > 0 or null"),
        (["csirl.intrinsic=maybe"], "csirl.intrinsic=maybe: must be true or false"),
        (["optim.lr=-1"], "optim.lr=-1.0: must be a number > 0.0"),
        (["replay_buffer.expert_fraction=1"], "replay_buffer.expert_fraction=1.0: must be a number >= 0.0 and < 1.0"),
        (["collector.frames_per_batch=101"], r"collector.frames_per_batch=101: must be a multiple of collector.num_workers \(2\)"),
        (["no.such.key=1"], "no.such.key: unknown configuration key"),
        (["csirl.metta_every=1"], "csirl.metta_every: unknown configuration key; did you mean csirl.meta_every"),
        (["seed"], "seed: not of the form key=value"),
        (["preset=fastest"], "preset=fastest: must be one of default, paper"),
        (["collector.main_threads=0"], "collector.main_threads=0: must be an integer > 0 or null"),
        (["collector.envs_per_worker=0"], "collector.envs_per_worker=0: must be an integer > 0 or null"),
        (["csirl.matching_features=speed"], "csirl.matching_features=speed: must be one of ego, position"),
        (["collector.envs_per_worker=3"], "multiple of collector.num_workers x collector.envs_per_worker"),
        (["device=tpu"], "device=tpu: must be one of cpu, cuda, auto"),
        (["expert.end_at=crash"], "expert.end_at=crash: must be one of recording, first_done, termination"),
    ],
)
def test_config_errors_name_the_problem(override, message):
    with pytest.raises(csirl.ConfigError, match=message):
        csirl.load_config(override)


def test_paper_preset_is_the_published_procedure():
    cfg = csirl.load_config(["preset=paper"])
    assert cfg.csirl.updates_per_round == 20000 and cfg.csirl.meta_every == 1
    assert cfg.replay_buffer.clear_each_round and cfg.optim.utd_ratio == 1.0
    spec = csirl.SCENARIOS["merge"]
    assert csirl.matching_feature_indices(cfg, spec) == spec.ego_feature_indices  # published search
    position = csirl.load_config(["csirl.matching_features=position"])
    assert csirl.matching_feature_indices(position, spec) == spec.position_feature_indices
    assert csirl.total_frames(cfg, curriculum_length=50) == 50 * (20000 + 1280)
    assert csirl.load_config(["preset=paper", "csirl.meta_every=4"]).csirl.meta_every == 4


@pytest.mark.parametrize("enabled", [False, True])
def test_ego_relative_features_switch_reaches_every_network(enabled):
    from torchrl_csirl.modules import EgoRelativeFeatures

    cfg = csirl.load_config([f"model.ego_relative_features={str(enabled).lower()}"])
    assert csirl.load_config(["preset=paper"]).model.ego_relative_features is False
    spec = csirl.SCENARIOS[cfg.env.task]
    modules = csirl.make_loss_modules(cfg, spec)
    for net in (modules.actor, modules.sac.qvalue_network, modules.reward_network):
        found = [m for m in net.modules() if isinstance(m, EgoRelativeFeatures)]
        assert len(found) == (1 if enabled else 0)


def test_reward_reference_switch_wraps_the_reward_network_around_expert_states():
    from torchrl_csirl.modules import ExpertCenteredReward

    cfg = csirl.load_config(["csirl.reward_reference=expert", "csirl.reward_scale=0.5"])
    spec = csirl.SCENARIOS[cfg.env.task]
    demos = builders.load_experts(cfg.expert, spec)
    reward = csirl.make_loss_modules(cfg, spec, demos=demos).reward_network
    assert isinstance(reward, ExpertCenteredReward) and reward.scale == 0.5
    assert reward.reference_observations.shape == (256, spec.obs_dim)
    assert not isinstance(csirl.make_loss_modules(csirl.load_config([]), spec).reward_network,
                          ExpertCenteredReward)
    with pytest.raises(ValueError, match="needs the demonstrations"):
        csirl.make_loss_modules(cfg, spec)


def test_meta_gradient_switch_reaches_the_meta_loss():
    spec = csirl.SCENARIOS["merge"]
    assert csirl.make_loss_modules(csirl.load_config([]), spec).meta.meta_gradient == "double_backward"
    cfg = csirl.load_config(["csirl.meta_gradient=jvp"])
    assert csirl.make_loss_modules(cfg, spec).meta.meta_gradient == "jvp"
    with pytest.raises(config.ConfigError, match="meta_gradient"):
        csirl.load_config(["csirl.meta_gradient=forward"])


@pytest.mark.parametrize(
    "scenario, overrides, expected",
    [
        ("merge", [], 2),  # 500 frames, 2 workers: 125 steps per env >= 60
        ("highway-fast", [], 1),  # 150-step episodes: 2 envs per worker would cut them at 125
        ("merge", ["collector.frames_per_batch=480"], 4),
        ("intersection", ["collector.frames_per_batch=480"], 3),  # 80 steps >= 65; 4 would give 60
        ("merge", ["collector.frames_per_batch=100"], 1),
        ("merge", ["collector.envs_per_worker=5"], 5),  # explicit: taken as given
    ],
)
def test_envs_per_worker_keeps_whole_episodes_per_batch(scenario, overrides, expected):
    cfg = csirl.load_config([f"env.task={scenario}", *overrides])
    assert builders.envs_per_worker(cfg.collector, csirl.SCENARIOS[scenario]) == expected


def test_collection_with_several_envs_per_worker_is_reproducible():
    """2 workers x 2 envs: a seeded batch is the same twice (what exact resume relies on)."""
    cfg = csirl.load_config(["collector.frames_per_batch=100", "collector.init_random_frames=0",
                             "collector.envs_per_worker=2", "collector.cut_episodes=true"])
    torch.manual_seed(0)
    actor = csirl.make_loss_modules(cfg, csirl.SCENARIOS["merge"]).actor
    batches = []
    collector = builders.make_collector("merge", cfg.collector, actor)
    try:
        iterator = iter(collector)
        for main_seed in range(2):  # the workers draw the actions: only set_seed matters
            collector.set_seed(11)
            collector.reset()
            torch.manual_seed(main_seed)
            batches.append(next(iterator))
    finally:
        shutdown_collector(collector)
    assert batches[0].batch_size == torch.Size([2, 2, 25])
    torch.testing.assert_close(batches[0]["next", "observation"], batches[1]["next", "observation"])
    # the four environments are seeded differently
    firsts = batches[0]["observation"][..., 0, :].reshape(4, -1)
    assert len({tuple(row.tolist()) for row in firsts}) == 4


def test_worker_processes_act_with_the_weights_the_main_process_trains():
    """The policy copies in the 2 worker processes follow in-place updates of the loss's actor
    parameters (what the optimiser does) and a ``load_state_dict`` (what a resume does), with no
    explicit weight sync."""
    cfg = csirl.load_config(["collector.frames_per_batch=40", "collector.init_random_frames=0",
                             "collector.envs_per_worker=2", "collector.cut_episodes=true"])
    torch.manual_seed(0)
    modules = csirl.make_loss_modules(cfg, csirl.SCENARIOS["merge"])
    collector = builders.make_collector("merge", cfg.collector, modules.actor)

    try:
        iterator = iter(collector)
        batch = next(iterator)
        with torch.no_grad():
            torch.testing.assert_close(batch["loc"], modules.actor(batch.select("observation").clone())["loc"])
        old_actor = copy.deepcopy(modules.actor)
        old_state = copy.deepcopy(modules.sac.state_dict())
        with torch.no_grad():  # an optimiser step on the loss's copy of the actor parameters
            for param in modules.sac.actor_network_params.values(True, True):
                param.add_(0.05 * torch.randn_like(param))
        batch = next(iterator)
        with torch.no_grad():
            new_loc = modules.actor(batch.select("observation").clone())["loc"]
            old_loc = old_actor(batch.select("observation").clone())["loc"]
        torch.testing.assert_close(batch["loc"], new_loc)
        assert not torch.allclose(batch["loc"], old_loc)
        modules.sac.load_state_dict(old_state)  # as a resume does: the workers follow too
        batch = next(iterator)
        with torch.no_grad():
            torch.testing.assert_close(batch["loc"], old_actor(batch.select("observation").clone())["loc"])
    finally:
        shutdown_collector(collector)


def test_summarize_runs_groups_seeds_by_configuration_variant(tmp_path, capsys):
    from torchrl_csirl.scripts import summarize

    for name, overrides, rate in [("a", [], 0.5), ("b", [], 0.7),
                                  ("c", ["model.ego_relative_features=false", "collector.main_threads=1"], 0.9)]:
        run_dir = tmp_path / name
        run_dir.mkdir()
        cfg = csirl.load_config([f"seed={ord(name)}", f"logger.output_dir={tmp_path}", *overrides])
        OmegaConf.save(cfg, run_dir / "config.yaml")
        (run_dir / "summary.json").write_text(json.dumps(
            {"scenario": "merge", "method": "csirl", "preset": "default", "seed": ord(name), "accomplish_rate": rate,
             "final_subgoal": ord(name) - 90, "curriculum_length": 45}))
    assert summarize.variant(str(tmp_path / "c"), "default") == "model.ego_relative_features=false"
    stats = summarize.main([str(tmp_path)])
    assert set(stats) == {"merge/csirl/default", "merge/csirl/default model.ego_relative_features=false"}
    assert stats["merge/csirl/default"]["accomplish_rate"]["mean"] == pytest.approx(0.6)
    assert stats["merge/csirl/default"]["seeds"] == [ord("a"), ord("b")]
    assert stats["merge/csirl/default"]["final_subgoal"] == "7, 8 of 45"  # by seed
    assert "| merge/csirl/default model.ego_relative_features=false | 99 |" in capsys.readouterr().err


def test_summarize_runs_variant_is_against_the_scenes_own_defaults(tmp_path):
    """A run of a scene's defaults is no variant; a run older than an option had the recipe's default."""
    from torchrl_csirl.scripts import summarize

    def save(name: str, cfg) -> str:
        (tmp_path / name).mkdir()
        OmegaConf.save(cfg, tmp_path / name / "config.yaml")
        return str(tmp_path / name)

    scene = csirl.load_config(["env.task=intersection"])  # model.lane_features=true there
    assert scene.model.lane_features
    assert summarize.variant(save("scene", scene), "default") == ""
    off = csirl.load_config(["env.task=intersection", "model.lane_features=false"])
    assert summarize.variant(save("off", off), "default") == "model.lane_features=false"
    old = OmegaConf.to_container(scene)
    del old["model"]["lane_features"]  # recorded before the option existed: it ran without
    assert summarize.variant(save("old", OmegaConf.create(old)), "default") == "model.lane_features=false"

def test_meta_gradient_balance_reports_both_parts(capsys):
    """docs/studies/scripts/meta_gradient_balance.py: with the published L1 weight the regulariser's part dominates."""
    import meta_gradient_balance

    out = meta_gradient_balance.main(["--frames", "60", "--steps", "2", "replay_buffer.batch_size=32"])
    assert json.loads(capsys.readouterr().out.strip().splitlines()[-1]) == out
    assert out["meta_grad_norm_imitation"] > 0 and out["meta_grad_norm_l1"] > 0
    assert out["l1_to_imitation_ratio"] > 100  # published constants: the L1 term swamps imitation
    assert 0.0 <= out["r_w_auc"] <= 1.0 and {"r_w_expert_mean", "r_w_policy_mean", "r_w_std"} <= set(out)
    assert out["r_w_std"] > 0  # an untrained network rates states differently
    off = meta_gradient_balance.main(["--frames", "60", "--steps", "2", "replay_buffer.batch_size=32",
                                      "csirl.reward_l1_coef=0"])
    assert off["meta_grad_norm_l1"] == 0 and off["meta_grad_norm_imitation"] > 0


def test_meta_gradient_balance_of_a_trained_run(full_run):
    """``checkpoint.resume=<run>`` reads the run's configuration and networks."""
    import meta_gradient_balance

    out = meta_gradient_balance.main(["--frames", "60", "--steps", "1", f"checkpoint.resume={full_run['run_dir']}"])
    assert out["checkpoint"] == full_run["run_dir"] and out["scenario"] == full_run["scenario"]
    assert out["meta_grad_norm_l1"] > 0


def test_policy_outcomes_reports_outcomes_and_speeds_and_splits_merge_by_the_traffic_ahead(tmp_path, capsys):
    from torchrl_csirl.modules import make_actor, save_policy
    from torchrl_csirl.scripts import driving_outcomes
    from torchrl_csirl.tasks import SCENARIOS, make_env

    def saved(scenario):
        spec = SCENARIOS[scenario]
        return str(save_policy(make_actor(spec.obs_dim, spec.action_dim), tmp_path / f"{scenario}.pt",
                               obs_dim=spec.obs_dim, action_dim=spec.action_dim, scenario=scenario, frames=0))

    stats = driving_outcomes.main([saved("merge"), "--episodes", "4"])
    assert json.loads(capsys.readouterr().out.strip().splitlines()[-1])["all"] == stats["all"]
    assert sum(stats[g]["episodes"] for g in ("free", "blocked") if g in stats) == stats["all"]["episodes"] == 4
    for group in stats.values():
        assert sum(group[o] for o in driving_outcomes.OUTCOMES) == group["episodes"]
    assert 0.0 <= stats["all"]["accomplish_rate"] <= 1.0
    assert stats["all"]["offroad_accomplish_rate"] is None or 0.0 <= stats["all"]["offroad_accomplish_rate"] <= 1.0
    # merge starts the ego at 30 m/s: the speeds read back from the observation are in that range
    assert 15.0 < stats["all"]["mean_speed"] <= stats["all"]["max_speed"] < 60.0
    roundabout = driving_outcomes.main([saved("roundabout"), "--episodes", "2"])
    assert set(roundabout) == {"all"} and roundabout["all"]["episodes"] == 2
    assert sum(roundabout["all"]["offroad_lanes"].values()) == roundabout["all"]["offroad"]
    # the ego's place on the road: its lane and the offset from that lane's centre line
    env = make_env("roundabout", seed=0)
    try:
        env.reset()
        at = driving_outcomes.road_position(env)
    finally:
        env.close()
    assert at["lane"].count("/") == 2 and abs(at["lateral"]) <= at["half_width"] == 2.0
    other = save_policy(make_actor(35, 2), tmp_path / "other.pt", obs_dim=35, action_dim=2, scenario="relocate", frames=0)
    with pytest.raises(SystemExit):
        driving_outcomes.main([str(other)])


def test_a_wrong_type_on_the_command_line_is_one_line_and_exit_2(tmp_path):
    proc = run_recipe("collector.total_frames=abc", f"logger.output_dir={tmp_path}", check=False)
    assert proc.returncode == 2
    assert proc.stderr.strip() == "error: collector.total_frames=abc: must be an integer > 0 or null"
    assert not os.listdir(tmp_path)  # refused before a run directory (or a worker) existed


def test_a_run_is_never_overwritten_unless_asked(full_run, tmp_path):
    out, name = os.path.split(full_run["run_dir"])
    before = os.path.getmtime(os.path.join(full_run["run_dir"], "summary.json"))
    proc = run_recipe(*TINY, f"logger.output_dir={out}", f"logger.exp_name={name}", check=False)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert f"logger.exp_name={name}: {full_run['run_dir']} already holds a run" in proc.stderr
    assert f"checkpoint.resume={full_run['run_dir']}" in proc.stderr and "logger.overwrite=true" in proc.stderr
    assert os.path.getmtime(os.path.join(full_run["run_dir"], "summary.json")) == before
    # asked for explicitly: the old directory is replaced as a whole
    (tmp_path / "old").mkdir()
    (tmp_path / "old" / "config.yaml").write_text("seed: 0\n")
    (tmp_path / "old" / "stale.txt").write_text("from the old run")
    assert run.make_run_dir(str(tmp_path), "old", "", overwrite=True) == str(tmp_path / "old")
    assert not os.listdir(tmp_path / "old")


def test_unnamed_runs_get_a_fresh_directory(tmp_path):
    first = run.make_run_dir(str(tmp_path), None, "merge-csirl-s0-x")
    open(os.path.join(first, "metrics.jsonl"), "w").close()
    second = run.make_run_dir(str(tmp_path), None, "merge-csirl-s0-x")
    assert second == first + "-2" and os.path.isdir(second)


def test_resume_merges_schema_saved_config_and_command_line(tmp_path):

    cfg = csirl.load_config(["preset=paper", "seed=4", "csirl.meta_every=3"])
    saved = OmegaConf.to_container(cfg)
    del saved["logger"]["overwrite"]  # a key added after the run was made takes the schema default
    saved["checkpoint"]["resume"] = "/somewhere/else"
    OmegaConf.save(OmegaConf.create(saved), tmp_path / "config.yaml")
    resumed = csirl.load_run_config(str(tmp_path), ["collector.total_frames=9000"])
    assert resumed.seed == 4 and resumed.csirl.meta_every == 3 and resumed.csirl.updates_per_round == 20000
    assert resumed.collector.total_frames == 9000 and resumed.logger.overwrite is False
    assert resumed.checkpoint.resume is None and resumed.preset == "paper"
    assert resumed.csirl.goal_conditioned is None  # saved with the key: its value
    with pytest.raises(config.ConfigError, match="a resumed run keeps its preset"):
        csirl.load_run_config(str(tmp_path), ["preset=default"])
    with pytest.raises(config.ConfigError, match="csirl.meta_every=0: must be an integer > 0"):
        csirl.load_run_config(str(tmp_path), ["csirl.meta_every=0"])
    saved["csirl"]["meta_every"] = "often"  # a hand-edited config.yaml is checked too, and named
    OmegaConf.save(OmegaConf.create(saved), tmp_path / "config.yaml")
    with pytest.raises(config.ConfigError, match=r"csirl.meta_every=often: must be an integer > 0 \(in .*config.yaml\)"):
        csirl.load_run_config(str(tmp_path))


def test_a_resumed_run_keeps_the_behaviour_of_a_setting_it_predates(tmp_path):
    """A run made before ``csirl.goal_conditioned`` existed matched one demonstration: resumed or diagnosed, it still
    does (the key's later default, null, would switch goal-conditioned matching on)."""
    saved = OmegaConf.to_container(csirl.load_config(["env.gym_id=PointMaze_UMaze-v3"]))
    del saved["csirl"]["goal_conditioned"]
    OmegaConf.save(OmegaConf.create(saved), tmp_path / "config.yaml")
    assert csirl.load_run_config(str(tmp_path)).csirl.goal_conditioned is False
    assert csirl.load_run_config(str(tmp_path), ["csirl.goal_conditioned=true"]).csirl.goal_conditioned is True


def test_device_is_read_and_a_missing_gpu_is_a_config_error():
    assert run.resolve_device("cpu").type == "cpu"
    assert run.resolve_device("auto").type == ("cuda" if torch.cuda.is_available() else "cpu")
    if not torch.cuda.is_available():
        with pytest.raises(config.ConfigError, match="device=cuda: CUDA is not available"):
            csirl.load_config(["device=cuda"])


def test_policy_mirror_copies_the_learner_weights_in_place():
    """With the learner on another device the workers act through a CPU copy that follows it."""
    from torchrl_csirl.modules import make_actor

    learner = make_actor(4, 2, hidden=(8,))
    mirror = builders.PolicyMirror(learner, torch.device("meta"))  # any non-CPU device: a separate copy
    assert mirror.mirrored and mirror.policy is not learner
    storages = [p.data_ptr() for p in mirror.policy.parameters()]
    with torch.no_grad():
        for p in learner.parameters():
            p.add_(1.0)
    mirror.sync()
    for a, b in zip(learner.parameters(), mirror.policy.parameters()):
        torch.testing.assert_close(a, b)
    assert [p.data_ptr() for p in mirror.policy.parameters()] == storages  # in place: shared memory follows


def test_help_lists_every_key_with_what_it_accepts():
    proc = run_recipe("--help")
    assert "csirl.meta_every = 2  # an integer > 0;" in proc.stdout
    assert "device = cpu  # one of cpu, cuda, auto" in proc.stdout
    assert len([line for line in proc.stdout.splitlines() if " = " in line]) == len(config.flatten_config(
        csirl.load_config([]))) - 1  # less the env.scenario mirror


def test_method_registry_reads_each_method_with_its_recipe_schema():
    from torchrl_csirl.run import known_methods, load_config_for

    assert {"csirl", "csirl-b"} <= set(known_methods())
    cfg = load_config_for("csirl-b")(["preset=paper"])
    assert cfg.csirl.updates_per_round == 20000 and cfg.csirl.intrinsic is False
    assert load_config_for("csirl")(["env.task=hopper"]).env.task == "hopper"


def test_main_threads_hold_from_the_runs_first_step(tmp_path):
    """``collector.main_threads`` reaches the work before the collector starts (an actor's warm start): two runs
    sharing two cores with one thread each, but a warm start on torch's default threads, spin in OpenMP."""
    from torchrl_csirl.run import lifecycle

    cfg = csirl.load_config(["collector.main_threads=1", f"logger.output_dir={tmp_path}", "logger.exp_name=threads"])
    seen = []

    def build(cfg, run_dir, **_):
        seen.append(torch.get_num_threads())
        raise RuntimeError("built")

    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        with pytest.raises(RuntimeError, match="built"):
            lifecycle.open_configured_run(cfg, lambda c: "csirl", build)
    finally:
        torch.set_num_threads(before)
    assert seen == [1] and not os.path.exists(os.path.join(tmp_path, "threads"))
