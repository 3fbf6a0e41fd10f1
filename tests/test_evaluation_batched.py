"""Evaluation on a batched environment: each copy's first episode, the single environment's numbers (issue 90)."""
from __future__ import annotations

from types import SimpleNamespace

import pytest
import torch
from tensordict import TensorDict
from tensordict.nn import TensorDictModule

from torchrl_csirl.tasks import SCENARIOS, accomplish_rate_from_rollout, make_env, make_serial_env
from torchrl_csirl.trainers import episode_metrics, evaluate_episodes, evaluate_policy


class _SteadyDriver(torch.nn.Module):
    """Half throttle, a small observation-dependent steer: episodes of different lengths on merge (44 and 14 steps)."""

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        action = torch.zeros(*observation.shape[:-1], 2)
        action[..., 0] = 0.5
        return action + 0.05 * torch.tanh(observation[..., 3:5])


@pytest.fixture(scope="module")
def policy() -> TensorDictModule:
    return TensorDictModule(_SteadyDriver(), in_keys=["observation"], out_keys=["action"])


def test_serial_env_gives_the_single_env_numbers_episode_by_episode(policy):
    max_steps = SCENARIOS["merge"].max_steps
    single = evaluate_episodes(make_env("merge"), policy, episodes=3, max_steps=max_steps, seed=10)
    env = make_serial_env("merge", 2)
    try:
        batched = evaluate_episodes(env, policy, episodes=3, max_steps=max_steps, seed=10)  # 2 rounds, the last one half used
        lengths = batched["episode_length"]
        assert lengths[0] != lengths[1]  # the copies' episodes end at different steps
        for key, value in single.items():
            torch.testing.assert_close(batched[key], value, msg=key)
        averaged = evaluate_policy(env, policy, episodes=3, max_steps=max_steps, seed=10)
        assert averaged["accomplish_rate"] == pytest.approx(float(single["accomplish_rate"].mean()))
        assert averaged["episode_length"] == pytest.approx(float(lengths.mean()))
        # what this replaces: TorchRL's default rollout stops every copy at the first done
        env.reset(list_of_kwargs=[{"seed": 10}, {"seed": 11}])
        cut = env.rollout(max_steps, policy)
        assert cut.shape[-1] == int(lengths[:2].min())
        assert accomplish_rate_from_rollout(cut)[0] < single["accomplish_rate"][0]
    finally:
        env.close()


def test_episodes_that_cannot_be_separated_are_refused():
    td = TensorDict({"next": {"reward": torch.ones(2, 3, 1)}}, batch_size=[2, 3])
    with pytest.raises(ValueError, match="done"):
        episode_metrics(td)
    env = SimpleNamespace(batch_size=torch.Size([2, 2]))
    with pytest.raises(ValueError, match="batch size"):
        evaluate_episodes(env, None, episodes=2, max_steps=3, seed=0)
