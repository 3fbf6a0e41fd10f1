"""Parity of EnsembleSACLoss's fused path with SACLoss's own (``fused=False``).

Float64, random batches: the losses and their gradients (actor, critics, temperature, reward,
second order through the meta-gradient) agree to 1e-6 for every option the fused path supports,
and the options it does not support fall back to SACLoss. In float32 the default is bit-identical.
"""
from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from tensordict.nn import TensorDictModule
from torch import nn
from torchrl.objectives.utils import ValueEstimators
from transitions import random_transitions

from torchrl_csirl.modules import make_actor, make_qvalue
from torchrl_csirl.objectives import EnsembleSACLoss, MetaRewardLoss

OBS, ACT, HID = 5, 2, (8, 8)
TOL = dict(rtol=0, atol=1e-6)


class _Scale(nn.Module):
    """A parameter-free input map (stands in for the ego-relative features)."""

    in_features, out_features = OBS, OBS + 1

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.cat([x * 0.5, x.sum(-1, keepdim=True)], dim=-1)


def _pair(dtype=torch.float64, input_features=False, **kwargs) -> tuple[EnsembleSACLoss, EnsembleSACLoss]:
    """The same loss (same initial parameters) on SACLoss's path and on the fused path."""
    losses = []
    for fused in (False, True):
        torch.manual_seed(0)
        features = _Scale() if input_features else None
        actor = make_actor(OBS, ACT, hidden=HID, input_features=features).to(dtype)
        critic = make_qvalue(OBS, ACT, hidden=HID, input_features=features).to(dtype)
        losses.append(EnsembleSACLoss(actor, critic, fused=fused, **kwargs).to(dtype))
    stock, fused = losses
    assert not stock.fused and fused.fused
    for key, value in stock.state_dict().items():
        assert torch.equal(value, fused.state_dict()[key]), key
    return stock, fused


def _batch(n=12, dtype=torch.float64, seed=1) -> TensorDict:
    td = random_transitions(n, OBS, ACT, dtype=dtype, generator=torch.Generator().manual_seed(seed))
    td["next", "terminated"][:3] = True
    td["next", "done"][:5] = True  # 3 terminated, 2 truncated
    return td


def _losses_and_grads(loss: EnsembleSACLoss, td: TensorDict, seed: int = 7):
    torch.manual_seed(seed)
    out = loss(td)
    params = [p for p in loss.parameters() if p.requires_grad]
    total = out["loss_qvalue"] + out["loss_actor"] + out["loss_alpha"]
    grads = torch.autograd.grad(total, params, allow_unused=True)
    return out, grads


def _assert_same(stock, fused):
    (out_s, grads_s), (out_f, grads_f) = stock, fused
    assert set(out_s.keys()) == set(out_f.keys())
    for key in out_s.keys():
        torch.testing.assert_close(out_f[key], out_s[key], **TOL, msg=key)
    assert len(grads_s) == len(grads_f)
    for g_s, g_f in zip(grads_s, grads_f):
        assert (g_s is None) == (g_f is None)
        if g_s is not None:
            torch.testing.assert_close(g_f, g_s, **TOL)


OPTIONS = {
    "default": {},
    "two_critics": dict(num_qvalue_nets=2),
    "one_critic": dict(num_qvalue_nets=1),
    "learned_alpha": dict(fixed_alpha=False, alpha_init=0.2),
    "learned_alpha_target_entropy": dict(fixed_alpha=False, target_entropy=-0.5),
    "alpha_bounds": dict(fixed_alpha=False, alpha_init=0.5, min_alpha=0.1, max_alpha=0.3),
    "smooth_l1": dict(loss_function="smooth_l1"),
    "gamma": dict(gamma=0.9),
    "no_target_critics": dict(delay_qvalue=False),
    "target_actor": dict(delay_actor=True),
    "prioritized": dict(use_prioritized_weights=True),
    "sum_reduction": dict(reduction="sum"),
}


@pytest.mark.parametrize("name", sorted(OPTIONS))
def test_fused_losses_and_gradients_equal_sacloss(name):
    stock, fused = _pair(**OPTIONS[name])
    assert fused.fused_applies()
    td = _batch()
    if name == "prioritized":
        td["priority_weight"] = torch.rand(12, dtype=torch.float64)
    td_s, td_f = td.clone(), td.clone()
    _assert_same(_losses_and_grads(stock, td_s), _losses_and_grads(fused, td_f))
    torch.testing.assert_close(td_f["td_error"], td_s["td_error"], **TOL)  # the priority SACLoss writes


def test_fused_with_input_features_and_set_keys():
    stock, fused = _pair(input_features=True)
    for loss in (stock, fused):
        loss.set_keys(reward="local_reward", terminated="term")
    td = _batch()
    td["next", "local_reward"] = td["next"].pop("reward") * 2
    td["next", "term"] = td["next", "terminated"].clone()
    td["next", "term"][5:7] = True
    _assert_same(_losses_and_grads(stock, td.clone()), _losses_and_grads(fused, td.clone()))


def test_fused_differentiable_reward_and_swapped_params():
    """The pieces the meta-gradient uses: critic loss with a graph-carrying reward and swapped-in
    parameters, actor loss with non-detached critic parameters; gradients to first and second order."""
    results = []
    for loss in _pair():
        td = _batch()
        reward = td["next", "reward"].clone().requires_grad_(True)
        td["next", "reward"] = reward
        theta = TensorDict({k: v.detach().clone().requires_grad_(True)
                            for k, v in loss.actor_network_params.items(True, True)}, [])
        phi = TensorDict({k: v.detach().clone().requires_grad_(True)
                          for k, v in loss.qvalue_network_params.items(True, True)}, [5])
        torch.manual_seed(3)
        with loss.using_params(theta, phi), loss.differentiable_reward_mode():
            loss_q, meta_q = loss.qvalue_v2_loss(td)
        phi_leaves = list(phi.values(True, True))
        grads_phi = torch.autograd.grad(loss_q, phi_leaves, create_graph=True)
        phi_new = phi.empty()
        for key, p, g in zip(phi.keys(True, True), phi_leaves, grads_phi):
            phi_new.set(key, p - 0.1 * g)
        with loss.using_params(theta, actor_loss_qvalue_params=phi_new):
            loss_pi, meta_pi = loss.actor_loss(td)
        theta_leaves = list(theta.values(True, True))
        grads_theta = torch.autograd.grad(loss_pi, theta_leaves, create_graph=True)
        second = sum((g * g).sum() for g in grads_theta)  # depends on the reward through phi_new
        (d_reward,) = torch.autograd.grad(second, reward)
        results.append((loss_q, meta_q["td_error"], loss_pi, meta_pi["log_prob"], *grads_phi, *grads_theta, d_reward))
    for stock, fused in zip(*results):
        torch.testing.assert_close(fused, stock, **TOL)


META_OPTIONS = {
    "default": {},
    "joint": dict(joint_sac_update=True),
    "deterministic_expert": dict(deterministic_expert_action=True),
    "normalized_no_matching": dict(gradient_balance="normalized", use_matching_reward=False),
}


@pytest.mark.parametrize("name", sorted(META_OPTIONS))
def test_fused_meta_gradient_equals_sacloss(name):
    results = []
    for sac in _pair(num_qvalue_nets=3):
        torch.manual_seed(0)
        net = nn.Sequential(nn.Linear(OBS, 4), nn.Tanh(), nn.Linear(4, 1)).double()
        reward = TensorDictModule(net, in_keys=["observation"], out_keys=["intrinsic_reward"])
        meta = MetaRewardLoss(sac, reward, **META_OPTIONS[name])
        online = _batch()
        online["next", "matching_reward"] = online["next"].pop("reward")
        expert = TensorDict({"observation": torch.randn(6, OBS, dtype=torch.float64),
                             "action": torch.rand(6, ACT, dtype=torch.float64) * 1.6 - 0.8}, [6])
        torch.manual_seed(5)
        out = meta(online, expert)
        total = sum(v for k, v in out.items() if k.startswith("loss_") and v.requires_grad)
        params = list(reward.parameters()) + [p for p in sac.parameters() if p.requires_grad]
        grads = torch.autograd.grad(total, params, allow_unused=True)
        results.append((out, grads))
    _assert_same(*results)


def test_fused_sample_actions_equal_sacloss():
    stock, fused = _pair()
    obs = torch.randn(4, OBS, dtype=torch.float64)
    for deterministic in (False, True):
        actions = []
        for loss in (stock, fused):
            torch.manual_seed(2)
            actions.append(loss.sample_actions(obs, deterministic=deterministic))
        assert torch.equal(*actions)


def test_fused_default_is_bit_identical_in_float32():
    stock, fused = _pair(dtype=torch.float32)
    td = _batch(dtype=torch.float32)
    (out_s, grads_s), (out_f, grads_f) = _losses_and_grads(stock, td.clone()), _losses_and_grads(fused, td.clone())
    for key in out_s.keys():
        assert torch.equal(out_f[key], out_s[key]), key
    for g_s, g_f in zip(grads_s, grads_f):
        assert (g_s is None and g_f is None) or torch.equal(g_s, g_f)


def test_unsupported_options_fall_back_to_sacloss():
    stock, fused = _pair(skip_done_states=True)
    assert fused.fused and not fused.fused_applies()
    _assert_same(_losses_and_grads(stock, _batch()), _losses_and_grads(fused, _batch()))
    _, fused = _pair()
    fused.make_value_estimator(ValueEstimators.TD1, gamma=0.9)
    assert not fused.fused_applies()
    assert fused(_batch())["loss_qvalue"].isfinite()


def test_fused_needs_supported_networks():
    actor, critic = make_actor(OBS, ACT, hidden=HID), make_qvalue(OBS, ACT, hidden=HID)
    with pytest.raises(ValueError, match="fused=True"):
        EnsembleSACLoss(actor, critic, fused=True, fused_qvalue=False)
    assert not EnsembleSACLoss(actor, critic, fused_qvalue=False).fused
    assert EnsembleSACLoss(actor, critic).fused  # the default: on where supported
