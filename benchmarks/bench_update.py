"""Wall-clock cost of one SAC update and of one full CSIRL iteration (SAC + meta step).

``sac_update_ms``: EnsembleSACLoss forward + backward + two Adam steps + target update.
``csirl_iteration_ms``: a full CSIRL iteration with ``MetaRewardLoss(joint_sac_update=True)``:
one forward giving the SAC losses on the local reward ``r_m + r_w(s)`` and the meta-loss
(shared critic target / critic forward-backward), one backward, the three Adam steps
(critic, actor, reward) and the target update.
``csirl_sequential_ms``: the same work done the plain way: a full SAC update (reward
network evaluated without grad), then ``MetaRewardLoss`` forward/backward and the reward
Adam step. 5 critics 2x256, observation size 25, action size 2,
expert batch 32, ``torch.set_num_threads(2)``; warm-up then the median over iterations.
The two measurements are interleaved so that their ratio is robust to machine load.

Usage::

    python benchmarks/bench_update.py [--batch 256] [--iters 30] [--warmup 5]

Prints one final JSON line.
"""
from __future__ import annotations

import argparse
import json
import statistics
import time

import torch
from tensordict import TensorDict

from torchrl.objectives import SoftUpdate

from torchrl_csirl.modules import make_actor, make_qvalue, make_reward_network
from torchrl_csirl.objectives import EnsembleSACLoss, MetaRewardLoss

OBS_DIM, ACTION_DIM, EXPERT_BATCH = 25, 2, 32


def _online_batch(batch: int) -> TensorDict:
    return TensorDict(
        {
            "observation": torch.randn(batch, OBS_DIM),
            "action": torch.rand(batch, ACTION_DIM) * 2 - 1,
            ("next", "observation"): torch.randn(batch, OBS_DIM),
            ("next", "matching_reward"): torch.randn(batch, 1),
            ("next", "done"): torch.zeros(batch, 1, dtype=torch.bool),
            ("next", "terminated"): torch.zeros(batch, 1, dtype=torch.bool),
            ("next", "truncated"): torch.zeros(batch, 1, dtype=torch.bool),
        },
        [batch],
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--batch", type=int, default=256)
    parser.add_argument("--iters", type=int, default=30)
    parser.add_argument("--warmup", type=int, default=5)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument(
        "--no-fused-adam", dest="fused_adam", action="store_false",
        help="use torch's default (for-loop) Adam instead of fused=True",
    )
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)

    sac = EnsembleSACLoss(make_actor(OBS_DIM, ACTION_DIM), make_qvalue(OBS_DIM, ACTION_DIM))
    updater = SoftUpdate(sac, tau=0.005)
    reward_net = make_reward_network(OBS_DIM)
    meta = MetaRewardLoss(sac, reward_net)
    joint = MetaRewardLoss(sac, reward_net, joint_sac_update=True)
    adam = dict(fused=True) if args.fused_adam else {}
    optim_q = torch.optim.Adam(list(sac.qvalue_network_params.values(True, True)), lr=3e-4, **adam)
    optim_pi = torch.optim.Adam(list(sac.actor_network_params.values(True, True)), lr=3e-4, **adam)
    optim_w = torch.optim.Adam(reward_net.parameters(), lr=1e-3, **adam)

    online = _online_batch(args.batch)
    regularizer = _online_batch(args.batch)
    expert = TensorDict(
        {
            "observation": torch.randn(EXPERT_BATCH, OBS_DIM),
            "action": torch.rand(EXPERT_BATCH, ACTION_DIM) * 2 - 1,
        },
        [EXPERT_BATCH],
    )

    def sac_update(td: TensorDict) -> None:
        losses = sac(td)
        optim_q.zero_grad(set_to_none=True)
        optim_pi.zero_grad(set_to_none=True)
        (losses["loss_qvalue"] + losses["loss_actor"]).backward()
        optim_q.step()
        optim_pi.step()
        updater.step()

    def plain_step() -> None:
        td = online.copy()
        td["next", "reward"] = td["next", "matching_reward"]
        sac_update(td)

    def sequential_step() -> None:
        td = online.copy()
        with torch.no_grad():
            r_w = meta.intrinsic_reward(td)
        td["next", "reward"] = td["next", "matching_reward"] + r_w
        sac_update(td)
        losses = meta(online, expert, regularizer)
        optim_w.zero_grad(set_to_none=True)
        losses["loss_meta"].backward()
        optim_w.step()

    def csirl_step() -> None:
        losses = joint(online, expert, regularizer)
        for optim in (optim_q, optim_pi, optim_w):
            optim.zero_grad(set_to_none=True)
        (losses["loss_qvalue"] + losses["loss_actor"] + losses["loss_meta"]).backward()
        for optim in (optim_q, optim_pi, optim_w):
            optim.step()
        updater.step()

    def timed(fn) -> float:
        start = time.perf_counter()
        fn()
        return (time.perf_counter() - start) * 1e3

    for _ in range(args.warmup):
        plain_step()
        csirl_step()
        sequential_step()
    sac_ms, csirl_ms, seq_ms, ratios, seq_ratios = [], [], [], [], []
    for _ in range(args.iters):
        a = timed(plain_step)
        b = timed(csirl_step)
        c = timed(sequential_step)
        sac_ms.append(a)
        csirl_ms.append(b)
        seq_ms.append(c)
        ratios.append(b / a)
        seq_ratios.append(c / a)
    result = {
        "batch": args.batch,
        "threads": args.threads,
        "iters": args.iters,
        "fused_adam": args.fused_adam,
        "sac_update_ms": round(statistics.median(sac_ms), 2),
        "csirl_iteration_ms": round(statistics.median(csirl_ms), 2),
        "csirl_sequential_ms": round(statistics.median(seq_ms), 2),
        "sac_update_ms_min": round(min(sac_ms), 2),
        "csirl_iteration_ms_min": round(min(csirl_ms), 2),
        "csirl_sequential_ms_min": round(min(seq_ms), 2),
        "csirl_over_sac_ratio": round(statistics.median(ratios), 3),
        "sequential_over_sac_ratio": round(statistics.median(seq_ratios), 3),
    }
    print(json.dumps(result))


if __name__ == "__main__":
    main()
