"""The learner's precision (``optim.precision``): float32 unchanged, bfloat16 close to it, refused where not native."""
from __future__ import annotations

import contextlib

import pytest
import torch
from tensordict import TensorDict
from torchrl.modules import MLP
from torchrl.objectives import SoftUpdate

from torchrl_csirl.methods import csirl
from torchrl_csirl.modules import (
    LearnerPrecision,
    PrecisionUnsupported,
    fused_critic_ensemble,
    fused_tanh_normal_actor,
    make_actor,
    make_qvalue,
    make_reward_network,
)
from torchrl_csirl.modules import precision as precision_lib
from torchrl_csirl.objectives import EnsembleSACLoss, MetaRewardLoss
from torchrl_csirl.trainers import SACUpdate

BF16 = LearnerPrecision(torch.bfloat16)
OBS, ACT, BATCH, EXPERT = 25, 2, 256, 32


def _cosine(a: torch.Tensor, b: torch.Tensor) -> float:
    return float(torch.nn.functional.cosine_similarity(a.flatten(), b.flatten(), dim=0))


def _flat(grads) -> torch.Tensor:
    return torch.cat([g.flatten() for g in grads])


def _batch(seed: int, size: int) -> TensorDict:
    g = torch.Generator().manual_seed(seed)
    return TensorDict({
        "observation": torch.randn(size, OBS, generator=g),
        "action": torch.rand(size, ACT, generator=g) * 2 - 1,
        ("next", "observation"): torch.randn(size, OBS, generator=g),
        ("next", "matching_reward"): torch.randn(size, 1, generator=g),
        ("next", "done"): torch.zeros(size, 1, dtype=torch.bool),
        ("next", "terminated"): torch.zeros(size, 1, dtype=torch.bool),
        ("next", "truncated"): torch.zeros(size, 1, dtype=torch.bool),
    }, [size])


def test_fp32_is_no_context_and_the_settings_resolve(monkeypatch):
    assert isinstance(LearnerPrecision().autocast(), contextlib.nullcontext)
    assert LearnerPrecision.from_setting("fp32").dtype == torch.float32
    monkeypatch.setattr(precision_lib, "_cpu_flags", lambda: {"avx2", "amx_bf16"})
    assert LearnerPrecision.from_setting("auto").dtype == torch.bfloat16
    assert LearnerPrecision.from_setting("bf16").name == "bf16"
    monkeypatch.setattr(precision_lib, "_cpu_flags", lambda: {"avx2"})
    assert LearnerPrecision.from_setting("auto").dtype == torch.float32
    with pytest.raises(ValueError, match="precision='half'"):
        LearnerPrecision.from_setting("half")


def test_the_default_is_auto_and_resolves_by_the_hardware(monkeypatch):
    cfg = csirl.load_config([])
    assert cfg.optim.precision == "auto"
    monkeypatch.setattr(precision_lib, "_cpu_flags", lambda: {"avx2"})
    assert csirl.learner_precision(cfg).name == "fp32"
    monkeypatch.setattr(precision_lib, "_cpu_flags", lambda: {"avx2", "avx512_bf16"})
    assert csirl.learner_precision(cfg).name == "bf16"


def test_bf16_without_native_support_is_refused_in_one_line(monkeypatch):
    monkeypatch.setattr(precision_lib, "_cpu_flags", lambda: {"avx2", "avx512f"})
    with pytest.raises(PrecisionUnsupported) as err:
        LearnerPrecision.from_setting("bf16", "cpu")
    assert "\n" not in str(err.value) and "no native bfloat16" in str(err.value)
    with pytest.raises(csirl.ConfigError, match=r"optim.precision=bf16: this CPU has no native bfloat16 matmuls"):
        csirl.load_config(["optim.precision=bf16"])
    with pytest.raises(csirl.ConfigError, match="optim.precision=half: must be one of fp32, bf16, auto"):
        csirl.load_config(["optim.precision=half"])


def test_networks_keep_float32_outputs_close_to_fp32_under_bf16():
    torch.manual_seed(0)
    critic, actor = make_qvalue(OBS, ACT), make_actor(OBS, ACT)
    reward = make_reward_network(OBS)
    params = TensorDict.from_module(critic).expand(5).clone()
    for value in params.values(True, True):
        value.normal_(0, 0.1)
    fused_q, fused_pi = fused_critic_ensemble(critic), fused_tanh_normal_actor(actor)
    actor_params = TensorDict.from_module(actor)
    x = torch.randn(BATCH, OBS + ACT)
    obs = x[:, :OBS]
    td = TensorDict({"observation": obs}, [BATCH])
    exact = (fused_q.values(x, params), *fused_pi.dist_params(obs, actor_params), reward(td.clone())["intrinsic_reward"],
             critic.module(obs, x[:, OBS:]))
    with BF16.autocast():
        low = (fused_q.values(x, params), *fused_pi.dist_params(obs, actor_params),
               reward(td.clone())["intrinsic_reward"], critic.module(obs, x[:, OBS:]))
    for name, a, b in zip(("critics", "loc", "scale", "reward", "one critic"), exact, low):
        assert b.dtype == torch.float32, name
        assert not torch.equal(a, b), f"{name}: bf16 did not change the numbers (not in bf16?)"
        torch.testing.assert_close(b, a, rtol=0.03, atol=0.02 * float(a.detach().abs().mean()), msg=name)


def test_a_parameter_is_cast_once_per_block_and_again_after_a_step():
    w = torch.nn.Parameter(torch.randn(4, 4))
    with BF16.autocast():
        first = precision_lib.cast_weight(w, torch.bfloat16)
        assert precision_lib.cast_weight(w, torch.bfloat16) is first
        assert precision_lib.cast_weight(w * 1, torch.bfloat16) is not first  # not a leaf: cast each time
        with torch.no_grad():
            w.add_(1.0)  # an optimiser step bumps the version
        assert precision_lib.cast_weight(w, torch.bfloat16) is not first
    assert precision_lib.cast_weight(w, torch.bfloat16) is not first  # outside: no cache


def test_mlp_forward_is_the_mlp_at_fp32_and_ends_in_float32_under_bf16():
    mlp = MLP(in_features=6, out_features=2, num_cells=[16, 16])
    x = torch.randn(8, 6)
    assert torch.equal(precision_lib.mlp_forward(mlp, x), mlp(x))
    with BF16.autocast():
        out = precision_lib.mlp_forward(mlp, x)
    assert out.dtype == torch.float32
    torch.testing.assert_close(out, mlp(x), rtol=0.05, atol=0.02)


def _joint_losses_and_grads(precision: LearnerPrecision, meta_gradient: str = "double_backward"):
    torch.manual_seed(0)
    sac = EnsembleSACLoss(make_actor(OBS, ACT), make_qvalue(OBS, ACT))
    reward_net = make_reward_network(OBS)
    joint = MetaRewardLoss(sac, reward_net, joint_sac_update=True, meta_gradient=meta_gradient)
    online, regularizer = _batch(1, BATCH), _batch(2, BATCH)
    expert = _batch(3, EXPERT).select("observation", "action")
    torch.manual_seed(1)  # the same random draws (actor samples) on both sides
    with precision.autocast():
        out = joint(online, expert, regularizer)
    losses = {key: out[key] for key in ("loss_qvalue", "loss_actor", "loss_meta")}
    critic = list(sac.qvalue_network_params.values(True, True))
    actor = list(sac.actor_network_params.values(True, True))
    reward = list(reward_net.parameters())
    grads = {
        "critic": _flat(torch.autograd.grad(losses["loss_qvalue"], critic, retain_graph=True)),
        "actor": _flat(torch.autograd.grad(losses["loss_actor"], actor, retain_graph=True)),
        "meta": _flat(torch.autograd.grad(losses["loss_meta"], reward)),
    }
    return {k: v.detach() for k, v in losses.items()}, grads


@pytest.mark.parametrize("meta_gradient", ["double_backward", "jvp"])
def test_bf16_losses_and_meta_gradient_stay_within_tolerance_of_fp32(meta_gradient):
    """The stated tolerance (docs/performance.md#bfloat16): on fixed batches, each loss within 2 % of
    its float32 value and the meta-gradient (and the critic's and actor's gradients) at cosine >= 0.99."""
    exact_losses, exact_grads = _joint_losses_and_grads(LearnerPrecision(), meta_gradient)
    low_losses, low_grads = _joint_losses_and_grads(BF16, meta_gradient)
    for key, value in low_losses.items():
        assert value.dtype == torch.float32, key
        torch.testing.assert_close(value, exact_losses[key], rtol=0.02, atol=1e-4, msg=key)
    for key, grad in low_grads.items():
        assert grad.dtype == torch.float32
        assert _cosine(grad, exact_grads[key]) >= 0.99, (key, _cosine(grad, exact_grads[key]))
    assert not torch.equal(low_grads["meta"], exact_grads["meta"])  # bf16 did run


def test_the_update_runs_its_forward_pass_in_the_configured_precision():
    torch.manual_seed(0)
    sac = EnsembleSACLoss(make_actor(OBS, ACT), make_qvalue(OBS, ACT))
    seen = []
    forward = sac.forward

    def spy(td):
        seen.append(torch.is_autocast_enabled("cpu") and torch.get_autocast_dtype("cpu"))
        return forward(td)

    sac.forward = spy
    batch = _batch(0, 32)
    batch["next", "reward"] = batch["next", "matching_reward"]
    optim = torch.optim.Adam(sac.parameters(), lr=1e-3)
    for precision in (LearnerPrecision(), BF16):
        SACUpdate(sac, optim, SoftUpdate(sac, tau=0.005), sample=lambda: batch.clone(), precision=precision)(
            type("T", (), {"updates": 0, "frames": 0})())
        assert not torch.is_autocast_enabled("cpu")  # the backward ran outside
    assert seen == [False, torch.bfloat16]


@pytest.mark.skipif(not precision_lib.has_native_bf16("cpu"), reason="this CPU has no native bfloat16")
def test_a_tiny_bf16_run_trains_every_network(tmp_path):
    cfg = csirl.load_config([
        "collector.frames_per_batch=100", "collector.cut_episodes=true", "collector.init_random_frames=100",
        "replay_buffer.warmup_frames=100", "replay_buffer.batch_size=64", "csirl.updates_per_round=20",
        "optim.utd_ratio=0.5", "eval.episodes=1", "eval.final_episodes=1", "logger.progress_bar=false",
        "collector.num_workers=1", "logger.backend=none", f"logger.output_dir={tmp_path}",
        "collector.total_frames=300", "optim.precision=bf16"])
    run = csirl.make_trainer(cfg, str(tmp_path))
    try:
        params = {"actor": list(run.parts.modules.actor.parameters()),
                  "critics": list(run.parts.modules.sac.qvalue_network_params.values(True, True)),
                  "reward": list(run.parts.modules.reward_network.parameters())}
        before = {k: [p.detach().clone() for p in v] for k, v in params.items()}
        run.trainer.train()
        assert run.trainer.updates == 150 and any("loss_meta" in r for r in run.logger.rows)
        for name, group in params.items():
            assert all(p.dtype == torch.float32 for p in group)
            assert all(not torch.equal(p, b) for p, b in zip(group, before[name])), name
        assert all(torch.isfinite(torch.tensor(r["loss_qvalue"])) for r in run.logger.rows if "loss_qvalue" in r)
    finally:
        run.close()
