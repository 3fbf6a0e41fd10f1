from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from torch import nn

from torchrl.modules import TanhNormal

from torchrl_csirl.modules import BoundedLogStdNormalParams, MaskedReLU, make_actor, make_qvalue


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


def test_masked_relu_matches_relu_values_and_gradients():
    x = torch.randn(50, dtype=torch.float64, requires_grad=True)
    x.data[0] = 0.0
    y1 = MaskedReLU()(x)
    (g1,) = torch.autograd.grad(y1.pow(2).sum(), x)
    y2 = torch.relu(x)
    (g2,) = torch.autograd.grad(y2.pow(2).sum(), x)
    assert torch.equal(y1, y2)
    assert torch.equal(g1, g2)
