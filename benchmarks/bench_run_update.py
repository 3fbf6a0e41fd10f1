"""The README run's mean update against ``bench_update.py``'s same mix, alternated.

``bench_update.py`` times the learner alone on random tensors; the README's run
(``recipes/csirl_highway.py``) also samples through its buffer transforms, draws expert and
regulariser batches, maps ego-relative inputs, keeps two collector worker processes and a 1 M-slot
storage. This script runs, ``--rounds`` times and alternated so that the machine's drift hits both:

* ``bench_recipe_update.py --iters N``: ``recipe_ms_*``, the recipe's own steps in its mix
  (sampling through the buffer transforms, expert and regulariser batches, ego-relative inputs);
* ``bench_update.py --iters N``: ``mix_ms_*``, the learner alone in the same mix, one CSIRL
  iteration every ``csirl.meta_every`` updates (as ``bench_recipe_update.py`` reports it) and a
  plain SAC update otherwise;
* the README's run, shortened to ``--frames`` frames (its default configuration otherwise; 2 test
  episodes, no video): ``run_ms``, its learner time per update (``1 / updates_per_s`` of its
  ``summary.json``: the updates only, collection and evaluation excluded).

The benchmarks' figures come as medians over iterations and as means; the run's is a mean (total
learner time over updates), so ``run_over_mix_mean`` compares like with like. ``*_over_mix_*`` are
medians over rounds of the per-round ratios.

Usage::

    python benchmarks/bench_run_update.py [--rounds 2] [--frames 8500] [--iters 40]

Prints one final JSON line.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _last_json_line(text: str) -> dict:
    for line in reversed(text.splitlines()):
        if line.startswith("{"):
            return json.loads(line)
    raise RuntimeError(f"no JSON line in the output:\n{text[-2000:]}")


def _benchmark_json(script: str, iters: int) -> dict:
    """The final JSON line of ``benchmarks/<script> --iters <iters>``."""
    out = subprocess.run([sys.executable, os.path.join(ROOT, "benchmarks", script), "--iters", str(iters)],
                         capture_output=True, text=True, check=True, cwd=ROOT).stdout
    return _last_json_line(out)


def recipe_mix_ms(iters: int) -> tuple[tuple[float, float], int]:
    """``bench_recipe_update.py``'s update (the recipe's own steps): (median, mean), and the recipe's
    ``csirl.meta_every``."""
    result = _benchmark_json("bench_recipe_update.py", iters)
    return (result["mean_update_ms"], result["mean_update_ms_mean"]), result["meta_every"]


def bench_mix_ms(iters: int, meta_every: int) -> tuple[float, float]:
    """``bench_update.py``'s update over the recipe's mix (a CSIRL iteration every ``meta_every``
    updates, SAC updates otherwise): (median, mean)."""
    result = _benchmark_json("bench_update.py", iters)
    return tuple((result[f"csirl_iteration_ms{s}"] + (meta_every - 1) * result[f"sac_update_ms{s}"]) / meta_every
                 for s in ("", "_mean"))


def run_update_ms(frames: int, out_dir: str, name: str) -> float:
    """Learner milliseconds per update of the README's run, shortened to ``frames`` frames."""
    subprocess.run(
        [sys.executable, os.path.join(ROOT, "recipes", "csirl_highway.py"), f"collector.total_frames={frames}",
         "logger.backend=csv", f"logger.output_dir={out_dir}", f"logger.exp_name={name}", "logger.progress_bar=false",
         "eval.final_episodes=2", "eval.video=false"],
        capture_output=True, text=True, check=True, cwd=ROOT,
    )
    with open(os.path.join(out_dir, name, "summary.json")) as f:
        return 1e3 / json.load(f)["updates_per_s"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--frames", type=int, default=8500, help="the shortened run's frames (8 500: two rounds)")
    parser.add_argument("--iters", type=int, default=40, help="timed iterations of each benchmark script")
    args = parser.parse_args()
    out_dir = tempfile.mkdtemp(prefix="bench_run_update-")
    mix, recipe, run = [], [], []
    for i in range(args.rounds):
        recipe_ms, meta_every = recipe_mix_ms(args.iters)
        recipe.append(recipe_ms)
        mix.append(bench_mix_ms(args.iters, meta_every))
        run.append(run_update_ms(args.frames, out_dir, f"round{i}"))
        print(f"round {i}: learner alone {mix[-1][0]:.1f} ms (mean {mix[-1][1]:.1f}), recipe's steps {recipe[-1][0]:.1f} "
              f"ms (mean {recipe[-1][1]:.1f}), run {run[-1]:.1f} ms (a mean)", file=sys.stderr, flush=True)
    result = {"rounds": args.rounds, "frames": args.frames, "run_ms": [round(x, 1) for x in run]}
    for k, stat in enumerate(("median", "mean")):
        result[f"mix_ms_{stat}"] = [round(x[k], 1) for x in mix]
        result[f"recipe_ms_{stat}"] = [round(x[k], 1) for x in recipe]
        result[f"recipe_over_mix_{stat}"] = round(statistics.median(r[k] / m[k] for r, m in zip(recipe, mix)), 3)
        result[f"run_over_mix_{stat}"] = round(statistics.median(r / m[k] for r, m in zip(run, mix)), 3)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
