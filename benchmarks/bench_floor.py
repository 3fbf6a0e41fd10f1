"""Our learner against a lean plain-PyTorch learner that computes the same losses: the floor of the hardware.

:class:`LeanLearner` is the SAC update and the CSIRL iteration of ``bench_update.py`` written plainly,
with nothing but tensors: the five critics as one stack of weights (one ``baddbmm`` per layer, the bias
inside), the tanh-Gaussian actor and ``r_w`` as ``addmm`` chains, the inner critic and actor steps of the
meta-gradient by ``torch.autograd.grad`` with ``create_graph=True``, fused Adam and ``_foreach_lerp_`` for
the target critics. It starts from a copy of our learner's parameters and draws its random numbers in
our order, so on one batch its losses equal ours (``tests/test_bench_floor.py`` pins them in float64):
it is a floor for the same computation, not a different method. It leaves out what ours adds beyond the
maths (TensorDicts, the loss modules' dispatch, the meta-loss's diagnostics).

In bfloat16 it makes the choices ours makes (``optim.precision=bf16``): hidden layers in bfloat16 with
each float32 weight cast once per update, output layers, losses, weights and Adam in float32.
``--plain-autocast`` times, in addition, the reference with every layer under ``torch.autocast`` (outputs
in bfloat16 too: a different rounding, shown for scale only).

Both learners are timed alternated in one process, in blocks of a few steps (the first of each block
untimed, so each learner runs with warm caches as it does alone in a run); the JSON line gives the
medians and ``*_over_floor``, the median of the per-round ratios ours / lean, and ``bf16_speedup_*``,
fp32 over bf16 for each learner.

Usage::

    python benchmarks/bench_floor.py --batch 256 --rounds 20      # fp32 and bf16 (where native)
    python benchmarks/bench_floor.py --batch 64 --precisions fp32
    python benchmarks/bench_floor.py --hidden 8 --batch 8 --threads 1 --precisions fp32   # the per-call overhead
    python benchmarks/bench_floor.py --precisions fp32 --fp32-bias-inside   # what float32's bit-identity costs

``--fp32-bias-inside`` times ours with its float32 critics computed as our bfloat16 path computes them (the
first layer as ``expand`` + ``baddbmm``, the bias inside every layer's matmul, as the floor does). That rounds
differently from TorchRL's critic, so it is not a path the package ships: it measures how much of the float32
gap the bit-identity to SACLoss's path accounts for.

Prints one final JSON line.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import statistics
from collections.abc import Sequence

import bench_update
import torch
from torch.nn import functional as F

from torchrl_csirl._compat import sac_alpha
from torchrl_csirl.modules import LearnerPrecision, has_native_bf16
from torchrl_csirl.modules.actor_critic import masked_relu
from torchrl_csirl.modules.ensemble import FusedCriticEnsemble
from torchrl_csirl.modules.precision import low_precision_dtype

_HALF_LOG_2PI = math.log(math.sqrt(2 * math.pi))
_LOG_2 = math.log(2.0)

Layers = list[tuple[torch.Tensor, torch.Tensor]]
CPU = torch.device("cpu")


# ----------------------------------------------------------------------------------- the maths, plainly
# ReLU whose backward reads its output detached (no second-order edge through the mask), as our networks use
relu = masked_relu


def _hidden(h: torch.Tensor, layers: Layers, low: torch.dtype | None) -> torch.Tensor:
    """ReLU layers of an MLP on ``h`` ``[M, D]``; in ``low`` precision when given."""
    if low is not None:
        h = h.to(low)
    for weight, bias in layers:
        h = relu(torch.addmm(bias, h, weight.t()))
    return h


def mlp(x: torch.Tensor, layers: Layers, low: torch.dtype | None = None) -> torch.Tensor:
    """An MLP of ReLU hidden layers; the output layer in float32 on the hidden activation."""
    h = _hidden(x, layers[:-1], low)
    weight, bias = layers[-1]
    return torch.addmm(bias, h.to(weight.dtype), weight.t())


def critics(x: torch.Tensor, layers: Layers, low: torch.dtype | None = None) -> torch.Tensor:
    """``[N, M, 1]`` values of ``N`` stacked critics (weights ``[N, out, in]``) on a shared input ``[M, D]``."""
    first, bias = layers[0]
    h = x if low is None else x.to(low)
    h = relu(torch.baddbmm(bias.unsqueeze(1), h.expand(first.shape[0], *h.shape), first.transpose(1, 2)))
    for weight, bias in layers[1:-1]:
        h = relu(torch.baddbmm(bias.unsqueeze(1), h, weight.transpose(1, 2)))
    weight, bias = layers[-1]
    return torch.baddbmm(bias.unsqueeze(1), h.to(weight.dtype), weight.transpose(1, 2))


def tanh_normal_params(out: torch.Tensor, log_std_min: float, log_std_max: float) -> tuple[torch.Tensor, torch.Tensor]:
    """``(loc, scale)`` of the actor's head: ``log(scale)`` squashed by tanh into ``[min, max]``."""
    loc, log_std = out.chunk(2, dim=-1)
    log_std = log_std_min + 0.5 * (log_std_max - log_std_min) * (torch.tanh(log_std) + 1.0)
    return loc, log_std.exp()


def rsample_and_log_prob(loc: torch.Tensor, scale: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """A reparameterised tanh-Gaussian action in ``[-1, 1]`` and its log-probability (TorchRL's TanhNormal)."""
    eps = torch.empty_like(loc).normal_()
    u = loc + eps * scale
    lim = 1.0 - torch.finfo(u.dtype).resolution
    action = torch.tanh(u).clamp(-lim, lim)
    log_prob = -((u - loc) ** 2) / (2 * scale**2) - scale.log() - _HALF_LOG_2PI
    log_det = 2.0 * (_LOG_2 - u - F.softplus(-2.0 * u))
    return action, log_prob.sum(-1) - log_det.sum(-1)


def rsample(loc: torch.Tensor, scale: torch.Tensor) -> torch.Tensor:
    """A reparameterised tanh-Gaussian action (the same draw as :func:`rsample_and_log_prob`)."""
    u = loc + torch.empty_like(loc).normal_() * scale
    lim = 1.0 - torch.finfo(u.dtype).resolution
    return torch.tanh(u).clamp(-lim, lim)


def _lookahead(params: Sequence[torch.Tensor], grads: Sequence[torch.Tensor], lr: float) -> list[torch.Tensor]:
    return [p - lr * g for p, g in zip(params, grads)]


def _pairs(flat: Sequence[torch.Tensor]) -> Layers:
    return list(zip(flat[0::2], flat[1::2]))


def _cast(flat: Sequence[torch.Tensor], low: torch.dtype | None) -> list[torch.Tensor]:
    """Hidden layers' weights and biases in ``low`` (the last pair, the output layer, stays float32)."""
    if low is None:
        return list(flat)
    return [t.to(low) for t in flat[:-2]] + list(flat[-2:])


# ------------------------------------------------------------------------------------- the learner
class LeanLearner:
    """The learner of ``bench_update._Learner`` in plain tensors, started from a copy of its parameters.

    Args:
        ours: a ``bench_update._Learner`` (its networks, batches and hyper-parameters are copied).
        precision: ``LearnerPrecision``; bfloat16 runs the hidden layers in bfloat16.
    """

    def __init__(self, ours: bench_update._Learner, precision: LearnerPrecision | None = None) -> None:
        sac = ours.sac
        fused_q, fused_pi = sac._fused_qvalue, sac._fused_actor
        self.low = None if precision is None or precision.dtype == torch.float32 else precision.dtype

        def flat(params, linear_keys) -> list[torch.Tensor]:
            return [params.get(k).detach().clone() for pair in linear_keys for k in pair]

        self.phi = [t.requires_grad_(True) for t in flat(sac.qvalue_network_params, fused_q.linear_keys)]
        self.phi_target = flat(sac.target_qvalue_network_params, fused_q.linear_keys)
        self.theta = [t.requires_grad_(True) for t in flat(sac.actor_network_params, fused_pi.linear_keys)]
        linears = [m for m in ours.reward_net.module.mlp if isinstance(m, torch.nn.Linear)]
        self.w = [t.detach().clone().requires_grad_(True) for m in linears for t in (m.weight, m.bias)]
        self.log_std_bounds = (fused_pi.head.log_std_min, fused_pi.head.log_std_max)
        self.alpha = float(sac_alpha(sac))
        self.gamma = float(sac.value_estimator.gamma)
        self.lr_inner, self.scale, self.l1 = ours.joint.lr_inner, ours.joint.scale, ours.joint.reward_l1_coef
        self.tau = 1.0 - float(ours.updater.eps)
        lr = {g: o.param_groups[0]["lr"] for g, o in (("q", ours.optim_q), ("pi", ours.optim_pi), ("w", ours.optim_w))}
        self.optim_q = torch.optim.Adam(self.phi, lr=lr["q"], fused=True)
        self.optim_pi = torch.optim.Adam(self.theta, lr=lr["pi"], fused=True)
        self.optim_w = torch.optim.Adam(self.w, lr=lr["w"], fused=True)
        self.batch = self._tensors(ours.online)
        self.regularizer = self._tensors(ours.regularizer)
        self.expert = (ours.expert["observation"], ours.expert["action"])

    @staticmethod
    def _tensors(td) -> dict[str, torch.Tensor]:
        return {
            "obs": td["observation"], "action": td["action"], "next_obs": td["next", "observation"],
            "r_m": td["next", "matching_reward"].squeeze(-1),
            "not_terminated": (~td["next", "terminated"]).squeeze(-1).to(td["observation"].dtype),
        }

    # -------------------------------------------------------------------------------- the pieces
    def actor(self, obs: torch.Tensor, theta: Sequence[torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
        return tanh_normal_params(mlp(obs, _pairs(theta), self.low), *self.log_std_bounds)

    def reward(self, obs: torch.Tensor, w: Sequence[torch.Tensor]) -> torch.Tensor:
        return torch.tanh(mlp(obs, _pairs(w), self.low)).squeeze(-1)

    def target(self, b: dict[str, torch.Tensor], theta_low: Sequence[torch.Tensor]) -> torch.Tensor:
        """``gamma (1 - terminated) min_k (Q'_k(s', a') - alpha log pi(a'|s'))``, no grad (the reward added by the caller)."""
        with torch.no_grad():
            action, log_prob = rsample_and_log_prob(*self.actor(b["next_obs"], theta_low))
            q = critics(torch.cat([b["next_obs"], action], -1), _pairs(_cast(self.phi_target, self.low)), self.low)
            value = (q.squeeze(-1) - self.alpha * log_prob).min(0)[0]
            return self.gamma * b["not_terminated"] * value

    def critic_loss(self, b, y: torch.Tensor, phi_low: Sequence[torch.Tensor]) -> torch.Tensor:
        q = critics(torch.cat([b["obs"], b["action"]], -1), _pairs(phi_low), self.low).squeeze(-1)
        return (q - y).pow(2).sum(0).mean()

    def actor_loss(self, b, theta_low: Sequence[torch.Tensor], phi_low: Sequence[torch.Tensor]):
        action, log_prob = rsample_and_log_prob(*self.actor(b["obs"], theta_low))
        q = critics(torch.cat([b["obs"], action], -1), _pairs(phi_low), self.low).squeeze(-1)
        return (self.alpha * log_prob - q.min(0)[0]).mean()

    def _steps(self, optims) -> None:
        for optim in optims:
            optim.step()
        torch._foreach_lerp_(self.phi_target, [p.detach() for p in self.phi], self.tau)

    # --------------------------------------------------------------------------------- the steps
    def sac_losses(self) -> tuple[torch.Tensor, torch.Tensor]:
        """The SAC update's critic and actor losses (for the parity test)."""
        b = self.batch
        phi_low, theta_low = _cast(self.phi, self.low), _cast(self.theta, self.low)
        y = b["r_m"] + self.target(b, theta_low)
        loss_q = self.critic_loss(b, y, phi_low)
        loss_pi = self.actor_loss(b, theta_low, [p.detach() for p in phi_low])
        return loss_q, loss_pi

    def plain_step(self) -> None:
        """One SAC update: losses, one backward, two fused Adam steps, the target critics' lerp."""
        for optim in (self.optim_q, self.optim_pi):
            optim.zero_grad(set_to_none=True)
        loss_q, loss_pi = self.sac_losses()
        (loss_q + loss_pi).backward()
        self._steps((self.optim_q, self.optim_pi))

    def csirl_losses(self) -> dict[str, torch.Tensor]:
        """The joint CSIRL iteration: inner critic and actor steps, the meta-loss and its gradient w.r.t. ``w``.

        Returns the losses and the gradients of the three parameter groups (critic, actor, reward).
        """
        b, (obs_e, action_e) = self.batch, self.expert
        theta_low, w_low, phi_low = _cast(self.theta, self.low), _cast(self.w, self.low), _cast(self.phi, self.low)
        r_w = self.reward(b["obs"], w_low)
        y = b["r_m"] + r_w + self.target(b, theta_low)
        loss_q = self.critic_loss(b, y, phi_low)
        grads_phi = torch.autograd.grad(loss_q, self.phi, create_graph=True)                    # Eq. 12
        phi_new = _lookahead(self.phi, grads_phi, self.lr_inner)
        loss_pi = self.actor_loss(b, theta_low, _cast(phi_new, self.low))
        grads_theta = torch.autograd.grad(loss_pi, self.theta, create_graph=True)              # Eq. 13
        theta_new = _lookahead(self.theta, grads_theta, self.lr_inner)
        a_hat = rsample(*self.actor(obs_e, _cast(theta_new, self.low)))
        loss_imitation = (a_hat - action_e).pow(2).mean()                                      # Eq. 11
        loss_l1 = self.reward(self.regularizer["obs"], w_low).abs().mean()
        loss_meta = self.scale * (loss_imitation + self.l1 * loss_l1)
        grads_w = torch.autograd.grad(loss_meta, self.w)
        loss_actor = self.actor_loss(b, theta_low, [p.detach() for p in phi_low])
        grads_actor = torch.autograd.grad(loss_actor, self.theta)
        return {"loss_qvalue": loss_q, "loss_inner_actor": loss_pi, "loss_imitation": loss_imitation,
                "loss_meta": loss_meta, "loss_actor": loss_actor,
                "grads_qvalue": [g.detach() for g in grads_phi], "grads_actor": list(grads_actor),
                "grads_reward": list(grads_w)}

    def csirl_step(self) -> None:
        """One joint CSIRL iteration and the three fused Adam steps, then the target critics' lerp."""
        out = self.csirl_losses()
        for group, params in (("qvalue", self.phi), ("actor", self.theta), ("reward", self.w)):
            for p, g in zip(params, out[f"grads_{group}"]):
                p.grad = g
        self._steps((self.optim_q, self.optim_pi, self.optim_w))


class AutocastLeanLearner(LeanLearner):
    """The lean learner with every layer under ``torch.autocast`` (bfloat16 outputs: a different rounding)."""

    def __init__(self, ours: bench_update._Learner) -> None:
        super().__init__(ours, None)

    def plain_step(self) -> None:
        with torch.autocast("cpu", torch.bfloat16):
            for optim in (self.optim_q, self.optim_pi):
                optim.zero_grad(set_to_none=True)
            loss_q, loss_pi = self.sac_losses()
        (loss_q + loss_pi).backward()
        self._steps((self.optim_q, self.optim_pi))

    def csirl_step(self) -> None:
        with torch.autocast("cpu", torch.bfloat16):
            out = self.csirl_losses()
        for group, params in (("qvalue", self.phi), ("actor", self.theta), ("reward", self.w)):
            for p, g in zip(params, out[f"grads_{group}"]):
                p.grad = g.float()
        self._steps((self.optim_q, self.optim_pi, self.optim_w))


# ------------------------------------------------------------------------------------------ timing
def measure(batch: int, precisions: Sequence[str], rounds: int, block: int, plain_autocast: bool) -> dict:
    """Ours and the lean learner, per precision, alternated in blocks of ``block`` steps; medians and ratios.

    Each round runs every learner ``block`` times per step kind and keeps the median of all but the
    first step of the block (caches warm again after the other learners ran, as in a run with one
    learner). ``*_over_floor`` is the median over rounds of ours / lean for the same round.
    """
    learners = {}
    for name in precisions:
        precision = LearnerPrecision.from_setting(name)
        ours = bench_update._Learner(True, True, batch, torch.device("cpu"), precision=precision)
        learners[f"{name}_ours"] = ours
        learners[f"{name}_floor"] = LeanLearner(ours, precision)
    if plain_autocast:
        learners["bf16_autocast_floor"] = AutocastLeanLearner(bench_update._Learner(True, True, batch, torch.device("cpu")))
    steps = ("plain", "csirl")
    times = {name: {step: [] for step in steps} for name in learners}
    for _ in range(rounds + 1):  # the first round warms up
        for step in steps:
            for name, learner in learners.items():
                fn = getattr(learner, f"{step}_step")
                fn()
                times[name][step].append(statistics.median(bench_update._timed(fn, CPU) for _ in range(max(block - 1, 1))))
    result = {}
    for name in learners:
        for step, label in (("plain", "sac_update_ms"), ("csirl", "csirl_iteration_ms")):
            result[f"{name}_{label}"] = round(statistics.median(times[name][step][1:]), 2)
    for name in precisions:
        for step, label in (("plain", "sac"), ("csirl", "csirl")):
            pairs = list(zip(times[f"{name}_ours"][step], times[f"{name}_floor"][step]))[1:]
            result[f"{name}_{label}_over_floor"] = round(statistics.median(o / f for o, f in pairs), 3)
    if "fp32" in precisions and "bf16" in precisions:
        for step, label in (("plain", "sac"), ("csirl", "csirl")):
            for who in ("ours", "floor"):
                pairs = list(zip(times[f"fp32_{who}"][step], times[f"bf16_{who}"][step]))[1:]
                result[f"bf16_speedup_{label}_{who}"] = round(statistics.median(a / b for a, b in pairs), 3)
    return result


def _put_fp32_bias_inside() -> None:
    """Our fused critics compute float32 as they compute bfloat16: the first layer on the expanded input, every
    layer one ``baddbmm`` (the bias inside)."""
    values = FusedCriticEnsemble.values

    def bias_inside(self, x, params, activations=None):
        if x.dtype != torch.float32 or low_precision_dtype(x) is not None:
            return values(self, x, params, activations)
        return self._values_low_precision(x, params, torch.float32, activations)

    FusedCriticEnsemble.values = bias_inside


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--batch", type=int, default=256)
    parser.add_argument("--rounds", type=int, default=20)
    parser.add_argument("--block", type=int, default=5, help="steps per learner per round (the first untimed)")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--precisions", nargs="+", default=None, choices=("fp32", "bf16"),
                        help="default: fp32, and bf16 where the CPU multiplies bfloat16 natively")
    parser.add_argument("--hidden", type=int, default=0,
                        help="hidden width of the actor and critics (0: bench_update.py's 256; 8 with --batch 8 "
                             "--threads 1 leaves the per-call overhead)")
    parser.add_argument("--fp32-bias-inside", action="store_true",
                        help="ours with float32 critics computed as the bfloat16 path does (not bit-identical to SACLoss)")
    parser.add_argument("--plain-autocast", action="store_true",
                        help="also time the lean learner with every layer under bfloat16 autocast")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    if args.hidden:  # smaller networks, as bench_revisions.py --hidden makes them
        make_actor, make_qvalue = bench_update.make_actor, bench_update.make_qvalue
        bench_update.make_actor = lambda obs, act: make_actor(obs, act, hidden=(args.hidden, args.hidden))
        bench_update.make_qvalue = lambda obs, act: make_qvalue(obs, act, hidden=(args.hidden, args.hidden))
    if args.fp32_bias_inside:
        _put_fp32_bias_inside()
    precisions = args.precisions or (["fp32", "bf16"] if has_native_bf16("cpu") else ["fp32"])
    result = {"batch": args.batch, "hidden": args.hidden or 256, "threads": args.threads, "rounds": args.rounds, "block": args.block,
              "fp32_bias_inside": args.fp32_bias_inside,
              "cpu": torch.cpu.get_capabilities().get("cpu_name"), "native_bf16": has_native_bf16("cpu"),
              "torch": torch.__version__}
    with contextlib.suppress(OSError):
        result["load_average"] = round(os.getloadavg()[0], 2)
    result.update(measure(args.batch, precisions, args.rounds, args.block, args.plain_autocast))
    print(json.dumps(result))


if __name__ == "__main__":
    main()
