"""The lean learner of ``benchmarks/bench_floor.py`` computes our losses and gradients (float64 parity).

It is a floor only if it does the same work: on one batch, with the same parameters and random draws,
its SAC losses, the CSIRL iteration's losses and the three parameter groups' gradients must equal ours.
"""
from __future__ import annotations

import bench_floor
import bench_update
import pytest
import torch

from torchrl_csirl.modules import LearnerPrecision


@pytest.fixture
def float64():
    previous = torch.get_default_dtype()
    torch.set_default_dtype(torch.float64)
    try:
        yield
    finally:
        torch.set_default_dtype(previous)


def _pair(batch: int = 16) -> tuple[bench_update._Learner, bench_floor.LeanLearner]:
    ours = bench_update._Learner(True, True, batch, torch.device("cpu"))
    return ours, bench_floor.LeanLearner(ours)


def _close(a: torch.Tensor, b: torch.Tensor) -> None:
    torch.testing.assert_close(a, b, rtol=1e-10, atol=1e-12)


def test_sac_losses_equal_ours(float64):
    ours, lean = _pair()
    torch.manual_seed(1)
    out = ours.sac(ours.online.set(("next", "reward"), ours.online["next", "matching_reward"]))
    torch.manual_seed(1)
    loss_q, loss_pi = lean.sac_losses()
    _close(loss_q, out["loss_qvalue"])
    _close(loss_pi, out["loss_actor"])


def test_csirl_iteration_losses_and_gradients_equal_ours(float64):
    ours, lean = _pair()
    torch.manual_seed(2)
    out = ours.joint(ours.online, ours.expert, ours.regularizer)
    (out["loss_qvalue"] + out["loss_actor"] + out["loss_meta"]).backward()
    torch.manual_seed(2)
    ref = lean.csirl_losses()
    for key in ("loss_qvalue", "loss_actor", "loss_meta", "loss_imitation", "loss_inner_actor"):
        _close(ref[key], out[key])
    fused_q, fused_pi = ours.sac._fused_qvalue, ours.sac._fused_actor
    groups = {
        "qvalue": [ours.sac.qvalue_network_params.get(k) for pair in fused_q.linear_keys for k in pair],
        "actor": [ours.sac.actor_network_params.get(k) for pair in fused_pi.linear_keys for k in pair],
        "reward": [p for m in ours.reward_net.module.mlp if isinstance(m, torch.nn.Linear) for p in (m.weight, m.bias)],
    }
    for group, params in groups.items():
        for param, grad in zip(params, ref[f"grads_{group}"], strict=True):
            _close(grad, param.grad)


def test_steps_update_the_parameters_and_targets():
    ours = bench_update._Learner(True, True, 8, torch.device("cpu"), precision=LearnerPrecision(torch.bfloat16))
    lean = bench_floor.LeanLearner(ours, LearnerPrecision(torch.bfloat16))
    before = [t.clone() for t in (*lean.phi, *lean.theta, *lean.w, *lean.phi_target)]
    lean.plain_step()
    lean.csirl_step()
    after = (*lean.phi, *lean.theta, *lean.w, *lean.phi_target)
    assert all(not torch.equal(b, a) for b, a in zip(before, after))
    assert all(t.dtype == torch.float32 and torch.isfinite(t).all() for t in after)


def test_measure_reports_ratios_over_the_floor():
    result = bench_floor.measure(8, ["fp32"], rounds=2, block=2, plain_autocast=False)
    assert result["fp32_sac_over_floor"] > 0 and result["fp32_csirl_over_floor"] > 0
    assert set(result) >= {"fp32_ours_sac_update_ms", "fp32_floor_csirl_iteration_ms"}
