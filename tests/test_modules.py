from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from torch import nn
from torchrl.modules import TanhNormal

from torchrl_csirl.modules import (
    BoundedLogStdNormalParams,
    EgoRelativeFeatures,
    FusedCriticEnsemble,
    MaskedReLU,
    fused_critic_ensemble,
    make_actor,
    make_qvalue,
)
from torchrl_csirl.modules.actor_critic import masked_relu


def _linears(module: nn.Module) -> list[nn.Linear]:
    return [m for m in module.modules() if isinstance(m, nn.Linear)]


def test_actor_architecture_and_outputs():
    torch.manual_seed(0)
    actor = make_actor(25, 2)
    sizes = [(lin.in_features, lin.out_features) for lin in _linears(actor)]
    assert sizes == [(25, 256), (256, 256), (256, 4)]
    assert sum(isinstance(m, MaskedReLU) for m in actor.modules()) == 2
    td = actor(TensorDict({"observation": torch.randn(64, 25) * 10}, [64]))
    for key in ("loc", "scale", "action", "action_log_prob"):
        assert key in td.keys()
    assert td["action"].shape == (64, 2)
    assert td["action"].abs().max() <= 1.0
    assert torch.isfinite(td["action_log_prob"]).all()
    assert isinstance(actor.get_dist(td), TanhNormal)


def test_actor_log_std_is_bounded():
    head = BoundedLogStdNormalParams(-5.0, 2.0)
    x = torch.cat([torch.zeros(3, 2), torch.tensor([[-1e3, -1e3], [0.0, 0.0], [1e3, 1e3]])], -1)
    loc, scale = head(x)
    log_std = scale.log()
    assert torch.allclose(log_std[0], torch.full((2,), -5.0))
    assert torch.allclose(log_std[1], torch.full((2,), -1.5))
    assert torch.allclose(log_std[2], torch.full((2,), 2.0))
    assert torch.equal(loc, torch.zeros(3, 2))


def test_actor_custom_in_key_and_hidden():
    actor = make_actor(3, 1, hidden=(16,), in_key="obs")
    assert [lin.out_features for lin in _linears(actor)] == [16, 2]
    td = actor(TensorDict({"obs": torch.randn(5, 3)}, [5]))
    assert td["action"].shape == (5, 1)


def test_qvalue_architecture_and_outputs():
    q = make_qvalue(25, 2)
    assert q.in_keys == ["observation", "action"]
    assert q.out_keys == ["state_action_value"]
    sizes = [(lin.in_features, lin.out_features) for lin in _linears(q)]
    assert sizes == [(27, 256), (256, 256), (256, 1)]
    assert sum(isinstance(m, MaskedReLU) for m in q.modules()) == 2
    td = TensorDict({"observation": torch.randn(7, 25), "action": torch.rand(7, 2)}, [7])
    value = q(td)["state_action_value"]
    assert value.shape == (7, 1)
    # Q depends on the action
    td2 = td.clone()
    td2["action"] = -td["action"]
    assert not torch.allclose(q(td2)["state_action_value"], value)


@pytest.mark.parametrize("bad", [dict(obs_dim=0), dict(action_dim=-1), dict(hidden=()), dict(hidden=(8, 0))])
def test_bad_dimensions_raise(bad):
    kwargs = dict(obs_dim=4, action_dim=2, hidden=(8,))
    kwargs.update(bad)
    with pytest.raises(ValueError):
        make_actor(**kwargs)
    with pytest.raises(ValueError):
        make_qvalue(**kwargs)


def test_log_std_bounds_validated():
    with pytest.raises(ValueError):
        make_actor(4, 2, log_std_min=1.0, log_std_max=0.0)


def test_reward_network_is_reexported():
    from torchrl_csirl import modules
    from torchrl_csirl.modules import reward

    assert modules.make_reward_network is reward.make_reward_network


@pytest.mark.parametrize("activation", ["elu", "silu", "tanh"])
def test_smooth_reward_activation_keeps_gradient_where_relu_units_are_dead(activation):
    """With every hidden pre-activation negative a ReLU r_w is constant and gets no gradient below its
    output layer; a smooth activation still varies with the state and passes gradient to every layer."""
    from torchrl_csirl.modules import REWARD_ACTIVATIONS, make_reward_network

    obs = TensorDict({"observation": torch.rand(32, 4)}, [32])
    grads, spreads = {}, {}
    for name in ("relu", activation):
        torch.manual_seed(0)
        net = make_reward_network(4, hidden=(8, 8), activation=name)
        assert any(isinstance(m, REWARD_ACTIVATIONS[name]) for m in net.modules())
        first, second = _linears(net)[:2]
        with torch.no_grad():  # kill every unit of both hidden layers (inputs are in [0, 1))
            first.weight.abs_().neg_()
            first.bias.fill_(-1.0)
            second.bias.fill_(-3.0)
        reward = net(obs)["intrinsic_reward"]
        reward.sum().backward()
        grads[name], spreads[name] = first.weight.grad.abs().sum(), reward.std()
    assert grads["relu"] == 0 and spreads["relu"] < 1e-6
    assert grads[activation] > 0 and spreads[activation] > 1e-6


def test_reward_network_rejects_unknown_activation():
    from torchrl_csirl.modules import make_reward_network

    with pytest.raises(ValueError, match="activation must be one of"):
        make_reward_network(4, activation="gelu")


def test_masked_relu_matches_relu_values_and_gradients():
    x = torch.randn(50, dtype=torch.float64, requires_grad=True)
    x.data[0] = 0.0
    y1 = MaskedReLU()(x)
    (g1,) = torch.autograd.grad(y1.pow(2).sum(), x)
    y2 = torch.relu(x)
    (g2,) = torch.autograd.grad(y2.pow(2).sum(), x)
    assert torch.equal(y1, y2)
    assert torch.equal(g1, g2)


def test_masked_relu_under_vmap_and_without_second_order_edge():
    x = torch.randn(3, 8, dtype=torch.float64)
    x[0, 0] = 0.0
    assert torch.equal(torch.vmap(masked_relu)(x), torch.relu(x))  # the functorch-capable path
    assert torch.equal(torch.vmap(torch.func.grad(lambda v: masked_relu(v).pow(2).sum()))(x),
                       torch.vmap(torch.func.grad(lambda v: torch.relu(v).pow(2).sum()))(x))
    # d/dx of the input gradient: no edge back through the mask (the point of MaskedReLU)
    xs = x.clone().requires_grad_(True)
    (g,) = torch.autograd.grad(masked_relu(xs).sum(), xs, create_graph=True)
    assert not g.requires_grad


def _stacked_params(critics: list[nn.Module]) -> TensorDict:
    return TensorDict.from_modules(*critics, as_module=False)


def _vmapped_values(critic: nn.Module, params: TensorDict, td: TensorDict) -> torch.Tensor:
    def call(p):
        with p.to_module(critic):
            return critic(td.clone())["state_action_value"]

    return torch.vmap(call)(params)


@pytest.mark.parametrize("features", [False, True])
@pytest.mark.parametrize("batch", [(7,), (3, 4)])
def test_fused_critic_ensemble_matches_vmap(features, batch):
    torch.manual_seed(0)
    obs_dim = 25
    feats = EgoRelativeFeatures(5, 5, relative_indices=[1, 2], gains=[1.0, 1.0]) if features else None
    critics = [make_qvalue(obs_dim, 2, hidden=(32, 16), input_features=feats) for _ in range(4)]
    fused = fused_critic_ensemble(critics[0])
    assert isinstance(fused, FusedCriticEnsemble)
    params = _stacked_params(critics).apply(lambda p: p.detach().requires_grad_(True))
    td = TensorDict({"observation": torch.randn(*batch, obs_dim),
                     "action": (torch.rand(*batch, 2) * 2 - 1).requires_grad_(True)}, list(batch))
    out = fused(td, params)
    assert out.batch_size == torch.Size([4, *batch])
    value = out["state_action_value"]
    expected = _vmapped_values(critics[0], params, td)
    assert torch.equal(value, expected)  # forward values are bit-identical
    leaves = [td["action"], *params.values(True, True)]
    weights = torch.randn_like(value)
    grads = torch.autograd.grad((value * weights).sum(), leaves)
    expected_grads = torch.autograd.grad((expected * weights).sum(), leaves)
    for g, e in zip(grads, expected_grads):
        assert torch.equal(g, e)


def test_fused_critic_ensemble_second_order_matches_vmap():
    torch.manual_seed(0)
    critics = [make_qvalue(4, 2, hidden=(6, 5)).double() for _ in range(3)]
    params = _stacked_params(critics).apply(lambda p: p.detach().requires_grad_(True))
    td = TensorDict({"observation": torch.randn(5, 4, dtype=torch.float64),
                     "action": torch.rand(5, 2, dtype=torch.float64)}, [5])
    target = torch.randn(3, 5, 1, dtype=torch.float64, requires_grad=True)
    leaves = list(params.values(True, True))

    def second_order(values):
        grads = torch.autograd.grad(((values - target) ** 2).sum(), leaves, create_graph=True)
        return torch.autograd.grad(sum(g.pow(2).sum() for g in grads), target)[0]

    fused = fused_critic_ensemble(critics[0])
    torch.testing.assert_close(second_order(fused(td, params)["state_action_value"]),
                               second_order(_vmapped_values(critics[0], params, td)), rtol=1e-10, atol=1e-12)


def test_fused_critic_ensemble_rejects_unknown_critics():
    assert fused_critic_ensemble(nn.Linear(3, 1)) is None
    from tensordict.nn import TensorDictModule

    other = TensorDictModule(nn.Sequential(nn.Linear(3, 1)), in_keys=["observation"], out_keys=["v"])
    assert fused_critic_ensemble(other) is None
    with_norm = make_qvalue(4, 2, hidden=(8,))
    with_norm.module.mlp.insert(1, nn.LayerNorm(8))  # a layer with parameters between the linears
    assert fused_critic_ensemble(with_norm) is None
    with pytest.raises(ValueError, match="batch size"):
        fused_critic_ensemble(make_qvalue(4, 2, hidden=(8,)))(
            TensorDict({"observation": torch.randn(2, 4), "action": torch.rand(2, 2)}, [2]),
            TensorDict.from_module(make_qvalue(4, 2, hidden=(8,))),
        )
