from __future__ import annotations

import copy
import itertools

import pytest
import torch
from devices import DEVICES
from tensordict import TensorDict
from tensordict.nn import TensorDictModule
from torch import nn
from transitions import random_transitions

from torchrl_csirl.modules import make_actor, make_qvalue, make_reward_network
from torchrl_csirl.objectives import EnsembleSACLoss, MetaRewardLoss
from torchrl_csirl.objectives.meta_reward import sgd_lookahead

OBS, ACT = 3, 2


def _tiny_reward(dtype=torch.float64) -> TensorDictModule:
    net = nn.Sequential(nn.Linear(OBS, 4), nn.Tanh(), nn.Linear(4, 1), nn.Tanh()).to(dtype)
    return TensorDictModule(net, in_keys=["observation"], out_keys=["intrinsic_reward"])


def _setup(dtype=torch.float64, num_critics=3, device="cpu", **meta_kwargs):
    torch.manual_seed(0)
    actor = make_actor(OBS, ACT, hidden=(6,)).to(dtype)
    critic = make_qvalue(OBS, ACT, hidden=(6,)).to(dtype)
    sac = EnsembleSACLoss(actor, critic, num_qvalue_nets=num_critics).to(dtype).to(device)
    reward = _tiny_reward(dtype).to(device)
    meta = MetaRewardLoss(sac, reward, **meta_kwargs)
    g = torch.Generator().manual_seed(1)
    n = 5
    online = random_transitions(n, OBS, ACT, dtype=dtype, generator=g, reward_key="matching_reward")
    online["next", "terminated"][0] = True
    expert = TensorDict(
        {
            "observation": torch.randn(4, OBS, generator=g, dtype=dtype),
            "action": torch.rand(4, ACT, generator=g, dtype=dtype) * 1.6 - 0.8,
        },
        [4],
    )
    regularizer = online.clone()
    regularizer["observation"] = torch.randn(n, OBS, generator=g, dtype=dtype)
    return sac, reward, meta, online.to(device), expert.to(device), regularizer.to(device)


def _meta_value(meta, online, expert, regularizer, seed=123) -> torch.Tensor:
    torch.manual_seed(seed)
    return meta(online, expert, regularizer)["loss_meta"].detach()


def _finite_difference(meta, reward, online, expert, regularizer, eps=1e-6):
    grads = []
    for p in reward.parameters():
        g = torch.zeros_like(p)
        flat = p.data.view(-1)
        for i in range(flat.numel()):
            orig = flat[i].item()
            flat[i] = orig + eps
            up = _meta_value(meta, online, expert, regularizer)
            flat[i] = orig - eps
            down = _meta_value(meta, online, expert, regularizer)
            flat[i] = orig
            g.view(-1)[i] = (up - down) / (2 * eps)
        grads.append(g)
    return grads


def flat_grads(grads) -> torch.Tensor:
    """The gradients of a parameter list as one vector."""
    return torch.cat([g.flatten() for g in grads])


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize(
    "kwargs",
    [
        {"reward_l1_coef": 0.0},  # the chain w -> phi' -> theta' -> L_meta alone
        {"reward_l1_coef": 1.0},
        {"reward_l1_coef": 0.0, "deterministic_expert_action": True},
    ],
)
def test_meta_gradient_matches_finite_differences(kwargs, device):
    _sac, reward, meta, online, expert, regularizer = _setup(device=device, **kwargs)
    torch.manual_seed(123)
    out = meta(online, expert, regularizer)
    out["loss_meta"].backward()
    analytic = [p.grad.clone() for p in reward.parameters()]
    numeric = _finite_difference(meta, reward, online, expert, regularizer)
    total = torch.cat([a.flatten() for a in analytic])
    # central differences at eps 1e-6 carry ~1e-8 of rounding noise (more on a GPU, whose float64
    # sums run in another order): the absolute tolerance is relative to the gradient's scale
    for a, n in zip(analytic, numeric):
        torch.testing.assert_close(a, n, rtol=1e-4, atol=1e-4 * total.abs().max().item())
    assert total.abs().max() > 1e-6  # not silently zero
    assert torch.isclose(out["meta_grad_norm"], total.norm())


def test_meta_gradient_split_into_imitation_and_regulariser_parts():
    """``meta_grad_norm_l1`` is the norm of the regulariser's own gradient; the rest is imitation."""
    _, reward, meta, online, expert, regularizer = _setup(reward_l1_coef=0.5)
    torch.manual_seed(123)
    out = meta(online, expert, regularizer)
    out["loss_meta"].backward()
    total = [p.grad.clone() for p in reward.parameters()]
    reward.zero_grad()
    l1 = meta.scale * 0.5 * reward(regularizer.select("observation"))["intrinsic_reward"].abs().mean()
    l1.backward()
    reg = [p.grad.clone() for p in reward.parameters()]
    torch.testing.assert_close(out["meta_grad_norm_l1"], flat_grads(reg).norm())
    torch.testing.assert_close(out["meta_grad_norm_imitation"], (flat_grads(total) - flat_grads(reg)).norm())
    assert out["meta_grad_norm_imitation"] > 0

    _, _, meta0, online, expert, regularizer = _setup(reward_l1_coef=0.0)
    out0 = meta0(online, expert, regularizer)
    assert out0["meta_grad_norm_l1"] == 0
    torch.testing.assert_close(out0["meta_grad_norm_imitation"], out0["meta_grad_norm"])


def test_normalized_balance_weighs_the_two_parts_by_the_l1_coefficient():
    """``gradient_balance="normalized"``: scale * (unit imitation part + coef * unit regulariser part)."""
    _, reward, meta, online, expert, regularizer = _setup(reward_l1_coef=0.5)
    torch.manual_seed(123)
    out = meta(online, expert, regularizer)
    out["loss_meta"].backward()
    total = flat_grads([p.grad for p in reward.parameters()])
    reward.zero_grad()
    l1 = meta.scale * 0.5 * reward(regularizer.select("observation"))["intrinsic_reward"].abs().mean()
    l1.backward()
    g_r = flat_grads([p.grad for p in reward.parameters()])
    g_i = total - g_r
    reward.zero_grad()

    _, reward_n, meta_n, *_ = _setup(reward_l1_coef=0.5, gradient_balance="normalized")
    torch.manual_seed(123)
    out_n = meta_n(online, expert, regularizer)
    out_n["loss_meta"].backward()
    balanced = flat_grads([p.grad for p in reward_n.parameters()])
    expected = meta.scale * (g_i / g_i.norm() + 0.5 * g_r / g_r.norm())
    torch.testing.assert_close(balanced, expected)
    torch.testing.assert_close(out_n["loss_meta"], out["loss_meta"])  # the value is still L_meta
    torch.testing.assert_close(out_n["meta_grad_norm"], balanced.norm())
    torch.testing.assert_close(out_n["meta_grad_norm_imitation"], out["meta_grad_norm_imitation"])

    # without the regulariser: the imitation part alone, at norm ``scale``
    _, reward_0, meta_0, *_ = _setup(reward_l1_coef=0.0, gradient_balance="normalized")
    torch.manual_seed(123)
    meta_0(online, expert, regularizer)["loss_meta"].backward()
    alone = flat_grads([p.grad for p in reward_0.parameters()])
    torch.testing.assert_close(alone.norm(), torch.tensor(meta.scale, dtype=alone.dtype))
    with pytest.raises(ValueError, match="gradient_balance"):
        _setup(gradient_balance="mean")


def test_meta_gradient_matches_unrolled_reference():
    """Independent re-derivation with explicit per-critic loops (no vmap, no SACLoss)."""
    sac, reward, meta, online, expert, _regularizer = _setup(reward_l1_coef=0.0, num_critics=2)
    lr, gamma, alpha = meta.lr_inner, 0.99, 0.01
    actor = sac.actor_network
    critic = make_qvalue(OBS, ACT, hidden=(6,)).to(torch.float64)

    def q_of(params, obs, act):
        with params.to_module(critic):
            return critic(TensorDict({"observation": obs, "action": act}, obs.shape[:1]))[
                "state_action_value"
            ].squeeze(-1)

    def sample(params, obs):
        with params.to_module(actor):
            dist = actor.get_dist(TensorDict({"observation": obs}, obs.shape[:1]))
        a = dist.rsample()
        return a, dist.log_prob(a)

    theta = sac.actor_network_params.data.apply(lambda p: p.clone().requires_grad_(True))
    phi = [sac.qvalue_network_params.data[k].apply(lambda p: p.clone().requires_grad_(True)) for k in range(2)]
    target_phi = [sac.target_qvalue_network_params.data[k] for k in range(2)]
    w = list(reward.parameters())
    torch.manual_seed(123)
    # same random draws, same order as MetaRewardLoss: target action, actor action, expert action
    r = online["next", "matching_reward"].squeeze(-1) + reward(online.select("observation"))["intrinsic_reward"].squeeze(-1)
    with torch.no_grad():
        a2, logp2 = sample(theta, online["next", "observation"])
        v = torch.stack([q_of(tp, online["next", "observation"], a2) for tp in target_phi]) - alpha * logp2
        v = v.min(0).values
        not_term = (~online["next", "terminated"].squeeze(-1)).double()
    y = r + gamma * not_term * v
    loss_q = sum(((q_of(p, online["observation"], online["action"]) - y) ** 2).mean() for p in phi)
    phi_new = []
    for p in phi:
        keys = list(p.keys(True, True))
        grads = torch.autograd.grad(loss_q, [p.get(k) for k in keys], create_graph=True)
        phi_new.append(TensorDict({k: p.get(k) - lr * g for k, g in zip(keys, grads)}, []))
    a, logp = sample(theta, online["observation"])
    qmin = torch.stack([q_of(p, online["observation"], a) for p in phi_new]).min(0).values
    loss_pi = (alpha * logp - qmin).mean()
    keys = list(theta.keys(True, True))
    grads = torch.autograd.grad(loss_pi, [theta.get(k) for k in keys], create_graph=True)
    theta_new = TensorDict({k: theta.get(k) - lr * g for k, g in zip(keys, grads)}, [])
    a_hat, _ = sample(theta_new, expert["observation"])
    ref = 100.0 * ((a_hat - expert["action"]) ** 2).mean()
    ref_grads = torch.autograd.grad(ref, w)

    torch.manual_seed(123)
    out = meta(online, expert)
    torch.testing.assert_close(out["loss_meta"].detach(), ref.detach(), rtol=1e-10, atol=1e-12)
    out["loss_meta"].backward()
    for p, g in zip(w, ref_grads):
        torch.testing.assert_close(p.grad, g, rtol=1e-8, atol=1e-12)
        assert g.abs().max() > 0


def test_actor_and_critic_untouched():
    sac, reward, meta, online, expert, regularizer = _setup(dtype=torch.float32)
    before = {
        name: getattr(sac, name).data.clone()
        for name in ("actor_network_params", "qvalue_network_params", "target_qvalue_network_params")
    }
    out = meta(online, expert, regularizer)
    out["loss_meta"].backward()
    for p in sac.parameters():
        assert p.grad is None
    for p in sac.actor_network.parameters():
        assert p.grad is None
    for name, value in before.items():
        assert (getattr(sac, name).data == value).all()
    assert all(p.grad is not None for p in reward.parameters())
    # only the reward network's parameters are exposed by the meta loss
    assert {id(p) for p in meta.parameters()} == {id(p) for p in reward.parameters()}
    assert not sac.differentiable_reward


def test_reward_keys():
    sac, reward, meta, online, expert, _regularizer = _setup(dtype=torch.float32)
    td = online.exclude(("next", "matching_reward"))
    with pytest.raises(KeyError, match="matching_reward"):
        meta(td, expert)
    no_matching = MetaRewardLoss(sac, reward, use_matching_reward=False)
    assert ("next", "matching_reward") not in no_matching.in_keys
    out = no_matching(td, expert)
    assert torch.isfinite(out["loss_meta"])
    meta.set_keys(matching_reward="r_m")
    td = online.rename_key_(("next", "matching_reward"), ("next", "r_m"))
    assert ("next", "r_m") in meta.in_keys
    assert torch.isfinite(meta(td, expert)["loss_meta"])


def test_matching_reward_enters_the_critic_target():
    _sac, _reward, meta, online, expert, _ = _setup(reward_l1_coef=0.0)
    torch.manual_seed(5)
    base = meta(online, expert)["loss_inner_qvalue"]
    shifted = online.clone()
    shifted["next", "matching_reward"] += 1.0
    torch.manual_seed(5)
    assert not torch.isclose(meta(shifted, expert)["loss_inner_qvalue"], base)


def test_bad_inputs():
    sac, reward, *_ = _setup(dtype=torch.float32)
    with pytest.raises(TypeError):
        MetaRewardLoss(object(), reward)
    with pytest.raises(ValueError):
        MetaRewardLoss(sac, reward, lr_inner=0.0)


def test_with_project_reward_network_and_adam_step():
    torch.manual_seed(0)
    sac = EnsembleSACLoss(make_actor(OBS, ACT, hidden=(8,)), make_qvalue(OBS, ACT, hidden=(8,)))
    reward = make_reward_network(OBS, hidden=(8,))
    meta = MetaRewardLoss(sac, reward)
    optim = torch.optim.Adam(meta.parameters(), lr=1e-3)
    _, _, _, online, expert, _ = _setup(dtype=torch.float32)
    before = [p.detach().clone() for p in reward.parameters()]
    meta(online, expert)["loss_meta"].backward()
    optim.step()
    assert any(not torch.equal(b, p) for b, p in zip(before, reward.parameters()))


def test_sgd_lookahead():
    p = TensorDict({"a": torch.tensor([1.0, 2.0], requires_grad=True)}, [])
    w = torch.tensor(2.0, requires_grad=True)
    new = sgd_lookahead((w * p["a"] ** 2).sum(), p, lr=0.5)
    torch.testing.assert_close(new["a"], torch.tensor([1.0 - 2.0, 2.0 - 4.0]))
    (gw,) = torch.autograd.grad(new["a"].sum(), w)
    assert gw.item() == pytest.approx(-0.5 * 2 * 3.0)


@pytest.mark.parametrize("device", DEVICES)
def test_joint_sac_update_matches_separate_losses(device):
    """joint_sac_update: same meta-loss/gradient, and the SAC losses/gradients of sac(td)."""
    sac, reward, meta, online, expert, regularizer = _setup(device=device)
    joint = MetaRewardLoss(sac, reward, joint_sac_update=True)
    torch.manual_seed(7)
    separate = meta(online, expert, regularizer)
    separate["loss_meta"].backward()
    meta_grads = [p.grad.clone() for p in reward.parameters()]
    reward.zero_grad()

    torch.manual_seed(7)
    out = joint(online, expert, regularizer)
    for key in ("loss_meta", "loss_imitation", "loss_inner_qvalue", "loss_inner_actor"):
        torch.testing.assert_close(out[key], separate[key], rtol=0, atol=0)
    (out["loss_qvalue"] + out["loss_meta"]).backward()
    for p, g in zip(reward.parameters(), meta_grads):
        torch.testing.assert_close(p.grad, g, rtol=0, atol=0)
    joint_q_grads = [p.grad.clone() for p in sac.qvalue_network_params.values(True, True)]
    assert all(p.grad is None for p in sac.actor_network_params.values(True, True))

    # reference: plain SAC critic loss on the local reward r_m + r_w (no grad)
    sac.zero_grad(set_to_none=True)
    td = online.clone()
    with torch.no_grad():
        td["next", "reward"] = td["next", "matching_reward"] + reward(td.select("observation"))["intrinsic_reward"]
    torch.manual_seed(7)
    ref_q, _ = sac.qvalue_v2_loss(td)
    torch.testing.assert_close(out["loss_qvalue"], ref_q.detach(), rtol=1e-12, atol=0)
    ref_q.backward()
    for p, g in zip(sac.qvalue_network_params.values(True, True), joint_q_grads):
        torch.testing.assert_close(g, p.grad, rtol=1e-10, atol=1e-12)

    # the actor loss is SACLoss's (detached critics): gradients reach the actor only
    sac.zero_grad(set_to_none=True)
    out["loss_actor"].backward()
    assert all(p.grad is not None for p in sac.actor_network_params.values(True, True))
    assert all(p.grad is None for p in sac.qvalue_network_params.values(True, True))
    assert torch.isclose(out["alpha"], torch.tensor(0.01, dtype=out["alpha"].dtype, device=out["alpha"].device))


class _Shifted(nn.Module):
    """A reward network with a trainable constant added to its output."""

    def __init__(self, net: nn.Module) -> None:
        super().__init__()
        self.net = net
        self.offset = nn.Parameter(torch.tensor(0.3, dtype=torch.float64))

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.net(obs) + self.offset


def test_expert_centred_reward_has_no_constant_shift_direction():
    """ExpertCenteredReward: a constant added to r_w changes nothing, so the meta-gradient never
    moves it, while the state-dependent parameters still receive a meta-gradient."""
    from torchrl_csirl.modules import ExpertCenteredReward

    sac, reward, _, online, expert, regularizer = _setup(reward_l1_coef=0.0)
    shifted = TensorDictModule(_Shifted(reward.module), in_keys=["observation"], out_keys=["intrinsic_reward"])
    centred = ExpertCenteredReward(shifted, expert["observation"], scale=2.0)
    before = centred(online.select("observation").clone())["intrinsic_reward"]
    with torch.no_grad():
        shifted.module.offset += 5.0
    after = centred(online.select("observation").clone())["intrinsic_reward"]
    torch.testing.assert_close(before, after)
    torch.testing.assert_close(centred(expert.select("observation").clone())["intrinsic_reward"].mean(),
                               torch.zeros((), dtype=torch.float64), atol=1e-12, rtol=0)

    for l1, meta_gradient in itertools.product((0.0, 1.0), ("double_backward", "jvp")):
        meta = MetaRewardLoss(sac, centred, reward_l1_coef=l1, meta_gradient=meta_gradient)
        centred.zero_grad()
        meta(online, expert, regularizer)["loss_meta"].backward()
        assert abs(shifted.module.offset.grad.item()) < 1e-10
        assert sum(p.grad.abs().sum() for p in reward.parameters()) > 0

    with pytest.raises(ValueError, match="state-only"):
        ExpertCenteredReward(make_reward_network(OBS, action_dim=ACT), expert["observation"])
    with pytest.raises(ValueError, match="non-empty"):
        ExpertCenteredReward(shifted, torch.zeros(0, OBS))


# ---------------------------------------------------------------------- meta_gradient="jvp"
def _meta_gradient(meta, reward, online, expert, regularizer, seed):
    reward.zero_grad()
    torch.manual_seed(seed)
    out = meta(online, expert, regularizer)
    loss = out["loss_meta"]
    if meta.joint_sac_update:
        loss = loss + out["loss_qvalue"] + out["loss_actor"]
    loss.backward()
    return out, torch.cat([p.grad.flatten() for p in reward.parameters()])


@pytest.mark.parametrize("joint_sac_update", [False, True])
@pytest.mark.parametrize("gradient_balance", ["sum", "normalized"])
@pytest.mark.parametrize("use_matching_reward", [True, False])
@pytest.mark.parametrize("reward_l1_coef", [0.0, 1.0])
def test_jvp_meta_gradient_matches_double_backward(joint_sac_update, gradient_balance, use_matching_reward,
                                                    reward_l1_coef):
    """float64 parity of the closed-form critic step with the double backward, on random batches."""
    options = {"joint_sac_update": joint_sac_update, "gradient_balance": gradient_balance,
                   "use_matching_reward": use_matching_reward, "reward_l1_coef": reward_l1_coef}
    sac, reward, reference, _, _, _ = _setup(**options)
    jvp = MetaRewardLoss(sac, reward, meta_gradient="jvp", **options)
    for draw in range(3):
        g = torch.Generator().manual_seed(100 + draw)
        n = 7
        online = random_transitions(n, OBS, ACT, dtype=torch.float64, generator=g, reward_key="matching_reward")
        online["next", "terminated"][draw] = True
        expert = TensorDict({"observation": torch.randn(4, OBS, generator=g, dtype=torch.float64),
                             "action": torch.rand(4, ACT, generator=g, dtype=torch.float64) * 1.6 - 0.8}, [4])
        regularizer = None if draw == 2 else online.apply(lambda x: x.clone())
        if regularizer is not None:
            regularizer["observation"] = torch.randn(n, OBS, generator=g, dtype=torch.float64)
        sac.zero_grad(set_to_none=True)
        out_ref, grad_ref = _meta_gradient(reference, reward, online, expert, regularizer, seed=draw)
        sac_grads_ref = [p.grad for p in sac.parameters()]
        sac.zero_grad(set_to_none=True)
        out_jvp, grad_jvp = _meta_gradient(jvp, reward, online, expert, regularizer, seed=draw)
        assert grad_ref.abs().max() > 0
        torch.testing.assert_close(grad_jvp, grad_ref, rtol=1e-6, atol=1e-6 * grad_ref.abs().max().item())
        for key in sorted(out_ref.keys()):
            if key.startswith("meta_grad_norm"):
                torch.testing.assert_close(out_jvp[key], out_ref[key], rtol=1e-6, atol=0)
            else:  # the losses and the SAC step: the same operations, bit for bit
                torch.testing.assert_close(out_jvp[key], out_ref[key], rtol=0, atol=0)
        for a, b in zip(sac_grads_ref, (p.grad for p in sac.parameters())):
            assert (a is None and b is None) or torch.equal(a, b)


def test_jvp_meta_gradient_options():
    """Deterministic expert actions, a smooth critic activation, priority weights; and what the path refuses."""
    sac, reward, reference, online, expert, regularizer = _setup(deterministic_expert_action=True)
    jvp = MetaRewardLoss(sac, reward, deterministic_expert_action=True, meta_gradient="jvp")
    _, ref = _meta_gradient(reference, reward, online, expert, regularizer, seed=0)
    _, new = _meta_gradient(jvp, reward, online, expert, regularizer, seed=0)
    torch.testing.assert_close(new, ref, rtol=1e-6, atol=1e-6 * ref.abs().max().item())

    # tanh critics (the activation's derivative through torch.func.jvp), priority-weighted critic loss
    torch.manual_seed(0)
    critic = make_qvalue(OBS, ACT, hidden=(6,)).to(torch.float64)
    critic.module.mlp[1] = nn.Tanh()
    sac = EnsembleSACLoss(make_actor(OBS, ACT, hidden=(6,)).to(torch.float64), critic, num_qvalue_nets=3).to(
        torch.float64)
    assert sac.fused_qvalue
    weighted = online.clone()
    weighted["priority_weight"] = torch.rand(weighted.shape[0], dtype=torch.float64)
    sac.set_keys(priority_weight="priority_weight")
    for batch in (online, weighted):
        reference = MetaRewardLoss(sac, reward)
        jvp = MetaRewardLoss(sac, reward, meta_gradient="jvp")
        _, ref = _meta_gradient(reference, reward, batch, expert, regularizer, seed=1)
        _, new = _meta_gradient(jvp, reward, batch, expert, regularizer, seed=1)
        torch.testing.assert_close(new, ref, rtol=1e-6, atol=1e-6 * ref.abs().max().item())

    with pytest.raises(ValueError, match="meta_gradient"):
        MetaRewardLoss(sac, reward, meta_gradient="forward")
    vmapped = EnsembleSACLoss(make_actor(OBS, ACT, hidden=(6,)), make_qvalue(OBS, ACT, hidden=(6,)), fused_qvalue=False)
    with pytest.raises(ValueError, match="fused critic ensemble"):
        MetaRewardLoss(vmapped, reward, meta_gradient="jvp")


@pytest.mark.parametrize("device", DEVICES)
def test_jvp_meta_gradient_matches_finite_differences(device):
    sac, reward, _, online, expert, regularizer = _setup(device=device, reward_l1_coef=0.0)
    meta = MetaRewardLoss(sac, reward, reward_l1_coef=0.0, meta_gradient="jvp")
    torch.manual_seed(123)
    meta(online, expert, regularizer)["loss_meta"].backward()
    analytic = torch.cat([p.grad.flatten() for p in reward.parameters()])
    numeric = torch.cat([g.flatten() for g in _finite_difference(meta, reward, online, expert, regularizer)])
    assert analytic.abs().max() > 1e-6
    torch.testing.assert_close(analytic, numeric, rtol=1e-4, atol=1e-4 * analytic.abs().max().item())


@pytest.mark.parametrize("activation", [None, nn.Tanh(), nn.ELU()])
def test_fused_critic_jvp_matches_central_differences(activation):
    """FusedCriticEnsemble.jvp along a parameter direction, with and without the recorded activations."""
    from torchrl_csirl.modules.ensemble import fused_critic_ensemble

    torch.manual_seed(0)
    critic = make_qvalue(OBS, ACT, hidden=(6, 5)).to(torch.float64)
    if activation is not None:
        critic.module.mlp[1] = activation
        critic.module.mlp[3] = copy.deepcopy(activation)
    fused = fused_critic_ensemble(critic)
    params = TensorDict.from_module(critic).expand(3).clone().apply(lambda p: p + 0.1 * torch.randn_like(p))
    tangents = params.apply(torch.randn_like)
    x = torch.randn(7, OBS + ACT, dtype=torch.float64)
    eps = 1e-6
    numeric = (fused.values(x, params + eps * tangents) - fused.values(x, params - eps * tangents)) / (2 * eps)
    cache = []
    fused.values(x, params, cache)
    for recorded in (None, cache):
        torch.testing.assert_close(fused.jvp(x, params, tangents, recorded), numeric, rtol=1e-6, atol=1e-8)


def test_jvp_meta_gradient_on_sacloss_own_path():
    """fused=False (SACLoss's losses, fused critics): the forward-mode pass runs the critics again."""
    torch.manual_seed(0)
    sac = EnsembleSACLoss(make_actor(OBS, ACT, hidden=(6,)).to(torch.float64),
                          make_qvalue(OBS, ACT, hidden=(6,)).to(torch.float64), num_qvalue_nets=3,
                          fused=False).to(torch.float64)
    _, reward, _, online, expert, regularizer = _setup()
    _, ref = _meta_gradient(MetaRewardLoss(sac, reward), reward, online, expert, regularizer, seed=2)
    _, new = _meta_gradient(MetaRewardLoss(sac, reward, meta_gradient="jvp"), reward, online, expert, regularizer, seed=2)
    torch.testing.assert_close(new, ref, rtol=1e-6, atol=1e-6 * ref.abs().max().item())
