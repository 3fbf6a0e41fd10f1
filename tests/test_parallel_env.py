"""YieldingParallelEnv: same data as TorchRL's SerialEnv, worker failures still reported."""
from __future__ import annotations

from functools import partial

import pytest
import torch
from torchrl.envs import SerialEnv

from torchrl_csirl.tasks import YieldingParallelEnv, make_env


def _rollout(env, steps: int = 12):
    env.set_seed(3)
    torch.manual_seed(0)
    actions = torch.rand(steps, 2, 2) * 2 - 1
    td = env.reset()
    obs = []
    for a in actions:
        td["action"] = a
        td = env.step(td)
        obs.append(td["next", "observation"].clone())
        td = env.step_mdp(td)
    return torch.stack(obs)


def test_yielding_parallel_env_matches_serial_env():
    serial = SerialEnv(2, partial(make_env, "merge"))
    parallel = YieldingParallelEnv(2, partial(make_env, "merge"), poll_interval=1e-4)
    try:
        torch.testing.assert_close(_rollout(parallel), _rollout(serial), rtol=0, atol=0)
        assert parallel.poll_interval == 1e-4
    finally:
        serial.close()
        parallel.close()


def test_yielding_parallel_env_rejects_negative_poll_interval():
    with pytest.raises(ValueError, match="poll_interval"):
        YieldingParallelEnv(2, partial(make_env, "merge"), poll_interval=-1.0)
