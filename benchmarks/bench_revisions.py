"""``bench_update.py``'s learner steps timed in two checkouts, alternated step by step.

Each checkout (``--before``: e.g. a ``git worktree`` of an older commit; ``--after``: this one)
runs in its own worker process, importing its own ``torchrl_csirl`` and its own
``benchmarks/bench_update.py`` learner. The driver asks the two workers in turn for one timed step
(a SAC update, a CSIRL iteration), so both sides see the same machine load, and reports the
medians and the median of the per-round ratios ``after / before`` (robust to load drift).
Only one worker computes at a time; each uses ``--threads`` torch threads, and the driver pauses
``--pause`` seconds before each step, so that the other worker's OpenMP threads have stopped
spinning (without it, two threads per worker measured 1.3-1.6x slower than ``bench_update.py``).

``--recipe`` times the recipe's own updates instead (``bench_recipe_update.py``'s steps: the README's
run, default configuration, after collecting ``--frames`` transitions; one update of the trainer, a plain
one and a CSIRL one, sampling and input maps included), each checkout with its own trainer.

Usage::

    git worktree add /tmp/base 58670cb
    python benchmarks/bench_revisions.py --before /tmp/base --batch 256
    python benchmarks/bench_revisions.py --before /tmp/base --batch 8 --hidden 8 --threads 1  # overhead
    python benchmarks/bench_revisions.py --before /tmp/base --recipe                          # the run's updates

Prints one final JSON line.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

import torch

_STEPS = {"sac_update": "plain_step", "csirl_iteration": "csirl_step"}

_WORKER = r"""
import sys, time, torch
import bench_update
batch, threads, warmup, hidden = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
if hidden:  # smaller networks: what is left is the per-call overhead
    make_actor, make_qvalue = bench_update.make_actor, bench_update.make_qvalue
    bench_update.make_actor = lambda obs, act: make_actor(obs, act, hidden=(hidden, hidden))
    bench_update.make_qvalue = lambda obs, act: make_qvalue(obs, act, hidden=(hidden, hidden))
torch.set_num_threads(threads)
learner = bench_update._Learner(True, True, batch, torch.device("cpu"))
steps = sys.argv[5:]
for _ in range(warmup):
    for step in steps:
        getattr(learner, step)()
print("ready", flush=True)
for line in sys.stdin:
    step = getattr(learner, line.strip())
    start = time.perf_counter()
    step()
    print((time.perf_counter() - start) * 1e3, flush=True)
"""


_RECIPE_STEPS = {"sac_step": "sac_step", "joint_step": "joint_step"}

_RECIPE_WORKER = r"""
import sys, tempfile, time, torch
from bench_recipe_update import _fill
from torchrl_csirl.methods import csirl
frames, threads, warmup = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
out = tempfile.mkdtemp(prefix="bench_revisions-")
cfg = csirl.load_config(["collector.num_workers=1", "logger.backend=none", "logger.progress_bar=false",
                         f"logger.output_dir={out}", f"collector.main_threads={threads}"])
run = csirl.make_trainer(cfg, out)
_fill(run, frames)
trainer = run.trainer
def step(updates):  # updates % meta_every decides the kind: 1 a plain update, 0 a CSIRL one
    trainer.updates = updates
    trainer._run_updates(1)
steps = {"sac_step": lambda: step(1), "joint_step": lambda: step(0)}
for _ in range(warmup):
    for fn in steps.values():
        fn()
print("ready", flush=True)
for line in sys.stdin:
    fn = steps[line.strip()]
    start = time.perf_counter()
    fn()
    print((time.perf_counter() - start) * 1e3, flush=True)
run.close()
"""


def _worker(tree: str, args: argparse.Namespace) -> subprocess.Popen:
    # the checkout's package and its benchmarks/ (bench_update) first on the worker's path
    env = dict(os.environ, PYTHONPATH=os.pathsep.join((tree, os.path.join(tree, "benchmarks"))), RL_WARNINGS="0")
    if args.recipe:
        cmd = [sys.executable, "-c", _RECIPE_WORKER, *map(str, (args.frames, args.threads, args.warmup))]
    else:
        cmd = [sys.executable, "-c", _WORKER, *map(str, (args.batch, args.threads, args.warmup, args.hidden)),
               *_STEPS.values()]
    proc = subprocess.Popen(cmd, cwd=tree, env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    for line in proc.stdout:  # log lines (TorchRL's logger writes to stdout) come before it
        if line.strip() == "ready":
            return proc
    raise RuntimeError(f"the worker in {tree} did not start")


def _ask(proc: subprocess.Popen, step: str) -> float:
    proc.stdin.write(step + "\n")
    proc.stdin.flush()
    return float(proc.stdout.readline())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--before", required=True, help="checkout timed as 'before'")
    parser.add_argument("--after", default=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    parser.add_argument("--batch", type=int, default=256)
    parser.add_argument("--iters", type=int, default=30)
    parser.add_argument("--warmup", type=int, default=5)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--pause", type=float, default=0.05, help="seconds between two timed steps")
    parser.add_argument("--hidden", type=int, default=0,
                        help="hidden width of the actor and critics (0: bench_update.py's 256)")
    parser.add_argument("--recipe", action="store_true", help="time the recipe's updates (the README's run)")
    parser.add_argument("--frames", type=int, default=3000, help="with --recipe: transitions collected first")
    args = parser.parse_args()
    steps = _RECIPE_STEPS if args.recipe else _STEPS
    workers = {side: _worker(getattr(args, side), args) for side in ("before", "after")}
    times = {side: {name: [] for name in steps} for side in workers}
    try:
        for _ in range(args.iters):
            for name, step in steps.items():
                for side, proc in workers.items():
                    time.sleep(args.pause)  # the other worker's OpenMP threads stop spinning
                    times[side][name].append(_ask(proc, step))
    finally:
        for proc in workers.values():
            proc.stdin.close()
            proc.wait()
    sizes = {"frames": args.frames} if args.recipe else {"batch": args.batch, "hidden": args.hidden or 256}
    result = {"recipe": args.recipe, **sizes, "threads": args.threads, "iters": args.iters,
              "cpu": torch.cpu.get_capabilities().get("cpu_name")}
    for name in steps:
        before, after = times["before"][name], times["after"][name]
        result[f"{name}_ms_before"] = round(statistics.median(before), 2)
        result[f"{name}_ms_after"] = round(statistics.median(after), 2)
        result[f"{name}_after_over_before"] = round(statistics.median(a / b for a, b in zip(after, before)), 3)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
