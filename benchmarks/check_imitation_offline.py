"""A sanity check of every imitation baseline at the recipe's sizes, without an environment.

On the ``merge`` scenario, each method (built by
:func:`~torchrl_csirl.trainers.make_imitation_method`, 2x256 networks with ``EgoRelativeFeatures``,
default hyperparameters except ValueDICE's actor rate, raised from 1e-5 to 1e-4 so that a few hundred
updates show a trend) is updated ``--updates`` times with its expert buffer holding the 25 shipped
demonstrations and its online buffer the same transitions with uniformly random actions. The
printed number is the mean squared distance between the policy's deterministic action and the
expert's on the expert states, before and after: every method should bring it down (its rewards or
objective favour the expert's actions over the random ones) clearly more than the control
``sqil-control`` (SQIL with expert reward 0: the same SAC updates without any imitation signal).
Not a benchmark of imitation quality: the agent never acts.

Usage::

    python benchmarks/check_imitation_offline.py [--updates 300] [--methods sqil-control,sqil,gail,dac,iqlearn,valuedice]

Prints one line per method and a final JSON line.
"""
from __future__ import annotations

import argparse
import json
import time

import torch
from bench_imitation_updates import build  # benchmarks/ is on the path when run as a script
from torchrl.envs.utils import ExplorationType, set_exploration_type

from torchrl_csirl.trainers import IMITATION_METHODS


def action_mse(actor, transitions) -> float:
    with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
        action = actor(transitions.select("observation").clone())["action"]
    return float((action - transitions["action"]).pow(2).mean())


#: hyperparameters that differ from the defaults, per checked name
OVERRIDES = {"valuedice": {"actor_lr": 1e-4}, "sqil-control": {"expert_reward": 0.0}}


def check(name: str, updates: int) -> dict[str, float]:
    torch.manual_seed(0)
    method, step, trainer, demos = build(name.removesuffix("-control"), OVERRIDES.get(name))
    before, start = action_mse(method.policy, demos.transitions()), time.perf_counter()
    for _ in range(updates):
        step(trainer)
        trainer.updates += 1
    return {"mse_before": round(before, 3), "mse_after": round(action_mse(method.policy, demos.transitions()), 3),
            "seconds": round(time.perf_counter() - start, 1)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--updates", type=int, default=300)
    parser.add_argument("--methods", default=",".join(("sqil-control", *IMITATION_METHODS)))
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    results = {}
    for name in args.methods.split(","):
        results[name] = check(name, args.updates)
        print(name, results[name], flush=True)
    print(json.dumps(results))


if __name__ == "__main__":
    main()
