"""Reward transforms of CSIRL: the subgoal matching reward, the learned intrinsic reward, their sum.

Each reward is written under its own key in the ``"next"`` sub-tensordict
(``("next", "matching_reward")``, ``("next", "intrinsic_reward")``), declared as an observation
so ``env.reward_key`` stays the environment's single reward. The training reward
``r = r_m + r_w`` is made with :class:`CombineRewards`, which overwrites ``("next", "reward")``
(the key TorchRL losses read by default). Since ``r_m`` depends only on ``(s, s', g)`` and
``r_w`` changes at every update, the usual place is the replay buffer: rewards are recomputed
for the current subgoal and reward network at sampling time.

Examples:
    >>> import torch
    >>> from torchrl.data import ListStorage, TensorDictReplayBuffer
    >>> from torchrl.envs import Compose
    >>> from torchrl.testing.mocking_classes import ContinuousActionVecMockEnv
    >>> from torchrl_csirl.modules.reward import make_reward_network
    >>> from torchrl_csirl.transforms import CombineRewards, IntrinsicReward, SubgoalMatchingReward
    >>> env = ContinuousActionVecMockEnv()
    >>> data = env.rollout(10)
    >>> matching = SubgoalMatchingReward(data["observation"], subgoal=2, scale=100.0)
    >>> reward_net = make_reward_network(7)
    >>> rb = TensorDictReplayBuffer(storage=ListStorage(100), batch_size=4)
    >>> _ = rb.append_transform(Compose(
    ...     matching, IntrinsicReward(reward_net),
    ...     CombineRewards(["matching_reward", "intrinsic_reward"])))  # -> ("next", "reward")
    >>> _ = rb.extend(data)
    >>> batch = rb.sample()
    >>> torch.allclose(batch["next", "reward"],
    ...                batch["next", "matching_reward"] + batch["next", "intrinsic_reward"])
    True
    >>> matching.set_subgoal(5)  # used by the next sample

The same ``Compose`` can be appended to a :class:`~torchrl.envs.TransformedEnv` (over a single,
serial or parallel env) to get the rewards at collection time.
"""
from __future__ import annotations

from torchrl_csirl.transforms.absorbing_states import AbsorbingStates, absorbing_self_loops, absorbing_value
from torchrl_csirl.transforms.combine_rewards import CombineRewards
from torchrl_csirl.transforms.constant_reward import ConstantReward
from torchrl_csirl.transforms.discriminator_reward import DiscriminatorReward, discriminator_reward
from torchrl_csirl.transforms.goal_matching import (
    GoalConditionedMatchingReward,
    nearest_goal_demonstration,
    subgoal_on_demonstration,
)
from torchrl_csirl.transforms.intrinsic_reward import IntrinsicReward
from torchrl_csirl.transforms.progress_reward import ProgressReward, progress_reward
from torchrl_csirl.transforms.subgoal_matching import (
    SubgoalMatchingReward,
    failed_termination_potential,
    matching_potential,
    matching_reward,
    matching_target_index,
    nearest_expert_index,
    path_potential,
    project_on_path,
)

__all__ = [
    "AbsorbingStates",
    "CombineRewards",
    "ConstantReward",
    "DiscriminatorReward",
    "GoalConditionedMatchingReward",
    "IntrinsicReward",
    "ProgressReward",
    "SubgoalMatchingReward",
    "absorbing_self_loops",
    "absorbing_value",
    "discriminator_reward",
    "failed_termination_potential",
    "matching_potential",
    "matching_reward",
    "matching_target_index",
    "nearest_expert_index",
    "nearest_goal_demonstration",
    "path_potential",
    "progress_reward",
    "project_on_path",
    "subgoal_on_demonstration",
]
