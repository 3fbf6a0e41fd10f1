"""A task the project does not ship, trained as the built-in ones are: through the registry
(``env.module=`` + ``register_task``) and through ``env.gym_id=`` with no code; the one-line errors
of bad demonstrations, features and collector budgets."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
import torch

from torchrl_csirl.data import record_demonstrations
from torchrl_csirl.methods.csirl import CSIRL_RECIPE
from torchrl_csirl.run import ConfigError, ExpertDataError
from torchrl_csirl.run.task_schemas import prepare_task
from torchrl_csirl.scripts import csirl_highway, csirl_robotics, imitation_robotics
from torchrl_csirl.tasks import make_gymnasium_task, register_task, resolve_scenario

MOUNTAIN_CAR = "MountainCarContinuous-v0"
TINY = [
    "collector.total_frames=400", "collector.frames_per_batch=200", "collector.cut_episodes=true",
    "collector.num_workers=1", "collector.init_random_frames=200", "collector.main_threads=1",
    "replay_buffer.warmup_frames=200", "optim.utd_ratio=0.1",
    "eval.episodes=1", "eval.final_episodes=2", "eval.video=false", "logger.backend=csv", "logger.progress_bar=false",
    "expert.num_trajectories=3",
]


def pump(td):
    """MountainCar's scripted expert: push the way the car moves (it swings up to the flag)."""
    td["action"] = torch.where(td["observation"][..., 1:] >= 0, 1.0, -1.0)
    return td


@pytest.fixture(scope="module")
def car_demos(tmp_path_factory) -> str:
    make_gymnasium_task(MOUNTAIN_CAR, features="0")
    demos = record_demonstrations(MOUNTAIN_CAR, pump, episodes=3, seed=100, only_successful=True)
    path = str(tmp_path_factory.mktemp("demos") / "car.npz")
    demos.save(path)
    return path


def test_a_gymnasium_id_trains_csirl_with_no_code(tmp_path, car_demos):
    """The README's CSIRL script takes any task: its family picks the schema."""
    summary = csirl_highway.main([f"env.gym_id={MOUNTAIN_CAR}", "env.features=0", f"expert.path={car_demos}",
                                   "csirl.updates_per_round=10", "csirl.num_qvalue_nets=2", "replay_buffer.batch_size=32",
                                   "csirl.matching_target=path", *TINY, f"logger.output_dir={tmp_path}"])
    assert summary["scenario"] == MOUNTAIN_CAR and summary["frames"] == 400
    assert summary["accomplish_rate"] == summary["success_rate"]  # no finish: the success rate
    assert isinstance(summary["return"], float)
    run_dir = summary["run_dir"]
    with open(os.path.join(run_dir, "summary.json")) as f:
        assert json.load(f)["scenario"] == MOUNTAIN_CAR
    # the task is part of the saved configuration: a resume re-registers it and continues
    resumed = csirl_highway.main([f"checkpoint.resume={run_dir}", "collector.total_frames=600"])
    assert resumed["frames"] == 600 and resumed["run_dir"] == run_dir


def test_a_registered_task_trains_a_baseline_by_name(tmp_path):
    """env.module imports the user's module (its register_task call); collection runs in a worker
    process, which receives the task's factory, not its name."""
    import own_task_module

    def swing(td):
        td["action"] = torch.clamp(-2.0 * td["observation"][..., 2:], -1.0, 1.0)
        return td

    path = str(tmp_path / "pendulum.npz")
    record_demonstrations(own_task_module.NAME, swing, episodes=3).save(path)
    summary = imitation_robotics.main(["method=bc", "env.module=own_task_module", f"env.task={own_task_module.NAME}",
                                       f"expert.path={path}", *TINY, f"logger.output_dir={tmp_path}"])
    assert summary["scenario"] == own_task_module.NAME and summary["success_rate"] == 0.0
    assert summary["frames"] == 400 and summary["updates"] > 0


def test_register_task_refuses_the_builtin_names_and_twice_the_same():
    spec = resolve_scenario("merge")
    with pytest.raises(ValueError, match="'merge' is a built-in task"):
        register_task(spec, lambda: None)
    import own_task_module

    with pytest.raises(ValueError, match="already registered"):
        register_task(own_task_module.SPEC, own_task_module.make_own_pendulum)


def test_every_task_is_built_by_its_factory_with_the_device_and_info_keys_it_takes():
    """One env-building path (issue 89): every task, built-in or registered, has a factory; ``device``
    and ``info_keys`` reach a factory that names them, never one whose ``**kwargs`` would swallow them."""
    from functools import partial

    from torchrl.envs import GymEnv

    from torchrl_csirl.tasks import TASKS
    from torchrl_csirl.tasks.registry import build_env, registered_factory

    assert all(registered_factory(name) is not None for name in TASKS)
    seen: dict = {}

    def factory(device="cpu", info_keys=(), **overrides):
        seen.update(device=device, info_keys=info_keys, **overrides)
        return GymEnv("Pendulum-v1", device=device)

    env = build_env(factory, seed=0, device="cpu", info_keys=("success",), g=9.81)
    assert seen == {"device": "cpu", "info_keys": ("success",), "g": 9.81} and env.device == torch.device("cpu")
    env = build_env(partial(GymEnv, "Pendulum-v1"), seed=0, info_keys=("success",))  # takes neither: not passed
    assert env.rollout(2)["observation"].shape == (2, 3)
    import own_task_module

    from torchrl_csirl.tasks import make_env

    assert make_env(own_task_module.NAME, seed=0, device="cpu").device == torch.device("cpu")


def test_a_registered_task_names_its_expert():
    import own_task_module

    from torchrl_csirl.tasks import TASKS, TaskSpec
    from torchrl_csirl.tasks import registry as task_registry
    from torchrl_csirl.tasks.driving.expert import expert_tasks, make_expert

    spec = TaskSpec(name="own-relocate-expert", obs_dim=3, action_dim=1, max_steps=200, finish_position=None,
                    ego_feature_indices=(0,), position_feature_indices=(0,), matching_scale=1.0,
                    expert="torchrl_csirl.tasks.robotics.expert:make_relocate_expert")
    register_task(spec, own_task_module.make_own_pendulum)
    try:
        assert expert_tasks()[-1] == spec.name and type(make_expert(spec.name)).__name__ == "DAPGRelocateExpert"
        with pytest.raises(ValueError, match="takes no options, got \\['horizon'\\]"):
            make_expert(spec.name, horizon=3)
    finally:
        TASKS.pop(spec.name, None)
        task_registry._FACTORIES.pop(spec.name, None)
    with pytest.raises(ValueError, match="No expert for the task 'own-pendulum'"):
        make_expert(own_task_module.NAME)


@pytest.mark.parametrize("overrides, message", [
    ([f"env.gym_id={MOUNTAIN_CAR}", "env.features=2"],
     "env.features=2: index 2 is outside the observation (size 2: indices 0-1)"),
    ([f"env.gym_id={MOUNTAIN_CAR}", "env.features=speed"], "env.features=speed: 'speed' is neither"),
    (["env.gym_id=CartPole-v1"], "env.gym_id=CartPole-v1: its action space is Discrete(2)"),
    (["env.gym_id=MountainCar-v9"], "env.gym_id=MountainCar-v9: not a registered gymnasium id"),
    (["env.module=no_such_module_here"], "env.module=no_such_module_here: cannot import it"),
    ([f"env.gym_id={MOUNTAIN_CAR}", "env.task=relocate"], "env.task=relocate and env.gym_id="),
])
def test_bad_task_settings_are_one_line(overrides, message):
    with pytest.raises(ConfigError) as err:
        CSIRL_RECIPE.load_config(overrides)
    assert message in str(err.value) and "\n" not in str(err.value)


def test_demonstrations_must_exist_and_fit_the_task(tmp_path, car_demos):
    cfg = CSIRL_RECIPE.load_config([f"env.gym_id={MOUNTAIN_CAR}", *TINY, f"logger.output_dir={tmp_path}"])
    with pytest.raises(ExpertDataError, match="expert.path: required for 'MountainCarContinuous-v0'"):
        csirl_robotics.main([f"env.gym_id={MOUNTAIN_CAR}", *TINY, f"logger.output_dir={tmp_path}"])
    with pytest.raises(ExpertDataError, match="observations of size 2 and actions of size 1, but 'relocate' has 39 and 30"):
        csirl_robotics.main(["env.task=relocate", f"expert.path={car_demos}", *TINY, f"logger.output_dir={tmp_path}"])
    assert cfg.env.task == MOUNTAIN_CAR and not os.listdir(tmp_path)  # no run directory left behind


def test_a_batch_that_would_cut_episodes_is_refused(tmp_path):
    with pytest.raises(ConfigError, match=r"each of the 2 environments steps 50 frames per batch, fewer than merge's "
                                          r"episode limit \(60\)"):
        csirl_highway.main(["collector.frames_per_batch=100", "collector.total_frames=200", f"logger.output_dir={tmp_path}"])


def test_prepare_task_keeps_the_saved_task_on_resume(tmp_path):
    (tmp_path / "config.yaml").write_text(f"env:\n  gym_id: {MOUNTAIN_CAR}\n  features: '0'\n  success: termination\n")
    assert prepare_task(["collector.total_frames=10"], str(tmp_path)) == ["collector.total_frames=10"]
    assert resolve_scenario(MOUNTAIN_CAR).position_feature_indices == (0,)


def test_the_own_task_page_runs_as_written(tmp_path, monkeypatch):
    """docs/own-task.md's Python blocks, in order, on a tiny budget (its ``budget`` line replaced)."""
    from markdown_examples import python_blocks

    from torchrl_csirl.tasks import TASKS
    from torchrl_csirl.tasks import registry as task_registry

    blocks = python_blocks("docs/own-task.md")
    assert len(blocks) == 2 and 'budget = ["collector.total_frames=25000"' in blocks[1]
    tiny = [t for t in TINY if not t.startswith("expert.")] + [f"logger.output_dir={tmp_path / 'runs'}"]
    blocks[1] = "\n".join(f"budget = {tiny!r}" if line.startswith("budget = ") else line
                          for line in blocks[1].splitlines())
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    try:
        for block in blocks:
            exec(compile(block, "docs/own-task.md", "exec"), namespace)  # noqa: S102 - our own docs
    finally:
        TASKS.pop("my-car", None)
        task_registry._FACTORIES.pop("my-car", None)
    assert namespace["demos"].num_trajectories == 20 and os.path.isfile(tmp_path / "mountain_car_20.npz")
    assert namespace["summary"]["scenario"] == "my-car" and namespace["summary"]["frames"] == 400


def test_the_benchmark_sweeps_a_gymnasium_id_with_the_non_driving_scripts(tmp_path):
    from torchrl_csirl.scripts import benchmark

    todo, _ = benchmark.plan_cells(["csirl", "sac"], [MOUNTAIN_CAR], [0, 1], str(tmp_path),
                                   ["env.features=0", "csirl_robotics:csirl.matching_target=path"])
    commands = {c.name: c.command[2:] for c in todo}
    assert set(commands) == {f"{MOUNTAIN_CAR}-{m}-s{s}" for m in ("csirl", "sac") for s in (0, 1)}
    csirl = commands[f"{MOUNTAIN_CAR}-csirl-s0"]
    assert csirl[0] == "torchrl_csirl.scripts.csirl_robotics" and f"env.gym_id={MOUNTAIN_CAR}" in csirl
    assert "csirl.matching_target=path" in csirl
    sac = commands[f"{MOUNTAIN_CAR}-sac-s1"]
    assert sac[0] == "torchrl_csirl.scripts.imitation_robotics" and "method=sac" in sac
    assert not any(a.startswith("csirl.") for a in sac)


def test_train_expert_trains_sac_on_a_gymnasium_id_and_writes_its_demonstrations(tmp_path):
    from torchrl_csirl.data import ExpertDemonstrations
    from torchrl_csirl.scripts import train_expert

    summary = train_expert.main([
        f"env.gym_id={MOUNTAIN_CAR}", "collector.total_frames=400", "collector.frames_per_batch=200",
        "collector.cut_episodes=true", "collector.num_workers=1", "collector.init_random_frames=200",
        "replay_buffer.warmup_frames=200", "optim.utd_ratio=0.1", "updates_per_round=10", "sac.batch_size=32",
        "eval.episodes=1", "eval.final_episodes=1", "demos.episodes=2", "logger.backend=none",
        "logger.progress_bar=false", "device=cpu", f"logger.output_dir={tmp_path}"])
    assert summary["scenario"] == MOUNTAIN_CAR and summary["frames"] == 400 and summary["demos_episodes"] == 2
    demos = ExpertDemonstrations.load(summary["demos_path"])
    assert demos.num_trajectories == 2 and (demos.observation_dim, demos.action_dim) == (2, 1)
    assert [e["seed"] for e in demos.metadata["episodes"]] == [20_000, 20_001]


@pytest.mark.parametrize("overrides, schema", [
    ([f"env.gym_id={MOUNTAIN_CAR}"], "CSIRLTaskConfig"), (["env.task=relocate"], "CSIRLTaskConfig"),
    (["env.task=hopper"], "CSIRLTaskConfig"), (["env.task=roundabout"], "CSIRLHighwayConfig"), ([], "CSIRLHighwayConfig"),
])
def test_the_csirl_script_configures_every_task_with_its_familys_schema(overrides, schema):
    from torchrl_csirl.methods import csirl

    cfg = csirl.load_config(overrides)
    assert ("gym_id" in cfg.env) == (schema == "CSIRLTaskConfig")
    assert cfg.model.ego_relative_features == (schema == "CSIRLHighwayConfig")


def test_the_console_command_trains_csirl_on_the_hopper(tmp_path):
    """``torchrl-csirl train env.task=hopper`` (here as ``python -m torchrl_csirl``, the same entry point)."""
    import subprocess
    import sys

    import tomllib

    with open(os.path.join(os.path.dirname(__file__), "..", "pyproject.toml"), "rb") as f:
        assert tomllib.load(f)["project"]["scripts"]["torchrl-csirl"] == "torchrl_csirl.scripts.cli:main"
    command = [sys.executable, "-m", "torchrl_csirl", "train", "env.task=hopper", "csirl.updates_per_round=10",
               "csirl.num_qvalue_nets=2", "replay_buffer.batch_size=32", *TINY, f"logger.output_dir={tmp_path}"]
    unshipped = subprocess.run(command, capture_output=True, text=True, timeout=300)  # TINY asks for 3 trajectories
    assert unshipped.returncode == 2 and unshipped.stderr.strip().splitlines()[-1].startswith(
        "error: expert.num_trajectories=3: num_trajectories must be one of the shipped sizes")
    proc = subprocess.run([*command, "expert.num_trajectories=5"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    summary = json.loads(proc.stdout.strip().splitlines()[-1])
    assert (summary["scenario"], summary["method"], summary["frames"]) == ("hopper", "csirl", 400)
    bad = subprocess.run([sys.executable, "-m", "torchrl_csirl", "train", "method=nope"], capture_output=True, text=True)
    assert bad.returncode == 2 and bad.stderr.strip().startswith("error: method=nope: unknown; one of bc, csirl, csirl-b")


def test_the_benchmark_knows_the_tasks_an_env_module_override_registers(tmp_path):
    """A fresh interpreter: ``--scenarios own-pendulum`` is known once ``env.module=own_task_module`` (an
    override of the sweep) is imported, as the cells will import it; a module that cannot be imported is one line."""
    code = ("import sys; from torchrl_csirl.sweep.plan import plan_cells, BenchmarkError\n"
            f"todo, _ = plan_cells(['bc'], ['own-pendulum'], [0], {str(tmp_path)!r}, ['env.module=own_task_module'])\n"
            "print([c.name for c in todo], 'env.module=own_task_module' in todo[0].command)\n"
            "try:\n    plan_cells(['bc'], ['own-pendulum'], [0], '.', ['bc:env.module=no_such_module_here'])\n"
            "except BenchmarkError as err:\n    print(err)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=os.path.dirname(__file__)).stdout.strip().splitlines()
    assert out[-2] == "['own-pendulum-bc-s0'] True"
    assert out[-1].startswith("env.module=no_such_module_here: cannot import it")
