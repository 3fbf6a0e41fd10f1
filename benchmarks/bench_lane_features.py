"""The cost of the lane-relative input map (``model.lane_features``) against an actor's own forward pass.

``python benchmarks/bench_lane_features.py [--batch 256] [--repeats 200]``: one thread, the roundabout's
road; prints the milliseconds per call of :class:`~torchrl_csirl.modules.LaneFeatures` and of the
default actor over the same batch, and their ratio (final JSON line).
"""
from __future__ import annotations

import argparse
import json
import time

import torch
from tensordict import TensorDict

from torchrl_csirl.modules import LaneFeatures, make_actor
from torchrl_csirl.tasks import SCENARIOS


def per_call_ms(fn, repeats: int) -> float:
    """Mean wall time of ``fn()`` in milliseconds, after one warm-up call."""
    fn()
    start = time.perf_counter()
    for _ in range(repeats):
        fn()
    return (time.perf_counter() - start) / repeats * 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=256)
    parser.add_argument("--repeats", type=int, default=200)
    args = parser.parse_args()
    torch.set_num_threads(1)
    torch.manual_seed(0)
    spec = SCENARIOS["roundabout"]
    lane = LaneFeatures.from_scenario(spec)
    actor = make_actor(spec.obs_dim, spec.action_dim)
    obs = torch.rand(args.batch, spec.obs_dim) * 0.4 - 0.2
    td = TensorDict({"observation": obs}, [args.batch])
    with torch.no_grad():
        lane_ms = per_call_ms(lambda: lane(obs), args.repeats)
        actor_ms = per_call_ms(lambda: actor(td.clone()), args.repeats)
    print(json.dumps({"batch": args.batch, "centre_points": len(lane._centres), "lane_features_ms": round(lane_ms, 3),
                      "actor_ms": round(actor_ms, 3), "ratio": round(lane_ms / actor_ms, 2)}))


if __name__ == "__main__":
    main()
