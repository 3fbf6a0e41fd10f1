"""Wall-clock cost of one update of each imitation baseline, with the recipe's network sizes.

Each method is built by :func:`~torchrl_csirl.trainers.make_imitation_method` on the ``merge``
scenario (observation 25, action 2, actor and critics 2x256 through ``EgoRelativeFeatures``, the
published batch sizes), its expert buffer holds the 25 shipped demonstrations and its online buffer
the same transitions with random actions (a stand-in for collected data; the cost does not depend on
the values). One update is whatever the method's update step does (sampling and buffer transforms
included: discriminator reward, absorbing states). ``torch.set_num_threads(threads)``; warm-up, then
the median over iterations, methods interleaved so that their ratios are robust to machine load.

Usage::

    python benchmarks/bench_imitation_updates.py [--iters 20] [--warmup 3] [--threads 2]

Prints one final JSON line ``{"<method>_update_ms": ..., ...}``.
"""
from __future__ import annotations

import argparse
import json
import statistics
import time
from types import SimpleNamespace

import torch
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
from torchrl.envs import Compose

from torchrl_csirl.data import load_expert_demonstrations
from torchrl_csirl.modules import EgoRelativeFeatures, make_actor, make_qvalue
from torchrl_csirl.tasks import SCENARIOS
from torchrl_csirl.trainers import IMITATION_METHODS, make_imitation_method


def build(name: str, hyperparameters: dict | None = None):
    """``(method, update_step, trainer stand-in, demonstrations)`` on merge, the online buffer holding
    the demonstrations' transitions with uniformly random actions."""
    spec = SCENARIOS["merge"]
    features = EgoRelativeFeatures.from_scenario(spec)
    method = make_imitation_method(
        name, make_actor(spec.obs_dim, spec.action_dim, input_features=features),
        lambda: make_qvalue(spec.obs_dim, spec.action_dim, input_features=features),
        obs_dim=spec.obs_dim, action_dim=spec.action_dim, hyperparameters=hyperparameters)
    demos = load_expert_demonstrations("merge", 25)
    expert = demos.as_replay_buffer(batch_size=256, transform=Compose(*method.expert_transforms))
    online = TensorDictReplayBuffer(storage=LazyTensorStorage(100_000), batch_size=256,
                                    transform=Compose(*method.online_transforms))
    transitions = demos.transitions().clone()
    transitions["action"] = torch.rand_like(transitions["action"]) * 2 - 1
    online.extend(transitions)
    trainer = SimpleNamespace(updates=0, frames=0, online_buffer=online)
    return method, method.make_update_step(online, expert), trainer, demos


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--iters", type=int, default=20)
    parser.add_argument("--warmup", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    steps = {name: build(name)[1:3] for name in IMITATION_METHODS}
    times: dict[str, list[float]] = {name: [] for name in steps}
    for i in range(args.warmup + args.iters):
        for name, (step, trainer) in steps.items():
            t = time.perf_counter()
            step(trainer)
            trainer.updates += 1
            if i >= args.warmup:
                times[name].append(time.perf_counter() - t)
    result = {f"{name}_update_ms": round(1000 * statistics.median(v), 1) for name, v in times.items()}
    result.update(threads=args.threads, iters=args.iters)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
