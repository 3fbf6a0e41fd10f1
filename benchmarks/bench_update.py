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
The measurements are interleaved so that their ratios are robust to machine load.
Medians are the headline figures; ``*_mean`` keys give the means (what a training run's
updates-per-second measures) and ``*_min`` the minima.
``--reference`` also times, interleaved in the same process, the same learner with the critics
evaluated by SACLoss's ``torch.vmap`` and the losses on SACLoss's own path (``reference_*`` keys
and the ``*_speedup`` ratios). ``--stock-losses`` times the SACLoss path of the losses
(``EnsembleSACLoss(fused=False)``) with the fused critics. ``--meta-gradient jvp`` computes the
meta-gradient with ``MetaRewardLoss(meta_gradient="jvp")`` and also times, interleaved, the
CSIRL iteration of the same learner on the double backward (``against_*`` keys and
``jvp_over_double_backward``, the median of the per-round ratios); ``--against M`` sets the
compared path (``--meta-gradient double_backward --against double_backward``: the noise).
``--precision bf16`` runs the losses' forward passes under bfloat16 autocast
(:class:`~torchrl_csirl.modules.LearnerPrecision`, ``optim.precision``) and also times, interleaved,
the same learner in float32 (``fp32_*`` keys; ``bf16_speedup_sac`` / ``bf16_speedup_csirl``, the
medians of the per-round ratios fp32 / bf16).

Usage::

    python benchmarks/bench_update.py [--batch 256] [--iters 30] [--warmup 5] [--reference]
    python benchmarks/bench_update.py --device cuda     # the learner on a GPU
    python benchmarks/bench_update.py --meta-gradient jvp --iters 60   # jvp against the double backward
    python benchmarks/bench_update.py --precision bf16 --iters 60      # bf16 against fp32, alternated

Prints one final JSON line.
"""
from __future__ import annotations

import argparse
import json
import statistics
import time

import torch
from tensordict import TensorDict

from torchrl_csirl.modules import LearnerPrecision, make_actor, make_qvalue, make_reward_network
from torchrl_csirl.objectives import EnsembleSACLoss, FusedSoftUpdate, MetaRewardLoss

OBS_DIM, ACTION_DIM, EXPERT_BATCH = 25, 2, 32


def _online_batch(batch: int, device: torch.device) -> TensorDict:
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
        device=device,
    )


class _Learner:
    """One learner (ensemble SAC, reward net, optimisers) and its three timed steps."""

    def __init__(
        self,
        fused_qvalue: bool,
        fused_adam: bool,
        batch: int,
        device: torch.device,
        fused: bool | None = None,
        meta_gradient: str = "double_backward",
        precision: LearnerPrecision | None = None,
    ) -> None:
        torch.manual_seed(0)
        self.precision = precision or LearnerPrecision(device_type=device.type)
        self.sac = sac = EnsembleSACLoss(
            make_actor(OBS_DIM, ACTION_DIM), make_qvalue(OBS_DIM, ACTION_DIM), fused_qvalue=fused_qvalue, fused=fused
        ).to(device)
        self.updater = FusedSoftUpdate(sac, tau=0.005)
        self.reward_net = make_reward_network(OBS_DIM).to(device)
        self.meta = MetaRewardLoss(sac, self.reward_net, meta_gradient=meta_gradient)
        self.joint = MetaRewardLoss(sac, self.reward_net, joint_sac_update=True, meta_gradient=meta_gradient)
        adam = {"fused": True} if fused_adam else {}
        self.optim_q = torch.optim.Adam(list(sac.qvalue_network_params.values(True, True)), lr=3e-4, **adam)
        self.optim_pi = torch.optim.Adam(list(sac.actor_network_params.values(True, True)), lr=3e-4, **adam)
        self.optim_w = torch.optim.Adam(self.reward_net.parameters(), lr=1e-3, **adam)
        self.online = _online_batch(batch, device)
        self.regularizer = _online_batch(batch, device)
        self.expert = TensorDict(
            {
                "observation": torch.randn(EXPERT_BATCH, OBS_DIM),
                "action": torch.rand(EXPERT_BATCH, ACTION_DIM) * 2 - 1,
            },
            [EXPERT_BATCH],
            device=device,
        )

    def _sac_update(self, td: TensorDict) -> None:
        with self.precision.autocast():
            losses = self.sac(td)
        self.optim_q.zero_grad(set_to_none=True)
        self.optim_pi.zero_grad(set_to_none=True)
        (losses["loss_qvalue"] + losses["loss_actor"]).backward()
        self.optim_q.step()
        self.optim_pi.step()
        self.updater.step()

    def plain_step(self) -> None:
        td = self.online.copy()
        td["next", "reward"] = td["next", "matching_reward"]
        self._sac_update(td)

    def sequential_step(self) -> None:
        td = self.online.copy()
        with torch.no_grad():
            r_w = self.meta.intrinsic_reward(td)
        td["next", "reward"] = td["next", "matching_reward"] + r_w
        self._sac_update(td)
        with self.precision.autocast():
            losses = self.meta(self.online, self.expert, self.regularizer)
        self.optim_w.zero_grad(set_to_none=True)
        losses["loss_meta"].backward()
        self.optim_w.step()

    def csirl_step(self) -> None:
        with self.precision.autocast():
            losses = self.joint(self.online, self.expert, self.regularizer)
        optims = (self.optim_q, self.optim_pi, self.optim_w)
        for optim in optims:
            optim.zero_grad(set_to_none=True)
        (losses["loss_qvalue"] + losses["loss_actor"] + losses["loss_meta"]).backward()
        for optim in optims:
            optim.step()
        self.updater.step()


def _timed(fn, device: torch.device) -> float:
    start = time.perf_counter()
    fn()
    if device.type == "cuda":
        torch.cuda.synchronize(device)
    return (time.perf_counter() - start) * 1e3


def _summary(prefix: str, times: dict[str, list[float]]) -> dict[str, float]:
    if set(times) == {"csirl"}:
        return {f"{prefix}csirl_iteration_ms": round(statistics.median(times["csirl"]), 2)}
    if set(times) == {"plain", "csirl"}:
        return {f"{prefix}sac_update_ms": round(statistics.median(times["plain"]), 2),
                f"{prefix}csirl_iteration_ms": round(statistics.median(times["csirl"]), 2)}
    sac_ms, csirl_ms, seq_ms = times["plain"], times["csirl"], times["sequential"]
    return {
        f"{prefix}sac_update_ms": round(statistics.median(sac_ms), 2),
        f"{prefix}csirl_iteration_ms": round(statistics.median(csirl_ms), 2),
        f"{prefix}csirl_sequential_ms": round(statistics.median(seq_ms), 2),
        f"{prefix}sac_update_ms_mean": round(statistics.mean(sac_ms), 2),
        f"{prefix}csirl_iteration_ms_mean": round(statistics.mean(csirl_ms), 2),
        f"{prefix}sac_update_ms_min": round(min(sac_ms), 2),
        f"{prefix}csirl_iteration_ms_min": round(min(csirl_ms), 2),
        f"{prefix}csirl_sequential_ms_min": round(min(seq_ms), 2),
        f"{prefix}csirl_over_sac_ratio": round(statistics.median(b / a for a, b in zip(sac_ms, csirl_ms)), 3),
        f"{prefix}sequential_over_sac_ratio": round(statistics.median(c / a for a, c in zip(sac_ms, seq_ms)), 3),
    }


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
    parser.add_argument(
        "--vmap-critics", dest="fused_qvalue", action="store_false",
        help="evaluate the critic ensemble with SACLoss's torch.vmap instead of the fused ensemble",
    )
    parser.add_argument(
        "--stock-losses", dest="fused", action="store_false", default=None,
        help="compute the SAC losses on SACLoss's own path (EnsembleSACLoss(fused=False))",
    )
    parser.add_argument(
        "--reference", action="store_true",
        help="also time the vmapped-critic learner (reference_* keys), interleaved in this process",
    )
    parser.add_argument(
        "--meta-gradient", default="double_backward", choices=("double_backward", "jvp"),
        help="MetaRewardLoss(meta_gradient=...); jvp also times the double backward's CSIRL iteration, interleaved",
    )
    parser.add_argument(
        "--against", default=None, choices=("double_backward", "jvp"),
        help="time the CSIRL iteration of this meta-gradient path too, interleaved (default: double_backward "
             "when --meta-gradient is jvp)",
    )
    parser.add_argument("--device", default="cpu", help="where the learner runs (cpu, cuda, cuda:1...)")
    parser.add_argument(
        "--precision", default="fp32", choices=("fp32", "bf16", "auto"),
        help="optim.precision of the learner; bf16 also times the fp32 learner, interleaved (fp32_* keys)",
    )
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    device = torch.device(args.device)
    precision = LearnerPrecision.from_setting(args.precision, device)

    learners = {"": _Learner(args.fused_qvalue, args.fused_adam, args.batch, device, args.fused, args.meta_gradient,
                             precision)}
    steps = {"": ("plain", "csirl", "sequential")}
    if precision.dtype != torch.float32:  # the same learner (same seed) in float32
        learners["fp32_"] = _Learner(args.fused_qvalue, args.fused_adam, args.batch, device, args.fused,
                                     args.meta_gradient)
        steps["fp32_"] = ("plain", "csirl")
    if args.reference:
        learners["reference_"] = _Learner(False, args.fused_adam, args.batch, device, meta_gradient=args.meta_gradient)
        steps["reference_"] = steps[""]
    against = args.against or ("double_backward" if args.meta_gradient != "double_backward" else None)
    if against is not None:  # the same learner (same seed) on the other path
        learners["against_"] = _Learner(args.fused_qvalue, args.fused_adam, args.batch, device, args.fused, against)
        steps["against_"] = ("csirl",)
    for _ in range(args.warmup):
        for prefix, learner in learners.items():
            for step in steps[prefix]:
                getattr(learner, f"{step}_step")()
    times = {prefix: {step: [] for step in steps[prefix]} for prefix in learners}
    for _ in range(args.iters):
        for prefix, learner in learners.items():
            for step in steps[prefix]:
                times[prefix][step].append(_timed(getattr(learner, f"{step}_step"), device))
    result = {
        "batch": args.batch,
        "device": str(device),
        "threads": args.threads,
        "iters": args.iters,
        "fused_adam": args.fused_adam,
        "fused_qvalue": learners[""].sac.fused_qvalue,
        "fused_losses": learners[""].sac.fused,
        "meta_gradient": args.meta_gradient,
        "precision": precision.name,
        "cpu": torch.cpu.get_capabilities().get("cpu_name") if device.type == "cpu" else None,
    }
    for prefix in learners:
        result.update(_summary(prefix, times[prefix]))
    if args.reference:  # per-iteration ratios of the interleaved runs: robust to machine load
        for name, step in (("sac_update", "plain"), ("csirl_iteration", "csirl")):
            pairs = zip(times[""][step], times["reference_"][step])
            result[f"{name}_speedup"] = round(statistics.median(ref / new for new, ref in pairs), 3)
    if "fp32_" in learners:
        for name, step in (("sac", "plain"), ("csirl", "csirl")):
            pairs = zip(times[""][step], times["fp32_"][step])
            result[f"bf16_speedup_{name}"] = round(statistics.median(ref / new for new, ref in pairs), 3)
    if against is not None:
        pairs = zip(times[""]["csirl"], times["against_"]["csirl"])
        result[f"{args.meta_gradient}_over_{against}"] = round(statistics.median(new / old for new, old in pairs), 3)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
