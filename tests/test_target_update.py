"""FusedSoftUpdate against TorchRL's SoftUpdate: the same targets, bit for bit, in float64 and float32."""
from __future__ import annotations

import pytest
import torch
from torchrl.objectives import SoftUpdate

from torchrl_csirl.modules import make_actor, make_qvalue
from torchrl_csirl.objectives import EnsembleSACLoss, FusedSoftUpdate, make_csirl_learner


def _loss(dtype: torch.dtype) -> EnsembleSACLoss:
    torch.manual_seed(0)
    return EnsembleSACLoss(make_actor(6, 2, hidden=(16, 16)), make_qvalue(6, 2, hidden=(16, 16)),
                           num_qvalue_nets=3).to(dtype)


def _move_sources(loss: EnsembleSACLoss, seed: int) -> None:
    """One optimiser-like move of every critic parameter, the same for every loss built by ``_loss``."""
    generator = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for p in loss.qvalue_network_params.values(True, True):
            p.add_(torch.randn(p.shape, generator=generator, dtype=p.dtype))


@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_fused_soft_update_gives_stock_targets_bit_for_bit(dtype):
    stock_loss, fused_loss = _loss(dtype), _loss(dtype)
    stock, fused = SoftUpdate(stock_loss, tau=0.05), FusedSoftUpdate(fused_loss, tau=0.05)
    for step in range(5):
        _move_sources(stock_loss, step)
        _move_sources(fused_loss, step)
        stock.step()
        fused.step()
    stock_targets = stock_loss.target_qvalue_network_params.data
    fused_targets = fused_loss.target_qvalue_network_params.data
    initial = _loss(dtype).target_qvalue_network_params.data
    assert all(not torch.equal(a, b) for a, b in zip(fused_targets.values(True, True), initial.values(True, True)))
    for key in stock_targets.keys(True, True):
        assert torch.equal(stock_targets[key], fused_targets[key]), key
    assert fused.state_dict() == stock.state_dict()


def test_fused_soft_update_follows_a_reloaded_loss_module():
    source, target = _loss(torch.float32), _loss(torch.float32)
    _move_sources(source, 0)
    updater = FusedSoftUpdate(target, tau=0.5)
    updater.step()  # its tensors read before the reload
    target.load_state_dict(source.state_dict())
    _move_sources(target, 1)
    before = target.target_qvalue_network_params.data.clone()
    updater.step()
    for key, value in target.qvalue_network_params.data.items(True, True):
        torch.testing.assert_close(target.target_qvalue_network_params.data[key], before[key].lerp(value, 0.5))


def test_csirl_learner_fuses_its_target_update_and_keeps_the_stock_one_selectable():
    assert type(make_csirl_learner(4, 2, hidden=(8,)).target_updater) is FusedSoftUpdate
    assert type(make_csirl_learner(4, 2, hidden=(8,), fused_target_update=False).target_updater) is SoftUpdate


def test_fused_soft_update_reads_its_tensors_again_after_init():
    loss = _loss(torch.float32)
    updater = FusedSoftUpdate(loss, tau=0.5)
    updater.step()
    first = updater._leaves()
    assert updater._leaves() is first  # read once per init_()
    with pytest.warns(UserWarning, match="already initialized"):
        updater.init_()  # the targets copied from the sources again, the locked TensorDicts rebuilt
    assert updater._leaves() is not first
    _move_sources(loss, 0)
    before = loss.target_qvalue_network_params.data.clone()
    updater.step()
    for key, value in loss.qvalue_network_params.data.items(True, True):
        assert torch.equal(loss.target_qvalue_network_params.data[key], before[key].lerp(value, 0.5)), key
