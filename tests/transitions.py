"""Random SAC transitions for the loss tests (``from transitions import random_transitions``)."""
from __future__ import annotations

import torch
from tensordict import TensorDict


def random_transitions(n: int, obs_dim: int, act_dim: int, *, dtype: torch.dtype = torch.float32,
                       generator: torch.Generator | None = None, reward_key: str = "reward") -> TensorDict:
    """``n`` transitions: Gaussian observations, actions uniform in [-1, 1], a Gaussian ``("next", reward_key)``.

    ``("next", "done")`` and ``("next", "terminated")`` are all False; tests set the ones they need.
    The draws come in the order observation, action, next observation, reward.
    """
    def draw(*shape: int) -> torch.Tensor:
        return torch.randn(*shape, generator=generator, dtype=dtype)

    observation = draw(n, obs_dim)
    action = torch.rand(n, act_dim, generator=generator, dtype=dtype) * 2 - 1
    next_observation, reward = draw(n, obs_dim), draw(n, 1)
    return TensorDict({
        "observation": observation,
        "action": action,
        ("next", "observation"): next_observation,
        ("next", reward_key): reward,
        ("next", "done"): torch.zeros(n, 1, dtype=torch.bool),
        ("next", "terminated"): torch.zeros(n, 1, dtype=torch.bool),
    }, [n])
