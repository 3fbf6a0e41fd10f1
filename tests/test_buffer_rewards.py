"""The reward transforms on a TorchRL replay buffer: rewards of the current subgoal at sampling time
(a prefetching buffer, which would hand out batches computed before a subgoal change, is refused in
one line), and a rollout collected outside ``torch.no_grad()`` stored without its autograd graph."""
from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
from torchrl.envs import Compose

from torchrl_csirl.modules import make_actor, make_qvalue, make_reward_network
from torchrl_csirl.objectives import EnsembleSACLoss
from torchrl_csirl.tasks import SCENARIOS, make_env
from torchrl_csirl.transforms import CombineRewards, IntrinsicReward, SubgoalMatchingReward

#: a 1-D road: the expert at x = 0, 1, ..., 9
EXPERT = torch.arange(10.0).unsqueeze(-1)


def transitions(n: int = 64) -> TensorDict:
    x = torch.linspace(0.0, 8.0, n).unsqueeze(-1)
    return TensorDict({"observation": x, "action": torch.zeros(n, 1), "next": {"observation": x + 0.5}}, [n])


def buffer_with(matching: SubgoalMatchingReward, prefetch: int | None) -> TensorDictReplayBuffer:
    buffer = TensorDictReplayBuffer(storage=LazyTensorStorage(1000), batch_size=16, prefetch=prefetch,
                                    transform=Compose(matching))
    buffer.extend(transitions())
    return buffer


def current_reward(matching: SubgoalMatchingReward, batch: TensorDict) -> torch.Tensor:
    fresh = batch.exclude(("next", "matching_reward")).clone()
    return matching(fresh)["next", "matching_reward"]


def test_batches_sampled_after_a_subgoal_change_carry_the_new_subgoals_reward():
    matching = SubgoalMatchingReward(EXPERT, subgoal=2, scale=10.0)
    buffer = buffer_with(matching, prefetch=None)
    buffer.sample()
    matching.set_subgoal(9)
    for _ in range(5):
        batch = buffer.sample()
        torch.testing.assert_close(batch["next", "matching_reward"], current_reward(matching, batch))


def test_a_prefetching_buffer_is_refused_in_one_line_before_it_hands_out_a_stale_reward():
    matching = SubgoalMatchingReward(EXPERT, subgoal=2, scale=10.0)
    buffer = buffer_with(matching, prefetch=3)
    try:
        stale = 0
        with pytest.raises(ValueError, match=r"^SubgoalMatchingReward on a replay buffer with prefetch=3: ") as err:
            buffer.sample()
            matching.set_subgoal(9)  # as a curriculum's round end does
            for _ in range(5):
                batch = buffer.sample()
                stale += not torch.allclose(batch["next", "matching_reward"], current_reward(matching, batch))
        assert "\n" not in str(err.value) and stale == 0
    finally:
        buffer.close() if hasattr(buffer, "close") else None


def test_the_reward_transforms_compose_with_prefetch_when_applied_to_the_sampled_batch():
    """What the refusal recommends: the buffer prefetches raw transitions, the rewards are computed on hand-out."""
    matching = SubgoalMatchingReward(EXPERT, subgoal=2, scale=10.0)
    buffer = TensorDictReplayBuffer(storage=LazyTensorStorage(1000), batch_size=16, prefetch=3)
    buffer.extend(transitions())
    buffer.sample()
    matching.set_subgoal(9)
    batch = matching(buffer.sample())
    torch.testing.assert_close(batch["next", "matching_reward"], current_reward(matching, batch))


def test_a_rollout_collected_with_its_graph_is_stored_without_it_and_trains_twice():
    """The README tour's buffer filled with ``env.rollout(60, actor)`` outside ``torch.no_grad()``."""
    spec = SCENARIOS["merge"]
    torch.manual_seed(0)
    actor = make_actor(spec.obs_dim, spec.action_dim)
    sac = EnsembleSACLoss(actor, make_qvalue(spec.obs_dim, spec.action_dim), num_qvalue_nets=2)
    expert = torch.randn(10, spec.obs_dim)
    buffer = TensorDictReplayBuffer(
        storage=LazyTensorStorage(1000), batch_size=32,
        transform=Compose(SubgoalMatchingReward(expert, subgoal=3, scale=spec.matching_scale),
                          IntrinsicReward(make_reward_network(spec.obs_dim)),
                          CombineRewards(["matching_reward", "intrinsic_reward"])))
    rollout = make_env("merge", seed=0).rollout(20, actor).reshape(-1)
    assert rollout["action"].requires_grad  # what the tour's rollout holds
    buffer.extend(rollout)
    assert not buffer[:]["action"].requires_grad
    optim = torch.optim.Adam(sac.parameters(), lr=1e-3)
    for _ in range(2):  # the second backward used to fail: "Trying to backward through the graph a second time"
        batch = buffer.sample()
        batch.set(("next", "reward"), batch.get(("next", "reward")).detach())
        losses = sac(batch)
        optim.zero_grad()
        (losses["loss_qvalue"] + losses["loss_actor"]).backward()
        optim.step()
