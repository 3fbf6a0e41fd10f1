"""MetaRewardLoss called the TorchRL way: ``loss(td)`` on one TensorDict, ``set_keys``, ``td_error`` (issue 90)."""
from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from test_meta_loss import _setup
from torchrl.data import LazyTensorStorage, TensorDictPrioritizedReplayBuffer, TensorDictReplayBuffer


def _losses_and_grads(meta, reward, *args, seed: int = 11) -> tuple[TensorDict, list[torch.Tensor]]:
    """The loss TensorDict (detached) and the reward network's gradient of ``loss_meta``."""
    reward.zero_grad(set_to_none=True)
    torch.manual_seed(seed)
    out = meta(*args)
    out["loss_meta"].backward()
    return out.detach(), [p.grad.clone() for p in reward.parameters()]


@pytest.mark.parametrize("meta_gradient", ["double_backward", "jvp"])
@pytest.mark.parametrize("joint_sac_update", [False, True])
@pytest.mark.parametrize("with_regularizer", [False, True])
def test_one_tensordict_call_matches_three_arguments(meta_gradient, joint_sac_update, with_regularizer):
    _sac, reward, meta, online, expert, regularizer = _setup(
        meta_gradient=meta_gradient, joint_sac_update=joint_sac_update)
    regularizer = regularizer if with_regularizer else None
    ref, ref_grads = _losses_and_grads(meta, reward, online.clone(), expert, regularizer)
    td = meta.meta_batch(online.clone(), expert, regularizer)
    assert td.batch_size == online.batch_size
    out, grads = _losses_and_grads(meta, reward, td)
    assert set(out.keys()) == set(ref.keys())
    assert any(key.startswith("loss_") for key in out.keys())
    for key in ref.keys():
        torch.testing.assert_close(out[key], ref[key], rtol=0, atol=0)
    for g, g_ref in zip(grads, ref_grads):
        assert g.dtype == torch.float64
        torch.testing.assert_close(g, g_ref, rtol=0, atol=0)
    assert any(g.abs().max() > 0 for g in grads)


def test_regularizer_batch_is_used():
    _sac, reward, meta, online, expert, regularizer = _setup()
    without = meta(meta.meta_batch(online, expert))["loss_reward_l1"]
    with_reg = meta(meta.meta_batch(online, expert, regularizer))["loss_reward_l1"]
    assert not torch.isclose(without, with_reg)


def test_root_without_batch_size_is_read_as_the_online_batch():
    _sac, reward, meta, online, expert, regularizer = _setup()
    ref, ref_grads = _losses_and_grads(meta, reward, online.clone(), expert, regularizer)
    td = online.clone()
    td.batch_size = []
    td["expert"], td["regularizer"] = expert, regularizer
    out, grads = _losses_and_grads(meta, reward, td)
    torch.testing.assert_close(out["loss_meta"], ref["loss_meta"], rtol=0, atol=0)
    for g, g_ref in zip(grads, ref_grads):
        torch.testing.assert_close(g, g_ref, rtol=0, atol=0)
    assert td["td_error"].shape == online.batch_size


def test_set_keys_renames_the_nested_batches():
    _sac, reward, meta, online, expert, regularizer = _setup()
    ref, ref_grads = _losses_and_grads(meta, reward, online.clone(), expert, regularizer)
    default = meta.meta_batch(online, expert, regularizer)
    meta.set_keys(expert="demos", regularizer=("aux", "reg"), expert_observation="obs", expert_action="act")
    demos = expert.rename_key_("observation", "obs").rename_key_("action", "act")
    td = meta.meta_batch(online.clone(), demos, regularizer)
    assert "expert" not in td.keys() and ("demos", "obs") in td.keys(True) and ("aux", "reg") in td.keys(True)
    assert ("demos", "obs") in meta.in_keys and ("demos", "act") in meta.in_keys
    out, grads = _losses_and_grads(meta, reward, td)
    torch.testing.assert_close(out["loss_meta"], ref["loss_meta"], rtol=0, atol=0)
    for g, g_ref in zip(grads, ref_grads):
        torch.testing.assert_close(g, g_ref, rtol=0, atol=0)
    with pytest.raises(KeyError, match="demos"):
        meta(default)  # the expert batch under the old key is not found


def test_bad_one_tensordict_calls():
    _sac, _reward, meta, online, expert, regularizer = _setup()
    with pytest.raises(KeyError, match="expert"):
        meta(online)
    with pytest.raises(ValueError, match="without an expert"):
        meta(online, None, regularizer)
    with pytest.raises(ValueError, match="flat expert"):
        meta.meta_batch(online, expert.unsqueeze(0))


@pytest.mark.parametrize("meta_gradient", ["double_backward", "jvp"])
def test_td_error_is_the_critics_per_sample_error(meta_gradient):
    sac, reward, meta, online, expert, regularizer = _setup(meta_gradient=meta_gradient)
    batch = online.clone()
    torch.manual_seed(3)
    meta(batch, expert, regularizer)  # the three-argument call writes into the online batch
    td_error = batch["td_error"]
    assert td_error.shape == online.batch_size and not td_error.requires_grad
    # reference: SACLoss's TD errors with the local reward r_m + r_w, same target draws
    ref = online.clone()
    with torch.no_grad():
        ref["next", "reward"] = ref["next", "matching_reward"] + reward(ref.select("observation"))["intrinsic_reward"]
    torch.manual_seed(3)
    _, metadata = sac.qvalue_v2_loss(ref)
    torch.testing.assert_close(td_error, metadata["td_error"], rtol=1e-12, atol=1e-12)


def test_td_error_updates_a_prioritised_buffer():
    # float32: TorchRL's priority trees hold float32 and take no float64 priorities
    _sac, _reward, meta, online, expert, _ = _setup(dtype=torch.float32)
    n = online.batch_size[0]
    online_rb = TensorDictPrioritizedReplayBuffer(
        alpha=1.0, beta=1.0, eps=1e-8, storage=LazyTensorStorage(n), batch_size=n)
    online_rb.extend(online)
    expert_rb = TensorDictReplayBuffer(storage=LazyTensorStorage(expert.batch_size[0]), batch_size=3)
    expert_rb.extend(expert)
    td = meta.sample_meta_batch(online_rb, expert_rb, online_rb)
    assert td.batch_size == (n,) and td["expert"].batch_size == (n, 3) and td["regularizer"].batch_size == (n, n)
    meta(td)
    assert td["td_error"].shape == (n,)
    updates = []
    update_priority = online_rb.update_priority
    online_rb.update_priority = lambda index, priority: updates.append((index, priority)) or update_priority(
        index, priority)
    online_rb.update_tensordict_priority(td)
    (index, priority), = updates
    torch.testing.assert_close(index, td["index"])
    torch.testing.assert_close(priority.to(td["td_error"].dtype), td["td_error"])
    tree = online_rb.sampler.state_dict()["_sum_tree"]
    for i in td["index"].unique().tolist():  # sampled with replacement: one of its samples' errors
        candidates = td["td_error"][td["index"] == i] + 1e-8
        assert torch.isclose(candidates, torch.tensor(tree[i]), rtol=1e-5, atol=1e-6).any()
