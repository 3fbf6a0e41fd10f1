"""Builders every recipe shares: demonstrations, environments, collector, buffers, logging,
evaluation, checkpoints, the learner device, the plots and the run itself.

Each ``make_*`` takes sections of the typed configuration (:mod:`torchrl_csirl.launch.config`) and returns one
TorchRL / torchrl-csirl piece; a method's recipe builds its losses and update step and hands them
to :func:`assemble_trainer`, which wires the shared hooks. Library code below takes plain arguments
(configuration stops here).
"""
from __future__ import annotations

import atexit
import contextlib
import copy
import json
import os
import shutil
import sys
import time
import weakref
from dataclasses import dataclass, field
from functools import partial
from typing import Any, Callable

import torch
from omegaconf import DictConfig, OmegaConf
from tensordict import TensorDict
from torch import nn
from torchrl.collectors import BaseCollector, Collector
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
from torchrl.envs import Compose, EnvBase, Transform

from torchrl_csirl.data import (
    ExpertDemonstrations,
    FilledRowsCheckpointer,
    available_expert_datasets,
    import_published,
    load_expert_demonstrations,
    load_minari_dataset,
)
from torchrl_csirl.envs import SCENARIOS, ScenarioSpec, TaskSpec, env_factory, make_serial_env, resolve_scenario  # noqa: F401
from torchrl_csirl.envs import make_env as make_scenario_env
from torchrl_csirl.launch.config import ConfigError, flatten_config, override_strings
from torchrl_csirl.launch.run import (
    ExpertDataError,
    default_run_name,
    make_run_dir,
    resolve_resume,
    resume_command,
    stop_with_checkpoint,
)
from torchrl_csirl.modules import make_input_features
from torchrl_csirl.trainers import (
    CheckpointHook,
    CollectorWorkerError,
    CSIRLTrainer,
    EvaluationHook,
    MetricsLogger,
    WorkerErrorLog,
    evaluate_policy,
    ignoring_interrupts,
    shutdown_collector,
    start_collector,
)

__all__ = [
    "PolicyMirror",
    "Run",
    "assemble_trainer",
    "check_collector",
    "curriculum_first",
    "envs_per_worker",
    "load_experts",
    "make_collector",
    "make_eval_env",
    "make_logger",
    "make_online_buffer",
    "make_worker_env_fn",
    "recorded_in_traffic",
    "resume_run",
    "start_run",
    "evaluation_summary",
    "model_input_features",
]

MAX_ENVS_PER_WORKER = 4


# ---------------------------------------------------------------------------------------- models
def model_input_features(model: DictConfig, spec: TaskSpec) -> nn.Module | None:
    """The input map every network of a recipe reads the observation through (the ``model`` section:
    ``ego_relative_features``, ``lane_features``; :func:`~torchrl_csirl.modules.make_input_features`), or None."""
    return make_input_features(spec, model.ego_relative_features, model.lane_features)


# ---------------------------------------------------------------------------------------- data
def load_experts(expert: DictConfig, spec: ScenarioSpec) -> ExpertDemonstrations:
    """The demonstrations: the shipped ones, or ``expert.path`` (checked against the scenario).

    ``expert.path`` is an :class:`ExpertDemonstrations` ``.npz``, ``minari:<dataset id>`` (a local Minari
    dataset) or a published file (read by :func:`~torchrl_csirl.data.import_published` with
    ``end_at=expert.end_at``); a task without shipped demonstrations needs it. ``expert.curriculum`` picks
    its curriculum trajectory (:func:`curriculum_first`), then the first
    ``expert.num_trajectories`` are kept.

    Raises:
        ExpertDataError: a missing, malformed or mismatched file, naming it.
    """
    n = expert.num_trajectories
    if expert.path is None:
        if spec.name not in available_expert_datasets():
            raise ExpertDataError(f"expert.path: required for {spec.name!r}, which ships no demonstrations "
                                  "(an .npz of ExpertDemonstrations, or minari:<dataset id>)")
        return load_expert_demonstrations(spec.name, n, curriculum=expert.curriculum)
    if str(expert.path).startswith("minari:"):
        path = str(expert.path)
        try:
            demos = load_minari_dataset(path.removeprefix("minari:"), task=spec)
        except Exception as err:
            raise ExpertDataError(f"expert.path={path}: cannot read it ({type(err).__name__}: {err})") from None
        return _checked_demonstrations(demos, expert, spec, path)
    path = os.path.abspath(os.path.expanduser(str(expert.path)))
    if not os.path.isfile(path):
        raise ExpertDataError(f"expert.path: no such file {path!r}.")
    if path.endswith(".npz") and expert.end_at != "recording":
        raise ExpertDataError(f"expert.end_at={expert.end_at} applies to published files; {path!r} is an .npz "
                              "of ExpertDemonstrations (its episodes end where they were recorded).")
    try:
        if path.endswith(".npz"):
            demos = ExpertDemonstrations.load(path)
        else:
            demos = import_published(path, end_at=expert.end_at, scenario=spec.name)
    except Exception as err:
        raise ExpertDataError(f"expert.path: {path!r} is not a valid expert file ({type(err).__name__}: {err}).") from None
    return _checked_demonstrations(demos, expert, spec, path)


def _checked_demonstrations(demos: ExpertDemonstrations, expert: DictConfig, spec: TaskSpec,
                            path: str) -> ExpertDemonstrations:
    """A file's demonstrations matched against the task, curriculum first, the first ``num_trajectories``."""
    n = expert.num_trajectories
    if demos.observation_dim != spec.obs_dim or demos.action_dim != spec.action_dim:
        raise ExpertDataError(
            f"expert.path: {path!r} has observations of size {demos.observation_dim} and actions of size "
            f"{demos.action_dim}, but {spec.name!r} has {spec.obs_dim} and {spec.action_dim}.")
    if demos.num_trajectories < n:
        raise ExpertDataError(
            f"expert.path: {path!r} holds {demos.num_trajectories} trajectories, "
            f"expert.num_trajectories asks for {n}.")
    demos = curriculum_first(demos, expert.curriculum, spec, path)
    return demos.subset(n) if n < demos.num_trajectories else demos


def recorded_in_traffic(observations: torch.Tensor, spec: ScenarioSpec) -> bool:
    """Whether another vehicle is present in any of the observations ``[T, D]`` of a trajectory.

    Examples:
        >>> obs = torch.zeros(3, 25)
        >>> recorded_in_traffic(obs, SCENARIOS["merge"])
        False
        >>> obs[1, 5] = 1.0  # presence of the first other vehicle
        >>> recorded_in_traffic(obs, SCENARIOS["merge"])
        True
    """
    rows = observations.reshape(observations.shape[0], spec.vehicles_count, len(spec.features))
    return bool((rows[:, 1:, spec.features.index("presence")] > 0.5).any())


def curriculum_first(demos: ExpertDemonstrations, curriculum: str, spec: ScenarioSpec,
                     path: str = "expert.path") -> ExpertDemonstrations:
    """The demonstrations of a file with the curriculum trajectory chosen by ``expert.curriculum`` first.

    ``"empty"``: trajectory 0 as stored (the published files, like ours, store the empty-road
    trajectory first). ``"traffic"``: the first trajectory in which another vehicle is observed,
    moved to the front (the others keep their order); ``metadata["curriculum_trajectory"]`` is its
    index in the file.

    Raises:
        ExpertDataError: ``"traffic"`` and no trajectory of the file was recorded in traffic.
    """
    if curriculum != "traffic":
        return demos.with_metadata(curriculum_trajectory=0)
    found = [i for i in range(demos.num_trajectories)
             if recorded_in_traffic(demos.trajectory(i)["observation"], spec)]
    if not found:
        raise ExpertDataError(f"expert.curriculum=traffic: no trajectory of {path!r} was recorded in traffic "
                              "(no other vehicle observed); use expert.curriculum=empty.")
    first = found[0]
    if first == 0:
        return demos.with_metadata(curriculum_trajectory=0)
    order = [first, *(i for i in range(demos.num_trajectories) if i != first)]
    metadata = demos.metadata
    if len(metadata.get("episodes") or []) == demos.num_trajectories:
        metadata["episodes"] = [metadata["episodes"][i] for i in order]
    metadata["curriculum_trajectory"] = first
    return ExpertDemonstrations.from_episodes([demos.trajectory(i) for i in order], metadata=metadata)


# ---------------------------------------------------------------------------------------- envs
def check_collector(collector: DictConfig) -> None:
    """The checks that involve several ``collector.*`` keys (before any worker starts)."""
    fpb, workers, k = collector.frames_per_batch, collector.num_workers, collector.envs_per_worker
    if fpb % workers:
        raise ConfigError(f"collector.frames_per_batch={fpb}: must be a multiple of collector.num_workers ({workers})")
    if k is not None and fpb % (workers * k):
        raise ConfigError(f"collector.frames_per_batch={fpb}: must be a multiple of "
                          f"collector.num_workers x collector.envs_per_worker ({workers} x {k})")


def envs_per_worker(collector: DictConfig, spec: ScenarioSpec) -> int:
    """``collector.envs_per_worker``, or for ``null`` the most (up to 4) that keep whole episodes.

    Collection resets every environment at each batch start (exact resume), so each of the
    ``num_workers x k`` environments steps ``frames_per_batch / (num_workers x k)`` times per batch;
    the automatic choice keeps that at least the scenario's episode limit.

    Examples:
        >>> from omegaconf import OmegaConf
        >>> c = OmegaConf.create({"envs_per_worker": None, "frames_per_batch": 480, "num_workers": 2})
        >>> envs_per_worker(c, SCENARIOS["merge"]), envs_per_worker(c, SCENARIOS["highway-fast"])
        (4, 1)
    """
    if collector.envs_per_worker is not None:
        return collector.envs_per_worker
    fpb, workers = collector.frames_per_batch, collector.num_workers
    fitting = [k for k in range(1, MAX_ENVS_PER_WORKER + 1)
               if fpb % (workers * k) == 0 and fpb // (workers * k) >= spec.max_steps]
    return max(fitting, default=1)


def make_worker_env_fn(scenario: str, collector: DictConfig) -> Callable[[], EnvBase]:
    """A picklable factory of one collector worker's environments (``envs_per_worker`` copies).

    Examples:
        >>> from omegaconf import OmegaConf
        >>> c = OmegaConf.create({"envs_per_worker": 2, "frames_per_batch": 500, "num_workers": 2})
        >>> make_worker_env_fn("merge", c)().batch_size
        torch.Size([2])
    """
    spec = resolve_scenario(scenario)
    k = envs_per_worker(collector, spec)
    check_whole_episodes(collector, spec, k)
    # Ctrl-C reaches the workers too: they keep collecting until the main process stops them; a task
    # of the user's own reaches them as its factory (a spawned worker has no registry)
    return ignoring_interrupts(partial(make_serial_env, env_factory(spec.name), k))


def check_whole_episodes(collector: DictConfig, spec: TaskSpec, k: int) -> None:
    """Each environment must step at least the task's episode limit per batch: collection restarts
    every environment at each batch start (exact resume), so a shorter share would cut every longer
    episode, silently. ``collector.cut_episodes=true`` allows it (tiny test budgets).

    Raises:
        ConfigError: one line with the share, the limit and the ``frames_per_batch`` that fits.

    Examples:
        >>> from omegaconf import OmegaConf
        >>> c = OmegaConf.create({"frames_per_batch": 100, "num_workers": 2, "cut_episodes": False})
        >>> check_whole_episodes(c, SCENARIOS["merge"], 1)  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        torchrl_csirl.launch.config.ConfigError: collector.frames_per_batch=100: each of the 2 environments steps 50 ...
        >>> c.frames_per_batch = 120
        >>> check_whole_episodes(c, SCENARIOS["merge"], 1)
    """
    share = collector.frames_per_batch // (collector.num_workers * k)
    if share >= spec.max_steps or collector.get("cut_episodes", False):
        return
    envs = collector.num_workers * k
    raise ConfigError(
        f"collector.frames_per_batch={collector.frames_per_batch}: each of the {envs} environments steps {share} frames "
        f"per batch, fewer than {spec.name}'s episode limit ({spec.max_steps}), so episodes would be cut; use "
        f"collector.frames_per_batch >= {envs * spec.max_steps} (or collector.cut_episodes=true)")


def make_eval_env(scenario: str) -> EnvBase:
    """One evaluation environment (main process, seeded per episode by the evaluator)."""
    return make_scenario_env(scenario)


def make_collector(scenario: str, collector: DictConfig, policy: nn.Module, frames_done: int = 0,
                   worker_errors: WorkerErrorLog | None = None) -> BaseCollector:
    """A synchronous collector of ``collector.num_workers`` worker processes (unbounded; the trainer stops it).

    Each worker process holds ``envs_per_worker`` environments *and a copy of the policy* (TorchRL's
    multi-process synchronous collector, ``Collector(..., num_collectors=W, sync=True)``); the
    workers wait while the main process updates, which gets every core (``collector.main_threads``).
    Why this scales better than a ``ParallelEnv`` driven from the main process: docs/performance.md.

    The workers act with the weights the main process trains because TorchRL moves the policy's
    parameter storage into shared memory *in place*: optimiser steps and ``load_state_dict`` reach
    them with no explicit sync; replacing a parameter tensor (``.to(device)``) would not, so a
    learner on another device acts through a CPU :class:`PolicyMirror`.

    Args:
        scenario: the scenario name.
        collector: the ``collector`` section.
        policy: the acting policy (CPU); with one worker it runs in this process.
        frames_done: frames collected before (resume): uniform-random frames are not collected again.
        worker_errors: where the workers write the error that ends them (:class:`WorkerErrorLog`);
            a worker that fails to start is then one :class:`CollectorWorkerError` line.

    Examples:
        >>> from omegaconf import OmegaConf
        >>> from torchrl_csirl.modules import make_actor
        >>> c = OmegaConf.create({"envs_per_worker": None, "frames_per_batch": 60, "num_workers": 1,
        ...                       "main_threads": None, "init_random_frames": 0})
        >>> spec = SCENARIOS["merge"]
        >>> collector = make_collector("merge", c, make_actor(spec.obs_dim, spec.action_dim))
        >>> next(iter(collector)).numel()
        60
        >>> shutdown_collector(collector)
    """
    fpb = collector.frames_per_batch
    random_frames = max(0, collector.init_random_frames - frames_done)
    random_frames = -(-random_frames // fpb) * fpb
    workers = collector.num_workers
    main_threads = collector.main_threads or os.cpu_count() or 1
    common: dict[str, Any] = dict(frames_per_batch=fpb, total_frames=-1, init_random_frames=random_frames or None,
                                  auto_register_policy_transforms=False)
    env_fn = make_worker_env_fn(scenario, collector)
    if workers == 1:
        torch.set_num_threads(main_threads)
        return Collector(env_fn(), policy=policy, **common)
    if worker_errors is not None:
        env_fn = worker_errors.wrap(env_fn)
    made = start_collector(partial(Collector, [env_fn] * workers, policy, num_collectors=workers, sync=True,
                                   num_threads=main_threads, num_sub_threads=1, **common),
                           worker_errors)
    # whatever path the process leaves by (see shutdown_collector); a weak reference, so that
    # collectors dropped earlier (tests) are not kept alive
    atexit.register(_shutdown_if_alive, weakref.ref(made))
    return made


def _shutdown_if_alive(collector_ref: weakref.ref) -> None:
    collector = collector_ref()
    if collector is not None:
        shutdown_collector(collector)


# ---------------------------------------------------------------------------------------- device
class PolicyMirror:
    """A CPU copy of a learner's policy, for the collector workers and the evaluation env.

    On the CPU the learner's own policy acts (its parameters are the ones the workers share).
    On another device (``device=cuda``) the workers and the evaluation act with a CPU copy, and
    :meth:`sync` copies the learner's weights into it *in place* (so the workers' shared memory
    follows); the recipe calls it after each batch's updates and before each round's evaluation.

    Args:
        policy: the learner's policy (on ``device``).
        device: the learner's device.

    Examples:
        >>> from torchrl_csirl.modules import make_actor
        >>> actor = make_actor(4, 2, hidden=(8,))
        >>> PolicyMirror(actor, torch.device("cpu")).policy is actor
        True
    """

    def __init__(self, policy: nn.Module, device: torch.device) -> None:
        self.learner = policy
        self.mirrored = device.type != "cpu"
        self.policy = copy.deepcopy(policy).to("cpu") if self.mirrored else policy
        self._target = TensorDict.from_module(self.policy) if self.mirrored else None

    def sync(self, *_: Any) -> None:
        """Copies the learner's weights into the CPU policy (a no-op on the CPU)."""
        if self.mirrored:
            with torch.no_grad():
                self._target.update_(TensorDict.from_module(self.learner))


# ---------------------------------------------------------------------------------------- buffers, logging
def make_online_buffer(size: int, batch_size: int, transforms: list[Transform], device: torch.device) -> TensorDictReplayBuffer:
    """The online buffer, stored on the learner's device; ``transforms`` run at sampling time.

    Its checkpoints hold the filled rows only (:class:`~torchrl_csirl.data.FilledRowsCheckpointer`).
    """
    return TensorDictReplayBuffer(
        storage=LazyTensorStorage(size, device=device),
        batch_size=batch_size,
        checkpointer=FilledRowsCheckpointer(),
        transform=Compose(*transforms) if transforms else None,
    )


def make_logger(cfg: DictConfig, run_dir: str, resume_frames: int | None = None) -> MetricsLogger:
    """metrics.jsonl / metrics.csv in the run directory, plus W&B (offline by default) or TorchRL CSV."""
    return MetricsLogger(
        run_dir,
        backend=cfg.logger.backend,
        exp_name=os.path.basename(run_dir),
        config=OmegaConf.to_container(cfg, resolve=True),
        wandb_mode=cfg.logger.mode,
        project=cfg.logger.project,
        resume_frames=resume_frames,
    )


# ---------------------------------------------------------------------------------------- the run
@dataclass
class Run:
    """What every recipe's run holds; a method's recipe keeps its own pieces in ``parts``."""

    cfg: DictConfig
    spec: ScenarioSpec
    run_dir: str
    device: torch.device
    demos: ExpertDemonstrations | None
    online_buffer: TensorDictReplayBuffer
    mirror: PolicyMirror
    collector: BaseCollector
    eval_env: EnvBase
    logger: MetricsLogger
    trainer: CSIRLTrainer
    evaluation: EvaluationHook
    checkpoint: CheckpointHook
    parts: dict[str, Any] = field(default_factory=dict)
    worker_errors: WorkerErrorLog | None = None

    def __getattr__(self, name: str) -> Any:
        parts = self.__dict__.get("parts", {})
        if name in parts:
            return parts[name]
        raise AttributeError(f"{type(self).__name__} has no attribute {name!r}")

    def evaluate(self, episodes: int) -> dict[str, float]:
        """The deterministic policy on ``episodes`` seeded test episodes."""
        self.mirror.sync()
        return evaluate_policy(self.eval_env, self.mirror.policy, episodes=episodes,
                               max_steps=self.spec.max_steps, seed=self.cfg.eval.seed)

    def close(self) -> None:
        shutdown_collector(self.collector)
        self.eval_env.close()
        if self.worker_errors is not None:
            self.worker_errors.close()


def assemble_trainer(
    cfg: DictConfig,
    spec: ScenarioSpec,
    run_dir: str,
    *,
    device: torch.device,
    demos: ExpertDemonstrations | None,
    policy: nn.Module,
    online_buffer: TensorDictReplayBuffer,
    update_step: Callable[[CSIRLTrainer], dict[str, torch.Tensor]],
    total_frames: int,
    updates_per_round: int,
    states: dict[str, Any],
    round_hooks: list[tuple[str, Any]] = (),
    frames_done: int = 0,
    resume_frames: int | None = None,
    parts: dict[str, Any] | None = None,
    behaviour: Callable[[nn.Module], nn.Module] | None = None,
) -> Run:
    """The trainer with the shared hooks: evaluation and any ``round_hooks`` at each round end,
    checkpoints, metrics logging, and the CPU policy mirror for a learner on another device.

    Args:
        cfg: the recipe configuration (shared sections).
        spec: the scenario.
        run_dir: the run directory.
        device: the learner's device.
        demos: the demonstrations.
        policy: the learner's policy (what acts and is evaluated).
        online_buffer: the online replay buffer.
        update_step: one update (``callable(trainer) -> dict of losses``).
        total_frames: environment frames to collect.
        updates_per_round: updates between two round ends.
        states: ``name -> object with state_dict/load_state_dict`` saved in checkpoints.
        round_hooks: ``(name, hook)`` called at each round end before the evaluation.
        frames_done: frames already collected (resume).
        resume_frames: the resumed run's frames (the logger drops rows past them).
        parts: the method's own pieces, reachable as attributes of the :class:`Run`.
        behaviour: wraps the (mirrored) policy for the collector only, e.g. exploration noise
            (:class:`~torchrl_csirl.modules.MeanActionGaussianNoise`); the evaluation acts with the policy.
    """
    mirror = PolicyMirror(policy, device)
    logger = make_logger(cfg, run_dir, resume_frames)
    eval_env = make_eval_env(spec.name)
    # last: the worker processes start here
    acting = mirror.policy if behaviour is None else behaviour(mirror.policy)
    worker_errors = WorkerErrorLog()
    collector = make_collector(spec.name, cfg.collector, acting, frames_done, worker_errors)
    trainer = CSIRLTrainer(
        collector=collector,
        online_buffer=online_buffer,
        update_step=update_step,
        total_frames=total_frames,
        utd_ratio=cfg.optim.utd_ratio,
        updates_per_round=updates_per_round,
        warmup_frames=cfg.replay_buffer.warmup_frames,
        clear_buffer_each_round=cfg.replay_buffer.clear_each_round,
        seed=cfg.seed,
        progress_bar=cfg.logger.progress_bar and sys.stderr.isatty(),
    )

    curve_seed = cfg.eval.seed if cfg.eval.validation_seed is None else cfg.eval.validation_seed

    def run_eval() -> dict[str, float]:  # the learning curve: validation episodes, not the test ones
        return evaluate_policy(eval_env, mirror.policy, episodes=cfg.eval.episodes,
                               max_steps=spec.max_steps, seed=curve_seed)

    evaluation = EvaluationHook(run_eval, every_rounds=cfg.eval.every_rounds)
    checkpoint = CheckpointHook(os.path.join(run_dir, "checkpoints"),
                                online_buffer if cfg.checkpoint.save_buffer else None,
                                every_rounds=cfg.checkpoint.every_rounds)
    if mirror.mirrored:
        trainer.register_op("round_end", mirror.sync, "policy_mirror")
    for name, hook in round_hooks:
        trainer.register_op("round_end", hook, name)
    trainer.register_op("round_end", evaluation, "evaluation")
    trainer.register_op("post_round", checkpoint, "checkpoint")
    if mirror.mirrored:  # after each batch's updates, before the next collection
        trainer.register_op("log", mirror.sync, "policy_mirror")
    trainer.register_op("log", lambda t, row: logger.log(row), "metrics_logger")
    for name, obj in states.items():
        trainer.register_state(name, obj)
    trainer.register_state("evaluation", evaluation)
    return Run(cfg, spec, run_dir, device, demos, online_buffer, mirror, collector, eval_env, logger, trainer,
               evaluation, checkpoint, dict(parts or {}), worker_errors)


# ---------------------------------------------------------------------------------------- starting and resuming
def start_run(cfg: DictConfig, method: str, build: Callable[[DictConfig, str], Any]) -> Any:
    """A new run: its directory (``logger.*``) with ``config.yaml``, then ``build(cfg, run_dir)``.

    If ``build`` fails (e.g. a bad expert file) the new directory, which holds no run, is removed.
    """
    run_dir = make_run_dir(cfg.logger.output_dir, cfg.logger.exp_name,
                           default_run_name(cfg.env.scenario, method, cfg.seed), cfg.logger.overwrite)
    OmegaConf.save(cfg, os.path.join(run_dir, "config.yaml"))
    try:
        return build(cfg, run_dir)
    except BaseException:
        shutil.rmtree(run_dir, ignore_errors=True)
        raise


def resume_run(cfg: DictConfig, run_dir: str, checkpoint: str, make_trainer: Callable[..., Run]) -> Run:
    """A killed run continued: ``make_trainer(cfg, run_dir, frames_done=, resume_frames=)`` with the
    checkpoint's counters, then the checkpoint (and the online buffer, if saved) restored."""
    from torchrl_csirl.trainers import load_checkpoint, read_checkpoint_state

    counters = read_checkpoint_state(checkpoint)["counters"]  # an unreadable file: one CheckpointError line
    run = make_trainer(cfg, run_dir, frames_done=counters["frames"], resume_frames=counters["frames"])
    try:
        load_checkpoint(run.trainer, checkpoint, run.online_buffer if cfg.checkpoint.save_buffer else None)
    except BaseException:
        run.close()
        raise
    print(f"resumed {run_dir} at {counters['frames']} frames, {counters['updates']} updates", file=sys.stderr)
    record_resumed_settings(cfg, run_dir, counters["frames"])
    return run


def record_resumed_settings(cfg: DictConfig, run_dir: str, frames: int) -> dict[str, list[Any]]:
    """A resume that changes settings (``key=value`` beside ``checkpoint.resume``) writes them into the run's
    ``config.yaml``, so the next resume keeps them and the file says what the run ran with, and appends
    ``{"frames", "changed": {key: [before, after]}}`` to ``<run dir>/resumes.jsonl``, so the settings of
    the frames before stay on record. Keys the saved file lacks (settings the schema gained since the run
    started) hold their defaults and are no change. Returns the changes (empty: nothing written).

    Examples:
        >>> import tempfile, os
        >>> run_dir = tempfile.mkdtemp()
        >>> OmegaConf.save(OmegaConf.create({"seed": 0, "collector": {"total_frames": 1000}}),
        ...                os.path.join(run_dir, "config.yaml"))
        >>> cfg = OmegaConf.create({"seed": 0, "collector": {"total_frames": 5000}})
        >>> record_resumed_settings(cfg, run_dir, frames=1000)
        {'collector.total_frames': [1000, 5000]}
        >>> OmegaConf.load(os.path.join(run_dir, "config.yaml")).collector.total_frames
        5000
        >>> record_resumed_settings(OmegaConf.merge(cfg, {"eval": {"keep_best": False}}), run_dir, frames=5000)
        {}
    """
    path = os.path.join(run_dir, "config.yaml")
    saved = OmegaConf.load(path)
    effective = cfg.copy()
    if "checkpoint" in effective and "resume" in effective.checkpoint:
        effective.checkpoint.resume = None
    before, after = flatten_config(saved), flatten_config(effective)
    changed = {key: [before[key], value] for key, value in after.items()
               if key != "checkpoint.resume" and key in before and before[key] != value}
    if changed:
        tmp = f"{path}.tmp"
        OmegaConf.save(effective, tmp)
        os.replace(tmp, path)
        with open(os.path.join(run_dir, "resumes.jsonl"), "a") as f:
            f.write(json.dumps({"frames": int(frames), "changed": changed}) + "\n")
    return changed


def requested_config(argv: list[str], load: Callable[[list[str]], DictConfig],
                     load_run: Callable[[str, list[str]], DictConfig]) -> DictConfig:
    """The configuration a recipe's command line asks for: ``load(argv)`` for a new run, or with
    ``checkpoint.resume=`` the saved run's configuration updated by the rest of the command line
    (``load_run(run_dir, argv)``, e.g. a larger ``collector.total_frames``), ``checkpoint.resume`` kept."""
    resume = override_strings(argv).get("checkpoint.resume")
    if resume is None or resume == "null":
        return load(argv)
    cfg = load_run(resolve_resume(resume)[0], [a for a in argv if not a.startswith("checkpoint.resume=")])
    cfg.checkpoint.resume = resume
    return cfg


def open_configured_run(cfg: DictConfig, method: Callable[[DictConfig], str], make_trainer: Callable[..., Run]) -> Run:
    """A new run (:func:`start_run`, its directory named by ``method(cfg)``), or the run of
    ``cfg.checkpoint.resume`` with its checkpoint restored (:func:`resume_run`)."""
    if cfg.checkpoint.resume is None:
        return start_run(cfg, method(cfg), make_trainer)
    return resume_run(cfg, *resolve_resume(cfg.checkpoint.resume), make_trainer)


def open_run(argv: list[str], method: Callable[[DictConfig], str], make_trainer: Callable[..., Run],
             load: Callable[[list[str]], DictConfig],
             load_run: Callable[[str, list[str]], DictConfig]) -> Run:
    """The run a recipe's command line asks for (:func:`requested_config`, then
    :func:`open_configured_run`)."""
    return open_configured_run(requested_config(argv, load, load_run), method, make_trainer)


# ---------------------------------------------------------------------------------------- training and summary
def train(run: Run) -> None:
    """``run.trainer.train()``; on any exit the collector is shut down and the logs are kept.

    SIGTERM or Ctrl-C stops at the end of the current batch, writes a checkpoint there and exits
    (130 / 143) with the command that resumes the run (:func:`torchrl_csirl.launch.run.stop_with_checkpoint`).
    A collector worker that dies (an exception in its environment, a killed process) stops the run at
    once: the other workers are stopped, the last checkpoint is kept, and one line names the worker's error.

    Raises:
        TrainingDivergedError: with where the last good checkpoint is and how to resume.
        CollectorWorkerError: a worker died; with its error, the last checkpoint and how to resume.
    """
    from torchrl_csirl.trainers import StopOnSignals, TrainingDivergedError, TrainingInterrupted

    try:
        with StopOnSignals(run.trainer) as stop:
            run.trainer.train()
    except TrainingInterrupted:  # SIGTERM / Ctrl-C, at a batch boundary: checkpoint, say how to resume
        run.logger.close()
        stop_with_checkpoint(run.checkpoint.save(run.trainer), run.run_dir, stop.signum)
    except TrainingDivergedError as err:
        run.logger.close()
        raise TrainingDivergedError(
            f"{err}. Training stopped; {_last_checkpoint(run)} (resume with checkpoint.resume={run.run_dir}, "
            "e.g. with a smaller optim.lr)."
        ) from None
    except Exception as err:  # a dead collector worker: one line; anything else as it is
        run.logger.close()
        failure = run.worker_errors.describe(run.collector, err) if run.worker_errors is not None else None
        if failure is None:
            raise
        raise CollectorWorkerError(f"{failure}. Training stopped; {_last_checkpoint(run)}; "
                                   f"resume with: {resume_command(run.run_dir)}") from None
    except BaseException:  # Ctrl-C, SIGTERM: keep the logs (checkpoints are already on disk)
        run.logger.close()
        raise
    finally:
        with contextlib.suppress(Exception):  # a collector whose workers died may fail to shut down cleanly
            shutdown_collector(run.collector)
        if run.worker_errors is not None:
            run.worker_errors.close()


def _last_checkpoint(run: Run) -> str:
    """Where the run's last checkpoint is kept, in words."""
    if os.path.exists(run.checkpoint.path):
        return f"the last checkpoint is kept at {run.checkpoint.path}"
    return "no checkpoint was written yet"


def train_and_finish(run: Run, finish: Callable[[Run], dict[str, Any]]) -> dict[str, Any]:
    """:func:`train`, then ``finish(run)`` (final evaluation, policy, plots, summary); the logger and
    the evaluation environment are closed whatever happens."""
    train(run)
    try:
        return finish(run)
    finally:
        run.logger.close()
        run.eval_env.close()


def open_train_and_finish(argv: list[str], method: Callable[[DictConfig], str], make_trainer: Callable[..., Run],
                          load: Callable[[list[str]], DictConfig], load_run: Callable[[str, list[str]], DictConfig],
                          finish: Callable[[Run], dict[str, Any]]) -> dict[str, Any]:
    """A whole run from a command line: :func:`open_run`, :func:`train_and_finish`, and the summary's
    ``total_wall_s`` (this process's wall time with start-up, final evaluation and plots, plus the
    earlier processes' of a resumed run)."""
    start = time.perf_counter()
    summary = train_and_finish(open_run(argv, method, make_trainer, load, load_run), finish)
    summary["total_wall_s"] = round(time.perf_counter() - start + summary.get("earlier_wall_s", 0.0), 1)
    return summary


def evaluation_summary(cfg: DictConfig, spec: ScenarioSpec, method: str, final: dict[str, float],
                 expert_rate: float | None) -> dict[str, Any]:
    """The summary fields of a run's final test evaluation ``final`` (:func:`evaluate_policy`'s
    output), with the accomplish rate normalised by ``expert_rate`` (None: not normalised)."""
    from torchrl_csirl.envs import normalized_accomplish_rate

    return {
        "scenario": spec.name,
        "method": method,
        "preset": cfg.get("preset", "default"),
        "seed": cfg.seed,
        "accomplish_rate": final["accomplish_rate"],
        "accomplish_rate_std": final["accomplish_rate_std"],
        "success_rate": final["success_rate"],
        "crash_rate": final["crash_rate"],
        "return": final["env_return"],  # the env's own reward (robotics: the paper's metric; driving: reference)
        "normalized_accomplish_rate": (
            float(normalized_accomplish_rate(final["accomplish_rate"], expert_rate)) if expert_rate else None),
        "eval_episodes": cfg.eval.final_episodes,
    }


def final_summary(run: Run, method: str, title: str) -> dict[str, Any]:
    """Final checkpoint and test evaluation, ``policy.pt``, the learning curve, and the summary
    fields every recipe reports (the method adds its own). A run keeping its best policy
    (``run.parts["keep_best"]``, :class:`~torchrl_csirl.trainers.KeepBestPolicy`) is tested and saved with
    those weights (``policy_from`` in the summary); its checkpoint keeps the last ones."""
    from torchrl_csirl.launch.run import expert_accomplish_rate
    from torchrl_csirl.modules import save_policy
    from torchrl_csirl.visualization import plot_learning_curve

    trainer, cfg = run.trainer, run.cfg
    run.checkpoint.save(trainer)
    # eval.keep_best: the best evaluation's weights, loaded after the checkpoint (which keeps the last, to resume)
    kept = run.parts["keep_best"].restore() if "keep_best" in run.parts else None
    final = run.evaluate(cfg.eval.final_episodes)
    expert_rate = expert_accomplish_rate(run.demos.metadata) if run.demos is not None else None
    save_policy(run.mirror.policy, os.path.join(run.run_dir, "policy.pt"), obs_dim=run.spec.obs_dim,
                action_dim=run.spec.action_dim, scenario=run.spec.name,
                frames=trainer.frames if kept is None else kept["frames"])  # the frames its weights had seen
    throughput = trainer.throughput
    history = run.evaluation.history
    summary = {
        **evaluation_summary(cfg, run.spec, method, final, expert_rate),
        "device": str(run.device),
        "auc": sum(h["accomplish_rate"] for h in history) / len(history) if history else None,
        "frames": trainer.frames,
        "updates": trainer.updates,
        "rounds": trainer.rounds,
        "frames_per_s": throughput["frames_per_s"],
        "collect_fps": throughput["collect_fps"],
        "updates_per_s": throughput["updates_per_s"],
        "wall_s": round(max(trainer.wall_time, 0.0), 1),
        "earlier_wall_s": round(trainer.elapsed_before, 1),  # a resumed run's earlier processes (total_wall_s)
        "run_dir": run.run_dir,
    }
    if kept is not None:
        summary["policy_from"] = {"kept": "best evaluation", **kept}
    run.logger.log({"frames": trainer.frames, "updates": trainer.updates,
                    **{f"test_{k}": v for k, v in final.items()}})
    if cfg.eval.video:
        from torchrl_csirl.launch.video import film_final_episode

        summary["videos"] = film_final_episode(run)
    curve = plot_learning_curve(history, os.path.join(run.run_dir, "learning_curve.png"), title=title)
    summary["plots"] = [os.fspath(curve)]
    return summary
