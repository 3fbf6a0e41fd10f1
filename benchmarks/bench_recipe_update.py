"""Cost of the recipe's own update steps, on transitions the recipe collected.

``bench_update.py`` times the learner alone on random tensors; this script builds the run the
README's main command builds (``recipes/csirl_highway.py``, default configuration, one worker
process), collects ``--frames`` transitions into its online buffer and then times, interleaved:

* ``sample_ms``: one training batch (online transitions mixed with expert ones, rewarded by the
  buffer's transforms: matching reward, intrinsic reward);
* ``sac_step_ms``: a plain update (sample, ensemble-SAC losses, backward, Adam, Polyak);
* ``joint_step_ms``: a CSIRL update with the meta-gradient (sample, expert batch, regulariser
  batch, joint SAC + meta losses, one backward, the Adam steps);
* ``mean_update_ms``: the average over ``csirl.meta_every`` updates, i.e. what one update costs
  in the training loop, and ``updates_per_s`` its inverse.

Each figure is the median over iterations; ``*_ms_mean`` keys give the means (what a training run's
updates-per-second measures).

Usage::

    python benchmarks/bench_recipe_update.py [--iters 40] [key=value overrides of the recipe]

Prints one final JSON line.
"""
from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time

import torch

from torchrl_csirl.methods import csirl
from torchrl_csirl.run.run import resolve_device


def _fill(run, frames: int) -> None:
    collected = 0
    for batch in run.collector:
        run.online_buffer.extend(batch.reshape(-1))
        collected += batch.numel()
        if collected >= frames:
            return


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--iters", type=int, default=40)
    parser.add_argument("--warmup", type=int, default=5)
    parser.add_argument("--frames", type=int, default=3000, help="transitions collected before timing")
    parser.add_argument("overrides", nargs="*", help="recipe configuration, key=value")
    args = parser.parse_args()
    out_dir = tempfile.mkdtemp(prefix="bench_recipe_update-")
    cfg = csirl.load_config([
        "collector.num_workers=1", "logger.backend=none", "logger.progress_bar=false",
        f"logger.output_dir={out_dir}", *args.overrides,
    ])
    run = csirl.make_trainer(cfg, out_dir)
    try:
        _fill(run, args.frames)
        trainer, update = run.trainer, run.trainer.update_step
        sac_update = getattr(update, "sac_update", update)
        meta_every = getattr(update, "meta_every", None)

        def sample() -> None:
            sac_update.sample(trainer)

        def sac_step() -> None:
            trainer.updates = 1  # not a multiple of meta_every: a plain step
            trainer._run_updates(1)  # the trainer's own update (inside its input-map memo)

        def joint_step() -> None:
            trainer.updates = 0  # a multiple of meta_every: the meta-gradient step
            trainer._run_updates(1)

        sync = torch.cuda.synchronize if resolve_device(cfg.device).type == "cuda" else None
        steps = {"sample": sample, "sac_step": sac_step}
        if meta_every is not None:
            steps["joint_step"] = joint_step
        times: dict[str, list[float]] = {name: [] for name in steps}
        for i in range(args.warmup + args.iters):
            for name, step in steps.items():
                start = time.perf_counter()
                step()
                if sync is not None:
                    sync()  # the GPU works asynchronously: time the work, not its launch
                if i >= args.warmup:
                    times[name].append((time.perf_counter() - start) * 1e3)
        result = {"threads": torch.get_num_threads(), "device": "cuda" if sync else "cpu", "iters": args.iters,
                  "overrides": args.overrides,
                  "batch": cfg.replay_buffer.batch_size, "meta_every": meta_every}
        result.update({f"{name}_ms": round(statistics.median(ts), 2) for name, ts in times.items()})
        result.update({f"{name}_ms_mean": round(statistics.mean(ts), 2) for name, ts in times.items()})
        for suffix in ("", "_mean"):
            if meta_every is None:
                mean = result[f"sac_step_ms{suffix}"]
            else:
                mean = (result[f"joint_step_ms{suffix}"] + (meta_every - 1) * result[f"sac_step_ms{suffix}"]) / meta_every
            result[f"mean_update_ms{suffix}"] = round(mean, 2)
        result["updates_per_s"] = round(1e3 / result["mean_update_ms"], 1)
        print(json.dumps(result))
    finally:
        run.close()


if __name__ == "__main__":
    main()
