"""Input maps inside map_each_input_once: one computation per input tensor, the same numbers bit for bit."""
from __future__ import annotations

import contextlib
from unittest import mock

import pytest
import torch
from transitions import random_transitions

from torchrl_csirl.modules import EgoRelativeFeatures, make_input_features, map_each_input_once
from torchrl_csirl.objectives import make_csirl_learner
from torchrl_csirl.tasks import SCENARIOS

MERGE = SCENARIOS["merge"]


def _counting(cls: type, method: str):
    """Patches ``cls.method`` with a wrapper that counts its calls (``.call_count``)."""
    return mock.patch.object(cls, method, autospec=True, side_effect=getattr(cls, method))


def test_inside_the_block_each_map_of_a_chain_computes_once_per_input():
    chain = make_input_features(SCENARIOS["roundabout"], ego_relative=True, lane=True)
    obs = torch.rand(8, chain.in_features) * 2 - 1
    fresh = chain(obs)
    with _counting(EgoRelativeFeatures, "_relative_features") as ego, map_each_input_once():
        first, second = chain(obs), chain(obs)
    assert second is first and torch.equal(first, fresh)
    assert ego.call_count == 1
    assert chain(obs) is not first  # the block's memo is gone with it


def test_an_input_written_in_place_is_mapped_again():
    feats = EgoRelativeFeatures.from_scenario(MERGE)
    obs = torch.rand(4, feats.in_features)
    with map_each_input_once():
        before = feats(obs).clone()
        obs[:, 1] += 0.5  # the ego's x: every relative x changes
        after = feats(obs)
    assert not torch.equal(after, before)
    assert torch.equal(after, feats(obs))


@pytest.mark.parametrize("case", ["requires_grad", "inference_mode"])
def test_no_reuse_where_an_output_could_carry_a_graph_or_an_inference_tensor(case):
    feats = EgoRelativeFeatures.from_scenario(MERGE)
    obs = torch.rand(4, feats.in_features, requires_grad=case == "requires_grad")
    with map_each_input_once():
        if case == "inference_mode":
            with torch.inference_mode():
                first, second = feats(obs), feats(obs)
        else:
            first, second = feats(obs), feats(obs)
    assert second is not first and torch.equal(second, first)


def _csirl_iteration(memo: bool) -> tuple[dict[str, torch.Tensor], list[torch.Tensor], int]:
    """One joint CSIRL iteration (SAC losses and the meta-loss, one backward) of the merge learner."""
    torch.manual_seed(0)
    learner = make_csirl_learner(MERGE.obs_dim, MERGE.action_dim, hidden=(32, 32),
                                 input_features=make_input_features(MERGE))
    generator = torch.Generator().manual_seed(1)
    online = random_transitions(64, MERGE.obs_dim, MERGE.action_dim, generator=generator,
                                reward_key="matching_reward")
    expert = random_transitions(16, MERGE.obs_dim, MERGE.action_dim, generator=generator)
    regularizer = random_transitions(64, MERGE.obs_dim, MERGE.action_dim, generator=generator)
    parameters = [*learner.sac.parameters(), *learner.reward_network.parameters()]
    with _counting(EgoRelativeFeatures, "_relative_features") as ego:
        with map_each_input_once() if memo else contextlib.nullcontext():
            losses = learner.meta(online, expert, regularizer)
            sum(losses[k] for k in ("loss_qvalue", "loss_actor", "loss_meta")).backward()
    grads = [p.grad.clone() if p.grad is not None else torch.zeros(()) for p in parameters]
    return {k: v.detach() for k, v in losses.items() if isinstance(v, torch.Tensor)}, grads, ego.call_count


def test_a_csirl_iteration_gives_the_same_losses_and_gradients_bit_for_bit_with_the_memo():
    losses, grads, calls = _csirl_iteration(memo=False)
    memo_losses, memo_grads, memo_calls = _csirl_iteration(memo=True)
    assert memo_calls < calls
    assert losses.keys() == memo_losses.keys()
    for key, value in losses.items():
        assert torch.equal(value, memo_losses[key]), key
    assert all(torch.equal(a, b) for a, b in zip(grads, memo_grads))
