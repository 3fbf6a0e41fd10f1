"""Pins the TorchRL internals torchrl_csirl/_compat.py reaches into: a TorchRL upgrade that
changes one of them fails here, by name."""
from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from torchrl.collectors import Collector
from torchrl.objectives import SACLoss
from transitions import random_transitions

from torchrl_csirl import _compat
from torchrl_csirl.modules import make_actor, make_qvalue
from torchrl_csirl.objectives import EnsembleSACLoss
from torchrl_csirl.tasks import SCENARIOS, make_env, make_serial_env
from torchrl_csirl.trainers import shutdown_collector


def _batch(n: int = 6, obs: int = 4, act: int = 2) -> TensorDict:
    return random_transitions(n, obs, act)


@pytest.fixture
def loss():
    torch.manual_seed(0)
    # SACLoss's own path (fused=False): these tests pin the TorchRL behaviour it relies on
    return EnsembleSACLoss(
        make_actor(4, 2, hidden=(8,)), make_qvalue(4, 2, hidden=(8,)), num_qvalue_nets=3, fused=False
    )


def test_sac_internals_exist_with_the_signatures_we_override():
    _compat.check_sac_internals()


def test_sac_target_is_computed_without_graph_by_compute_target_v2(loss):
    """EnsembleSACLoss's differentiable reward relies on: SACLoss routes the critic target through
    ``_compute_target_v2`` and computes it under no_grad."""
    calls = []
    original = SACLoss._compute_target_v2

    def spy(self, tensordict):
        out = original(self, tensordict)
        calls.append(out.requires_grad)
        return out

    td = _batch()
    td["next", "reward"].requires_grad_(True)
    SACLoss._compute_target_v2 = spy
    try:
        loss.qvalue_v2_loss(td)
    finally:
        SACLoss._compute_target_v2 = original
    assert calls == [False]


def test_sac_actor_loss_reads_the_detached_critic_params(loss):
    """The actor loss evaluates Q with ``_cached_detached_qvalue_params`` (no graph to the critics)."""
    params = _compat.detached_qvalue_params(loss)
    assert params.batch_size == torch.Size([3])
    assert not any(p.requires_grad for p in params.values(True, True))
    loss_actor, _ = loss.actor_loss(_batch())
    loss_actor.backward()
    assert all(p.grad is None for p in loss.qvalue_network_params.values(True, True))


def test_vmap_over_critic_params_gives_one_value_per_critic(loss):
    td = _batch().select(*loss.qvalue_network.in_keys)
    out = _compat.vmap_qvalue_networks(loss, td, loss.qvalue_network_params)
    assert out.get("state_action_value").shape == torch.Size([3, 6, 1])


def test_every_critic_evaluation_goes_through_the_installed_evaluator(loss):
    """The fused critic ensemble relies on: SACLoss evaluates its N critics (target, critic loss,
    actor loss) only through ``_vmap_qnetworkN0``, which ``_make_vmap`` builds."""
    fused = loss._vmap_qnetworkN0
    calls = []

    def spy(tensordict, params):
        calls.append(params.batch_size)
        return fused(tensordict, params)

    _compat.set_qvalue_ensemble_evaluator(loss, spy)
    loss(_batch())
    assert calls == [torch.Size([3])] * 3  # target, critic loss, actor loss
    loss._make_vmap()  # what set_vmap_randomness calls: EnsembleSACLoss re-installs its evaluator
    assert loss._vmap_qnetworkN0 is fused


def test_alpha_and_its_reduced_loss(loss):
    assert torch.isclose(_compat.sac_alpha(loss), loss.log_alpha.exp())
    log_prob = torch.randn(6)
    value = _compat.sac_reduced_alpha_loss(loss, log_prob, _batch())
    assert value.shape == torch.Size([]) and torch.isclose(value, loss.alpha_loss(log_prob).mean())


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_fused_actor_draws_and_scores_as_tanh_normal(dtype):
    """The fused actor writes TorchRL's ``TanhNormal`` (low -1, high 1, safe tanh) out op for op:
    same random draw, bit-identical action, log-probability and gradients (saturated draws included)."""
    from torchrl.modules import TanhNormal
    from torchrl.modules.distributions.utils import rsample_and_log_prob

    from torchrl_csirl.modules.fused_actor import FusedTanhNormalActor

    loc = (torch.randn(7, 3, dtype=dtype) * torch.tensor([1.0, 1.0, 30.0], dtype=dtype)).requires_grad_(True)
    scale = torch.rand(7, 3, dtype=dtype).add(0.05).requires_grad_(True)
    results = []
    for sample in (
        lambda: rsample_and_log_prob(TanhNormal(loc, scale, low=-1.0, high=1.0)),
        lambda: FusedTanhNormalActor.rsample_and_log_prob(loc, scale),
    ):
        torch.manual_seed(3)
        action, log_prob = sample()
        grads = torch.autograd.grad((action.sum() + log_prob.sum()), (loc, scale))
        results.append((action, log_prob, *grads))
    for stock, fused in zip(*results):
        assert torch.equal(stock, fused)
    torch.manual_seed(3)
    stock_rsample = TanhNormal(loc, scale, low=-1.0, high=1.0).rsample()
    torch.manual_seed(3)
    assert torch.equal(FusedTanhNormalActor.rsample(loc, scale), stock_rsample)
    deterministic = TanhNormal(loc, scale, low=-1.0, high=1.0).deterministic_sample
    assert torch.equal(FusedTanhNormalActor.deterministic_sample(loc), deterministic)


def test_parallel_env_internals():
    _compat.check_parallel_env_internals()
    from torchrl_csirl.tasks import YieldingParallelEnv

    env = YieldingParallelEnv(2, _merge_env)
    try:
        env.rollout(2, break_when_any_done=False)
        _compat.check_parallel_env_internals(env)
        assert len(env._shm_done_flags) >= 2
    finally:
        env.close()


def _merge_env():
    return make_env("merge")


def test_multi_process_collector_keeps_weight_sync_schemes_and_exits_after_their_shutdown():
    spec = SCENARIOS["merge"]
    collector = Collector([_one_serial_env] * 2, make_actor(spec.obs_dim, spec.action_dim), num_collectors=2,
                          sync=True, frames_per_batch=20, total_frames=-1, auto_register_policy_transforms=False)
    try:
        next(iter(collector))
        assert _compat.collector_weight_sync_schemes(collector)  # what shutdown_collector stops
        procs = _compat.collector_worker_processes(collector)  # what WorkerErrorLog inspects
        assert len(procs) == 2 and all(p.is_alive() and p.pid for p in procs)
    finally:
        shutdown_collector(collector)
    assert _compat.collector_weight_sync_schemes(object()) == {}
    assert _compat.collector_worker_processes(object()) == []


def _one_serial_env():
    return make_serial_env("merge", 1)


def test_gym_env_of_returns_the_wrapped_gymnasium_env():
    import gymnasium

    env = make_env("merge", seed=0)
    inner = _compat.gym_env_of(env)
    assert isinstance(inner, gymnasium.Env)
    env.reset()
    assert inner.unwrapped.vehicle is not None  # the scene the TorchRL env steps
    with pytest.raises(_compat.TorchRLInternalsChanged, match="has no _env"):
        _compat.gym_env_of(torch.nn.Identity())
