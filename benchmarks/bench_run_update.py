"""The README run's mean update against ``bench_update.py``'s same mix, alternated.

``bench_update.py`` times the learner alone on random tensors; the README's run
(``recipes/csirl_highway.py``) also samples through its buffer transforms, draws expert and
regulariser batches, maps ego-relative inputs, keeps two collector worker processes and a 1 M-slot
storage. This script runs, ``--rounds`` times and alternated so that the machine's drift hits both:

* ``bench_update.py --iters N``: ``mix_ms``, the mean update of the recipe's mix, one CSIRL
  iteration every ``meta_every`` (2) updates and a plain SAC update otherwise;
* ``bench_recipe_update.py --iters N``: ``recipe_ms``, the same mix of the recipe's own steps
  (sampling through the buffer transforms, expert and regulariser batches, ego-relative inputs);
* the README's run, shortened to ``--frames`` frames (its default configuration otherwise; 2 test
  episodes, no video): ``run_ms``, its learner time per update (``1 / updates_per_s`` of its
  ``summary.json``: the updates only, collection and evaluation excluded).

``recipe_over_mix`` and ``run_over_mix`` are the medians over rounds of ``recipe_ms / mix_ms`` and
``run_ms / mix_ms``.

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
META_EVERY = 2  # the recipe's csirl.meta_every default


def _last_json_line(text: str) -> dict:
    for line in reversed(text.splitlines()):
        if line.startswith("{"):
            return json.loads(line)
    raise RuntimeError(f"no JSON line in the output:\n{text[-2000:]}")


def bench_mix_ms(iters: int) -> float:
    """``bench_update.py``'s mean update over the recipe's mix of CSIRL iterations and SAC updates."""
    out = subprocess.run([sys.executable, os.path.join(ROOT, "benchmarks", "bench_update.py"), "--iters", str(iters)],
                         capture_output=True, text=True, check=True, cwd=ROOT).stdout
    result = _last_json_line(out)
    return (result["csirl_iteration_ms"] + (META_EVERY - 1) * result["sac_update_ms"]) / META_EVERY


def recipe_mix_ms(iters: int) -> float:
    """``bench_recipe_update.py``'s mean update (the recipe's own steps, same mix)."""
    out = subprocess.run([sys.executable, os.path.join(ROOT, "benchmarks", "bench_recipe_update.py"), "--iters", str(iters)],
                         capture_output=True, text=True, check=True, cwd=ROOT).stdout
    return _last_json_line(out)["mean_update_ms"]


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
    parser.add_argument("--iters", type=int, default=40, help="bench_update.py's timed iterations")
    args = parser.parse_args()
    out_dir = tempfile.mkdtemp(prefix="bench_run_update-")
    mix, recipe, run = [], [], []
    for i in range(args.rounds):
        mix.append(bench_mix_ms(args.iters))
        recipe.append(recipe_mix_ms(args.iters))
        run.append(run_update_ms(args.frames, out_dir, f"round{i}"))
        print(f"round {i}: learner alone {mix[-1]:.1f} ms, recipe's steps {recipe[-1]:.1f} ms, run {run[-1]:.1f} ms",
              file=sys.stderr, flush=True)
    print(json.dumps({
        "rounds": args.rounds, "frames": args.frames,
        "mix_ms": [round(x, 1) for x in mix], "recipe_ms": [round(x, 1) for x in recipe],
        "run_ms": [round(x, 1) for x in run],
        "recipe_over_mix": round(statistics.median(r / m for r, m in zip(recipe, mix)), 3),
        "run_over_mix": round(statistics.median(r / m for r, m in zip(run, mix)), 3),
    }))


if __name__ == "__main__":
    main()
