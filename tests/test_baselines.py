"""The imitation baselines (docs/BASELINES.md): each loss's defining property on a tiny problem."""
from __future__ import annotations

from types import SimpleNamespace

import pytest
import torch
from tensordict import TensorDict
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
from torchrl.envs import Compose

from torchrl_csirl.data import ExpertDemonstrations
from torchrl_csirl.modules import make_actor, make_qvalue
from torchrl_csirl.trainers.imitation import _IMPLEMENTED, make_imitation_method

OBS, ACT, HIDDEN = 3, 1, (32, 32)


def transitions(n: int, obs: torch.Tensor | float, action: torch.Tensor | float, terminated_every: int = 0) -> TensorDict:
    """``n`` transitions; ``obs``/``action`` are broadcast; every ``terminated_every``-th one terminates."""
    obs = torch.as_tensor(obs, dtype=torch.float32).expand(n, OBS).clone()
    action = torch.as_tensor(action, dtype=torch.float32).expand(n, ACT).clone()
    terminated = torch.zeros(n, 1, dtype=torch.bool)
    if terminated_every:
        terminated[terminated_every - 1::terminated_every] = True
    return TensorDict({
        "observation": obs, "action": action,
        "next": {"observation": obs + 0.1, "terminated": terminated, "truncated": torch.zeros_like(terminated),
                 "done": terminated.clone(), "reward": torch.zeros(n, 1)}}, [n])


def buffers(method, online_data: TensorDict, expert_data: TensorDict):
    online = TensorDictReplayBuffer(storage=LazyTensorStorage(10_000), batch_size=64,
                                    transform=Compose(*method.online_transforms))
    online.extend(online_data)
    episodes = [{"observation": expert_data["observation"], "action": expert_data["action"],
                 "next_observation": expert_data["next", "observation"],
                 "terminated": expert_data["next", "terminated"].squeeze(-1)}]
    expert = ExpertDemonstrations.from_episodes(episodes).as_replay_buffer(
        batch_size=64, transform=Compose(*method.expert_transforms))
    return online, expert


def trainer(online) -> SimpleNamespace:
    return SimpleNamespace(updates=0, frames=0, online_buffer=online)


def build(name: str, hyperparameters=None, obs=OBS, act=ACT):
    torch.manual_seed(0)
    actor = make_actor(obs, act, hidden=HIDDEN)
    return make_imitation_method(name, actor, lambda: make_qvalue(obs, act, hidden=HIDDEN), obs_dim=obs,
                                 action_dim=act, hyperparameters=hyperparameters)


def run_updates(step, t, n: int) -> dict:
    out = {}
    for _ in range(n):
        out = step(t)
        t.updates += 1
    return out


# ------------------------------------------------------------------------------ interface
def test_unknown_method_and_bad_hyperparameters():
    with pytest.raises(ValueError, match="unknown imitation method 'dagger'"):
        build("dagger")
    with pytest.raises(ValueError, match="no field"):
        build("sqil", {"learning_rate": 1e-3})
    with pytest.raises(ValueError, match="action_dim"):
        make_imitation_method("sqil", make_actor(OBS, 2, hidden=HIDDEN), lambda: make_qvalue(OBS, 2), obs_dim=OBS,
                              action_dim=ACT)


@pytest.mark.parametrize("name", _IMPLEMENTED)
def test_every_method_updates_and_checkpoints(name):
    method = build(name, {"batch_size": 16})
    online, expert = buffers(method, transitions(40, torch.randn(40, OBS), torch.rand(40, ACT) * 2 - 1, 10),
                             transitions(30, torch.randn(30, OBS), 0.5, 15))
    step = method.make_update_step(online, expert)
    losses = run_updates(step, trainer(online), 2)
    assert losses and all(torch.isfinite(v).all() and not v.requires_grad for v in losses.values())
    for state in method.states.values():
        state.load_state_dict(state.state_dict())


# ------------------------------------------------------------------------------ SQIL
def test_sqil_labels_and_balanced_batches():
    method = build("sqil", {"batch_size": 32})
    online, expert = buffers(method, transitions(50, 0.0, 0.0), transitions(20, 1.0, 0.5))
    assert online.sample()["next", "reward"].eq(0).all() and expert.sample()["next", "reward"].eq(1).all()
    step = method.make_update_step(online, expert)
    batch = step.sample(trainer(online))
    is_expert = batch["observation"][:, 0].eq(1.0)
    assert int(is_expert.sum()) == 16  # 50/50
    torch.testing.assert_close(batch["next", "reward"].squeeze(-1), is_expert.float())
