"""The target critics' soft update: TorchRL's ``SoftUpdate`` against ``FusedSoftUpdate``, alternated in one process.

Both update the targets of one CSIRL learner (five 2x256 critics, ``make_csirl_learner(25, 2)``); the
fused one gives the same targets bit for bit (``tests/test_target_update.py``). Each round times a block of
``--block`` steps of each; the JSON line gives the medians per step and ``fused_over_stock``, the median of the
per-round ratios.

Usage::

    python benchmarks/bench_target_update.py --rounds 30 --threads 1

Prints one final JSON line.
"""
from __future__ import annotations

import argparse
import json
import statistics

import torch
from bench_lane_features import per_call_ms
from torchrl.objectives import SoftUpdate

from torchrl_csirl.objectives import FusedSoftUpdate, make_csirl_learner


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=30)
    parser.add_argument("--block", type=int, default=50, help="steps per timed block")
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    sac = make_csirl_learner(25, 2).sac
    stock, fused = SoftUpdate(sac, tau=0.005), FusedSoftUpdate(sac, tau=0.005)
    stock_ms, fused_ms = [], []
    for _ in range(args.rounds):
        stock_ms.append(per_call_ms(stock.step, args.block))
        fused_ms.append(per_call_ms(fused.step, args.block))
    ratios = [f / s for f, s in zip(fused_ms, stock_ms)]
    print(json.dumps({
        "threads": args.threads, "rounds": args.rounds, "block": args.block,
        "stock_ms": round(statistics.median(stock_ms), 3), "fused_ms": round(statistics.median(fused_ms), 3),
        "fused_over_stock": round(statistics.median(ratios), 3),
    }))


if __name__ == "__main__":
    main()
