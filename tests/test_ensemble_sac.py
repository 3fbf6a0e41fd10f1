from __future__ import annotations

import math
import warnings

import pytest
import torch
from devices import DEVICES
from tensordict.nn import TensorDictModule
from torchrl.objectives import SACLoss, SoftUpdate
from transitions import random_transitions

from torchrl_csirl.modules import make_input_features
from torchrl_csirl.modules.actor_critic import make_actor, make_qvalue
from torchrl_csirl.objectives import EnsembleSACLoss, qvalue_dispersion
from torchrl_csirl.tasks import SCENARIOS

OBS, ACT, HID = 5, 2, (16, 16)


def _batch(n=8, seed=1, **flags):
    g = torch.Generator().manual_seed(seed)
    td = random_transitions(n, OBS, ACT, generator=g)
    td["next", "truncated"] = torch.zeros(n, 1, dtype=torch.bool)
    for key, value in flags.items():
        td["next", key] = torch.full((n, 1), value)
    return td


def _loss(**kwargs):
    torch.manual_seed(0)
    return EnsembleSACLoss(make_actor(OBS, ACT, hidden=HID), make_qvalue(OBS, ACT, hidden=HID), **kwargs)


def test_defaults():
    """The recipes' (CSIRL_DEFAULTS): SAC's automatic temperature from 0.01 (issue 89; the paper fixes it)."""
    loss = _loss()
    assert loss.num_qvalue_nets == 5
    assert not loss.fixed_alpha and math.isclose(loss._alpha.item(), 0.01, rel_tol=1e-6)
    assert math.isclose(loss.value_estimator.gamma.item(), 0.99, rel_tol=1e-6)
    assert loss.loss_function == "l2"
    assert any(p is loss.log_alpha for p in loss.parameters())
    fixed = _loss(fixed_alpha=True)  # the paper's
    assert fixed.fixed_alpha and not any(p is fixed.log_alpha for p in fixed.parameters())


def test_critics_are_independently_initialised():
    loss = _loss()
    params = loss.qvalue_network_params
    for key, value in params.items(True, True):
        assert value.shape[0] == 5
        flat = value.detach().reshape(5, -1)
        for i in range(5):
            for j in range(i + 1, 5):
                assert not torch.equal(flat[i], flat[j]), key
    # each member follows nn.Linear's default init: |W| <= 1/sqrt(fan_in)
    first = params["module", "mlp", "0", "weight"]
    bound = 1 / math.sqrt(OBS + ACT)
    assert first.abs().max() <= bound
    # ... and is not a uniform resampling over the [min, max] of a single init
    stds = first.detach().reshape(5, -1).std(1)
    assert torch.allclose(stds, torch.full_like(stds, bound / math.sqrt(3)), rtol=0.15)
    # targets start equal to the online critics
    for key, value in loss.target_qvalue_network_params.items(True, True):
        assert torch.equal(value, params.get(key).detach())


def test_list_of_critics():
    torch.manual_seed(0)
    critics = [make_qvalue(OBS, ACT, hidden=HID) for _ in range(3)]
    loss = EnsembleSACLoss(make_actor(OBS, ACT, hidden=HID), critics, num_qvalue_nets=3)
    w = loss.qvalue_network_params["module", "mlp", "0", "weight"]
    for k, critic in enumerate(critics):
        assert torch.equal(w[k], critic.module.mlp[0].weight)
    with pytest.raises(ValueError, match="num_qvalue_nets"):
        EnsembleSACLoss(make_actor(OBS, ACT, hidden=HID), critics, num_qvalue_nets=5)


def test_qvalues_match_each_member():
    loss = _loss()
    td = _batch()
    q = loss.qvalues(td)
    assert q.shape == (5, 8)
    member = make_qvalue(OBS, ACT, hidden=HID)
    for k in range(5):
        with loss.qvalue_network_params[k].to_module(member):
            expected = member(td.select("observation", "action"))["state_action_value"].squeeze(-1)
        torch.testing.assert_close(q[k], expected)


def test_dispersion():
    loss = _loss()
    td = _batch()
    q = loss.qvalues(td).detach()
    var = ((q - q.mean(0)) ** 2).mean(0)
    torch.testing.assert_close(loss.qvalue_dispersion(td), var)
    torch.testing.assert_close(loss.qvalue_dispersion(q), var)
    torch.testing.assert_close(loss.qvalue_dispersion(q, "abs_cv"), (var / q.mean(0)).abs())
    abs_cv_loss = _loss(dispersion="abs_cv")
    torch.testing.assert_close(abs_cv_loss.qvalue_dispersion(q), (var / q.mean(0)).abs())
    with pytest.raises(ValueError):
        qvalue_dispersion(q, "std")
    with pytest.raises(ValueError):
        qvalue_dispersion(q[:1])
    with pytest.raises(ValueError):
        _loss(dispersion="bogus")


def _plain_sac_like(loss: EnsembleSACLoss) -> SACLoss:
    plain = SACLoss(
        loss.actor_network,
        make_qvalue(OBS, ACT, hidden=HID),
        num_qvalue_nets=5,
        alpha_init=0.01,
        fixed_alpha=True,
        loss_function="l2",
    )
    plain.make_value_estimator(gamma=0.99)
    with torch.no_grad():
        plain.actor_network_params.update_(loss.actor_network_params.data)
        plain.qvalue_network_params.update_(loss.qvalue_network_params.data)
        plain.target_qvalue_network_params.update_(loss.target_qvalue_network_params.data)
    return plain


@pytest.mark.parametrize("differentiable", [False, True])
def test_identical_to_plain_sac(differentiable):
    loss = _loss()
    plain = _plain_sac_like(loss)
    td = _batch(16)
    td["next", "terminated"][:4] = True
    td["next", "done"][:8] = True
    td["next", "truncated"][4:8] = True
    torch.manual_seed(3)
    expected = plain(td.clone())
    reward = td["next", "reward"].clone().requires_grad_(differentiable)
    td_e = td.clone()
    td_e["next", "reward"] = reward
    loss.differentiable_reward = differentiable
    torch.manual_seed(3)
    out = loss(td_e)
    for key in ("loss_qvalue", "loss_actor", "loss_alpha", "entropy"):
        assert torch.equal(out[key], expected[key]), key
    if differentiable:
        (grad,) = torch.autograd.grad(out["loss_qvalue"], reward)
        assert grad.abs().sum() > 0
    else:
        assert not out["loss_qvalue"].requires_grad or not reward.requires_grad


def test_differentiable_reward_gradient_is_exact():
    """d L_Q / d r = -2/B * sum_k (Q_k - y) for the summed squared error."""
    loss = _loss()
    td = _batch(6)
    reward = td["next", "reward"].clone().requires_grad_(True)
    td["next", "reward"] = reward
    with loss.differentiable_reward_mode():
        torch.manual_seed(0)
        target = loss._compute_target_v2(td)
        torch.manual_seed(0)
        loss_q, _ = loss.qvalue_v2_loss(td)
    assert not loss.differentiable_reward
    (grad,) = torch.autograd.grad(loss_q, reward)
    q = loss.qvalues(td).detach()
    expected = (-2.0 / 6 * (q - target.detach()).sum(0)).unsqueeze(-1)
    torch.testing.assert_close(grad, expected)


def test_truncation_is_not_termination():
    loss = _loss()
    base = _batch(6)
    truncated = _batch(6, done=True, truncated=True, terminated=False)
    terminated = _batch(6, done=True, truncated=False, terminated=True)
    targets = {}
    for name, td in (("base", base), ("truncated", truncated), ("terminated", terminated)):
        torch.manual_seed(0)
        with torch.no_grad():
            targets[name] = loss._compute_target_v2(td)
    reward = base["next", "reward"].squeeze(-1)
    # truncated transitions bootstrap exactly like ongoing ones
    assert torch.equal(targets["truncated"], targets["base"])
    assert not torch.allclose(targets["truncated"], reward)
    # terminated transitions do not bootstrap
    torch.testing.assert_close(targets["terminated"], reward)


def test_set_keys_reward_and_terminated():
    loss = _loss()
    loss.set_keys(reward="local_reward", terminated="term")
    td = _batch(6)
    td["next", "local_reward"] = td["next", "reward"] * 0 + 3.0
    td["next", "term"] = torch.ones(6, 1, dtype=torch.bool)
    del td["next", "reward"]
    assert ("next", "local_reward") in loss.in_keys
    with torch.no_grad():
        target = loss._compute_target_v2(td)
    torch.testing.assert_close(target, torch.full((6,), 3.0))


def test_using_params_swaps_and_restores():
    loss = _loss()
    td = _batch(6)
    q0 = loss.qvalues(td).detach()
    zeros = loss.qvalue_network_params.data.apply(torch.zeros_like)
    with loss.using_params(qvalue_params=zeros):
        assert torch.equal(loss.qvalues(td), torch.zeros(5, 6))
    assert torch.equal(loss.qvalues(td).detach(), q0)
    # the actor loss sees non-detached critic parameters when asked to
    phi = loss.qvalue_network_params.data.apply(lambda p: p.clone().requires_grad_(True))
    with loss.using_params(actor_loss_qvalue_params=phi):
        loss_actor, _ = loss.actor_loss(td)
    grads = torch.autograd.grad(loss_actor, list(phi.values(True, True)), allow_unused=True)
    assert any(g is not None and g.abs().sum() > 0 for g in grads)
    # ... and the default actor loss does not
    loss_actor, _ = loss.actor_loss(td)
    loss_actor.backward()
    assert all(p.grad is None for p in loss.qvalue_network_params.values(True, True))
    with pytest.raises(ValueError):
        with loss.using_params(qvalue_params=zeros[:2]):
            pass


def test_training_step_with_soft_update():
    loss = _loss()
    updater = SoftUpdate(loss, tau=0.005)
    optim = torch.optim.Adam(loss.parameters(), lr=1e-3)
    target_before = loss.target_qvalue_network_params.clone()
    td = _batch(8)
    out = loss(td)
    (out["loss_qvalue"] + out["loss_actor"]).backward()
    optim.step()
    updater.step()
    online = loss.qvalue_network_params.data
    for key, value in loss.target_qvalue_network_params.items(True, True):
        expected = 0.995 * target_before.get(key) + 0.005 * online.get(key)
        torch.testing.assert_close(value, expected)


def _assert_same(a: torch.Tensor | None, b: torch.Tensor | None, device: str) -> None:
    """Bit for bit on the CPU; within float32 rounding on a GPU (batched and vmapped products use different kernels);
    ``None`` (no gradient, e.g. the temperature's outside ``loss_alpha``) on both sides."""
    if a is None or b is None:
        assert a is None and b is None
    elif device == "cpu":
        assert torch.equal(a, b)
    else:
        torch.testing.assert_close(a, b, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("device", DEVICES)
def test_fused_critic_ensemble_is_the_default_and_identical_to_vmap(device):
    fused, vmapped = _loss().to(device), _loss(fused_qvalue=False).to(device)
    assert fused.fused_qvalue and not vmapped.fused_qvalue
    assert set(fused.state_dict()) == set(vmapped.state_dict())  # same parameters, same checkpoints
    td = _batch(16).to(device)
    td["next", "terminated"][:4] = True
    outs, grads = [], []
    for loss in (fused, vmapped):
        torch.manual_seed(3)
        out = loss(td.clone())
        (out["loss_qvalue"] + out["loss_actor"]).backward()
        outs.append(out)
        grads.append([p.grad for p in loss.parameters()])
    for key in ("loss_qvalue", "loss_actor", "loss_alpha", "entropy"):
        _assert_same(outs[0][key], outs[1][key], device)
    for g_fused, g_vmap in zip(*grads):
        _assert_same(g_fused, g_vmap, device)
    _assert_same(fused.qvalues(td), vmapped.qvalues(td), device)
    assert fused.qvalues(_batch(12).reshape(3, 4).to(device)).shape == (5, 3, 4)


@pytest.mark.parametrize("batch", [7, 256])
def test_fused_paths_are_bit_identical_to_sacloss_in_float32_at_the_recipes_sizes(batch):
    """The README's learner (merge's input map, 2x256 networks, five critics): the fused critics and actor against
    vmap over TorchRL's critic and SACLoss's actor path, losses and every gradient ``torch.equal`` in float32.
    Small networks can hide a change of summation order that these sizes show (a first layer as ``expand`` +
    ``bmm`` instead of ``matmul`` changed the gradients here and passed at 2x8)."""
    spec = SCENARIOS["merge"]
    losses = []
    for fused in (True, False):
        torch.manual_seed(0)
        features = make_input_features(spec)
        losses.append(EnsembleSACLoss(make_actor(spec.obs_dim, spec.action_dim, input_features=features),
                                      make_qvalue(spec.obs_dim, spec.action_dim, input_features=features),
                                      fused=fused, fused_qvalue=fused))
    assert losses[0].fused and losses[0].fused_qvalue and not losses[1].fused and not losses[1].fused_qvalue
    td = random_transitions(batch, spec.obs_dim, spec.action_dim, generator=torch.Generator().manual_seed(2))
    td["next", "terminated"][:2] = True
    outs, grads = [], []
    for loss in losses:
        torch.manual_seed(3)
        out = loss(td.clone())
        (out["loss_qvalue"] + out["loss_actor"] + out["loss_alpha"]).backward()
        outs.append(out)
        grads.append([p.grad for p in loss.parameters()])
    for key in ("loss_qvalue", "loss_actor", "loss_alpha", "entropy"):
        assert torch.equal(outs[0][key], outs[1][key]), key
    assert len(grads[0]) == len(grads[1])
    for g_fused, g_stock in zip(*grads):
        _assert_same(g_fused, g_stock, "cpu")


def test_fused_critic_ensemble_survives_set_vmap_randomness():
    loss = _loss()
    loss.set_vmap_randomness("different")  # SACLoss rebuilds its vmapped callers
    assert loss.fused_qvalue
    assert loss.qvalues(_batch()).shape == (5, 8)


def test_fused_qvalue_true_needs_a_supported_critic():
    critic = TensorDictModule(
        torch.nn.Sequential(torch.nn.Linear(OBS + ACT, 1)), in_keys=["observation"], out_keys=["state_action_value"]
    )
    with pytest.raises(ValueError, match="fused_qvalue=True"):
        EnsembleSACLoss(make_actor(OBS, ACT, hidden=HID), critic, fused_qvalue=True)


def _fresh_notices(monkeypatch) -> None:
    from torchrl_csirl.objectives import ensemble_sac

    monkeypatch.setattr(ensemble_sac, "_NOTICES_GIVEN", set())


def test_differences_from_sacloss_logged_once(monkeypatch, caplog):
    _fresh_notices(monkeypatch)
    actor = make_actor(3, 2, hidden=(4,))
    with caplog.at_level("INFO", logger="torchrl"):
        EnsembleSACLoss(actor, make_qvalue(3, 2, hidden=(4,)))
        EnsembleSACLoss(actor, make_qvalue(3, 2, hidden=(4,)))
    lines = [r.getMessage() for r in caplog.records if "differs from SACLoss" in r.getMessage()]
    assert len(lines) == 1
    assert "num_qvalue_nets=5 (SACLoss: 2)" in lines[0] and "loss_function='l2'" in lines[0]
    _fresh_notices(monkeypatch)
    caplog.clear()
    with caplog.at_level("INFO", logger="torchrl"):  # SACLoss's own settings: nothing to say
        EnsembleSACLoss(actor, [make_qvalue(3, 2, hidden=(4,)) for _ in range(2)], num_qvalue_nets=2,
                        alpha_init=1.0, loss_function="smooth_l1")
    assert not [r for r in caplog.records if "differs from SACLoss" in r.getMessage()]
    from torchrl_csirl.objectives import make_csirl_learner

    _fresh_notices(monkeypatch)
    with caplog.at_level("INFO", logger="torchrl"):  # CSIRL's own learner: its settings are the recipe's on purpose
        make_csirl_learner(3, 2, hidden=(4,))
    assert not [r for r in caplog.records if "differs from SACLoss" in r.getMessage()]


def test_unfused_path_warned_once_with_its_reason(monkeypatch):
    from torchrl.modules import MLP, ValueOperator

    _fresh_notices(monkeypatch)
    actor = make_actor(3, 2, hidden=(4,))

    def torchrl_critic():
        return ValueOperator(MLP(in_features=5, out_features=1, num_cells=[4]), in_keys=["observation", "action"])

    with pytest.warns(UserWarning, match="unfused path: the critic is not a make_qvalue ConcatMLP"):
        EnsembleSACLoss(actor, torchrl_critic(), num_qvalue_nets=2)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        EnsembleSACLoss(actor, torchrl_critic(), num_qvalue_nets=2, fused_qvalue=False)  # asked for: silent
        EnsembleSACLoss(actor, torchrl_critic(), num_qvalue_nets=2)  # once per process
        EnsembleSACLoss(actor, make_qvalue(3, 2, hidden=(4,)), num_qvalue_nets=2)  # fused: silent
