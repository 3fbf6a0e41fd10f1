"""A run's environments and collector: the workers' environment factories, whole episodes per batch, the
multi-process synchronous collector, the evaluation environment, and the CPU mirror of a learner's policy on
another device (the ``collector`` section)."""
from __future__ import annotations

import atexit
import copy
import os
import weakref
from functools import partial
from typing import Any, Callable

import torch
from omegaconf import DictConfig
from tensordict import TensorDict
from torch import nn
from torchrl.collectors import BaseCollector, Collector
from torchrl.envs import EnvBase

from torchrl_csirl.run.config import ConfigError
from torchrl_csirl.tasks import SCENARIOS, ScenarioSpec, TaskSpec, env_factory, make_serial_env, resolve_scenario  # noqa: F401 - SCENARIOS: doctests
from torchrl_csirl.tasks import make_env as make_scenario_env
from torchrl_csirl.trainers import WorkerErrorLog, ignoring_interrupts, shutdown_collector, start_collector

MAX_ENVS_PER_WORKER = 4


# ---------------------------------------------------------------------------------------- envs
def check_collector(collector: DictConfig) -> None:
    """The checks that involve several ``collector.*`` keys (before any worker starts)."""
    fpb, workers, k = collector.frames_per_batch, collector.num_workers, collector.envs_per_worker
    if fpb % workers:
        raise ConfigError(f"collector.frames_per_batch={fpb}: must be a multiple of collector.num_workers ({workers})")
    if k is not None and fpb % (workers * k):
        raise ConfigError(f"collector.frames_per_batch={fpb}: must be a multiple of "
                          f"collector.num_workers x collector.envs_per_worker ({workers} x {k})")


def check_collector_config(cfg: DictConfig) -> None:
    """:func:`check_collector` on a recipe configuration's ``collector`` section (a :class:`~torchrl_csirl.run.recipes.Recipe` check)."""
    check_collector(cfg.collector)


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
        torchrl_csirl.run.config.ConfigError: collector.frames_per_batch=100: each of the 2 environments steps 50 ...
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


def use_main_threads(collector: DictConfig) -> int:
    """Applies ``collector.main_threads`` to this process (``torch.set_num_threads``) from the run's first step, so
    that the work before the collector starts (an actor's warm start, the demonstrations' preparation) keeps to it;
    unset, torch's default stays. Returns the threads in use.

    Two runs sharing two cores with one thread each, but a warm start on torch's default two threads, spin in
    OpenMP's barriers: 30 000 behavioural-cloning updates took over 30 minutes instead of 3.

    Examples:
        >>> from omegaconf import OmegaConf
        >>> before = torch.get_num_threads()
        >>> use_main_threads(OmegaConf.create({"main_threads": 1}))
        1
        >>> torch.set_num_threads(before)
    """
    threads = collector.get("main_threads")
    if threads:
        torch.set_num_threads(int(threads))
    return torch.get_num_threads()


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
