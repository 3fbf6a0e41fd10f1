"""Collection throughput: frames/s of a collector with 1 vs 2 worker processes.

Both runs use the same scenario, the same CSIRL actor (``make_actor``, tanh-Gaussian, sampled
actions), the same number of frames and frames per batch, in the same process. Both collectors
are built and first gather one warm-up batch each (worker start-up, first resets, imports in the
spawned workers), which is excluded from the timing; then ``--frames`` frames are collected by
each, batches alternating between the two so that both see the same machine load.

Two ways to use worker processes:

* default, what the recipe does (``torchrl_csirl.run.builders.make_collector``): TorchRL's
  multi-process synchronous collector, ``Collector([env_fn] * W, policy, num_collectors=W,
  sync=True)``. Every worker holds its environments *and a copy of the policy* (weights in
  shared memory) and collects its share of the batch on its own; the main process only
  gathers the batches.
* ``--parallel-env``: one ``Collector`` over a ``ParallelEnv`` of W workers. The policy runs in
  the main process on the whole batch at every step, the workers only step the environments,
  and the two alternate (docs/performance.md explains why this scales worse). By default the
  env is our ``YieldingParallelEnv``; ``--spin`` measures TorchRL's own ``ParallelEnv``, whose
  main process spin-waits, ``--pipe`` its pipe mode. The main process runs with
  ``--main-threads`` torch threads (1: it must not compete with the workers for the cores).

Usage::

    python benchmarks/bench_collection.py [--scenario merge] [--frames 4000] [--frames-per-batch 1000]
                                          [--envs-per-worker 1] [--parallel-env [--main-threads 1]
                                          [--pipe] [--spin]] [--profile]

``--envs-per-worker k`` gives every worker process ``k`` environments (``make_serial_env``), for
both collectors alike. ``--profile`` (``--parallel-env`` only) also reports the policy's time.

Progress goes to stderr; the last line printed is a JSON object
``{"scenario", "frames", "fps_1_worker", "fps_2_workers", "speedup", "load_avg", ...}``.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from functools import partial

import torch
from tensordict.nn import TensorDictModuleBase
from torchrl.collectors import Collector
from torchrl.envs import ParallelEnv

from torchrl_csirl.modules import make_actor
from torchrl_csirl.tasks import SCENARIOS, YieldingParallelEnv, make_serial_env
from torchrl_csirl.trainers import shutdown_collector


def log(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


class TimedPolicy(TensorDictModuleBase):
    """Wraps a policy and accumulates the wall time spent in its forward (``--profile``)."""

    def __init__(self, policy: TensorDictModuleBase) -> None:
        super().__init__()
        self.policy = policy
        self.in_keys = policy.in_keys
        self.out_keys = policy.out_keys
        self.seconds = 0.0
        self.calls = 0

    def forward(self, tensordict):
        start = time.perf_counter()
        out = self.policy(tensordict)
        self.seconds += time.perf_counter() - start
        self.calls += 1
        return out


def _cpu_seconds(pids: list[int]) -> float:
    """user + system CPU seconds of processes (Linux ``/proc``; 0 where unreadable)."""
    tick = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
    total = 0.0
    for pid in pids:
        try:
            with open(f"/proc/{pid}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            total += (int(fields[11]) + int(fields[12])) / tick  # utime, stime
        except (OSError, IndexError, ValueError):
            pass
    return total


def make_parallel_env(
    scenario: str, workers: int, seed: int, main_threads: int | None, use_buffers: bool = True,
    spin: bool = False, envs_per_worker: int = 1,
) -> ParallelEnv:
    """``workers`` spawned processes of ``envs_per_worker`` scenario copies each.

    The worker factory ``partial(make_serial_env, ...)`` pickles.

    ``num_threads`` pins the main process's torch threads (ParallelEnv otherwise sets it to
    ``max(1, threads - workers)`` itself); each worker runs one thread (``num_sub_threads=1``).
    ``use_buffers=True`` (torchrl's default) exchanges data through shared memory and the main
    process *spin-polls* a shared done flag while the workers step (torchrl 0.14.1
    ``ParallelEnv._wait_for_workers``): it burns a full core, which on a 2-core machine is taken
    from the workers. ``use_buffers=False`` sends the data through the pipes and blocks on them.
    By default the env is our :class:`~torchrl_csirl.tasks.YieldingParallelEnv` (shared memory,
    but the main process sleeps between polls); ``spin=True`` measures TorchRL's own.
    """
    cls = ParallelEnv if spin else YieldingParallelEnv
    env = cls(
        workers,
        partial(make_serial_env, scenario, envs_per_worker),
        num_threads=main_threads,
        num_sub_threads=1,
        use_buffers=use_buffers,
    )
    env.set_seed(seed)
    return env


class Run:
    """One collector (``workers`` worker processes) and its timing."""

    def __init__(self, scenario: str, workers: int, frames_per_batch: int, seed: int,
                 main_threads: int | None, profile: bool, use_buffers: bool = True, spin: bool = False,
                 envs_per_worker: int = 1, parallel_env: bool = False) -> None:
        spec = SCENARIOS[scenario]
        torch.manual_seed(seed)  # same actor weights for every run
        policy = make_actor(spec.obs_dim, spec.action_dim)
        self.timed = TimedPolicy(policy) if profile else None
        self.name = f"{scenario} {workers}x{envs_per_worker}"
        if parallel_env:
            self.env = make_parallel_env(scenario, workers, seed, main_threads, use_buffers, spin, envs_per_worker)
            self.collector = Collector(
                self.env,
                self.timed if profile else policy,
                frames_per_batch=frames_per_batch,
                total_frames=-1,
                auto_register_policy_transforms=False,
            )
        else:
            self.env = None
            self.collector = Collector(
                [partial(make_serial_env, scenario, envs_per_worker)] * workers,
                policy,
                num_collectors=workers,
                sync=True,
                frames_per_batch=frames_per_batch,
                total_frames=-1,
                num_sub_threads=1,
                auto_register_policy_transforms=False,
            )
            self.collector.set_seed(seed)
        self.iterator = iter(self.collector)
        self.seconds = 0.0
        self.frames = 0
        self.cpu_seconds = 0.0

    def warm_up(self) -> None:
        """First batch: worker start-up and first resets, not timed."""
        start = time.perf_counter()
        batch = next(self.iterator)
        log(f"[{self.name}] warm-up batch of {batch.numel()} frames: {time.perf_counter() - start:.1f} s (not timed)")
        if self.timed is not None:
            self.timed.seconds, self.timed.calls = 0.0, 0

    def _pids(self) -> list[int]:
        procs = self.env._workers if self.env is not None else self.collector.procs
        return [os.getpid()] + [w.pid for w in procs if w.pid is not None]

    def timed_batch(self) -> None:
        pids = self._pids()
        cpu = _cpu_seconds(pids)
        start = time.perf_counter()
        batch = next(self.iterator)
        self.seconds += time.perf_counter() - start
        self.cpu_seconds += _cpu_seconds(pids) - cpu
        self.frames += batch.numel()

    def result(self) -> dict:
        out = {
            "frames": self.frames,
            "seconds": round(self.seconds, 3),
            "fps": round(self.frames / self.seconds, 1),
            # cores this collector (main + workers) actually got: < workers + 1 under contention
            "cores_used": round(self.cpu_seconds / self.seconds, 2),
        }
        if self.timed is not None:
            out["policy_seconds"] = round(self.timed.seconds, 3)
            out["policy_calls"] = self.timed.calls
            out["policy_share"] = round(self.timed.seconds / self.seconds, 3)
        return out

    def close(self) -> None:
        shutdown_collector(self.collector)
        if self.env is not None and not self.env.is_closed:
            self.env.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenario", default="merge", choices=sorted(SCENARIOS))
    parser.add_argument("--frames", type=int, default=4000)
    parser.add_argument("--frames-per-batch", type=int, default=1000)
    parser.add_argument("--envs-per-worker", type=int, default=1,
                        help="environments stepped by each worker process (both collectors)")
    parser.add_argument("--parallel-env", action="store_true",
                        help="a Collector over a ParallelEnv (policy in the main process) instead of the "
                             "multi-process collector (policy in every worker) the recipe uses")
    parser.add_argument("--main-threads", type=int, default=1,
                        help="torch threads of the main process (0: leave torch's default)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--profile", action="store_true", help="also report the time spent in the policy")
    parser.add_argument("--pipe", action="store_true",
                        help="ParallelEnv(use_buffers=False): data through the pipes, the main process blocks "
                             "instead of spin-waiting on shared memory (torchrl's default, use_buffers=True)")
    parser.add_argument("--spin", action="store_true",
                        help="TorchRL's own ParallelEnv, whose main process spin-waits for the workers "
                             "(default: torchrl_csirl's YieldingParallelEnv, which sleeps between polls)")
    args = parser.parse_args()
    if not args.parallel_env and (args.profile or args.pipe or args.spin):
        parser.error("--profile, --pipe and --spin measure the ParallelEnv collector: add --parallel-env")
    if args.main_threads > 0:
        torch.set_num_threads(args.main_threads)
    main_threads = args.main_threads if args.main_threads > 0 else None
    runs = {
        w: Run(args.scenario, w, args.frames_per_batch, args.seed, main_threads, args.profile, not args.pipe, args.spin,
               args.envs_per_worker, args.parallel_env)
        for w in (1, 2)
    }
    try:
        for run in runs.values():
            run.warm_up()
        load_before = os.getloadavg()[0]
        # batches alternate between the two collectors so that both see the same machine load
        for b in range(math.ceil(args.frames / args.frames_per_batch)):
            for w in ((1, 2) if b % 2 == 0 else (2, 1)):
                runs[w].timed_batch()
            log(f"batch {b + 1}: " + ", ".join(
                f"{r.name} {r.frames / r.seconds:.0f} fps ({r.cpu_seconds / r.seconds:.2f} cores)" for r in runs.values())
                + f" (load {os.getloadavg()[0]:.2f})")
        results = {w: run.result() for w, run in runs.items()}
    finally:
        for run in runs.values():
            run.close()
    summary = {
        "scenario": args.scenario,
        "frames": args.frames,
        "frames_per_batch": args.frames_per_batch,
        "envs_per_worker": args.envs_per_worker,
        "fps_1_worker": results[1]["fps"],
        "fps_2_workers": results[2]["fps"],
        "speedup": round(results[2]["fps"] / results[1]["fps"], 3),
        "cores_used_1_worker": results[1]["cores_used"],
        "cores_used_2_workers": results[2]["cores_used"],
        "collector": ("Collector over " + ("ParallelEnv" if args.spin else "YieldingParallelEnv")
                      if args.parallel_env else "Collector(num_collectors=W, sync=True)"),
        "use_buffers": not args.pipe,
        "main_threads": args.main_threads if args.main_threads > 0 else "default",
        "cpu_count": os.cpu_count(),
        "load_avg_before": round(load_before, 2),
        "load_avg": round(os.getloadavg()[0], 2),
    }
    if args.profile:
        summary["profile"] = {str(k): v for k, v in results.items()}
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
