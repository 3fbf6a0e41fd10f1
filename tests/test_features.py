"""EgoRelativeFeatures: values on real scenario observations, and the networks built over it."""
from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict

from torchrl_csirl.modules import (
    EgoRelativeFeatures,
    load_policy,
    make_actor,
    make_qvalue,
    make_reward_network,
    save_policy,
)
from torchrl_csirl.objectives import EnsembleSACLoss, MetaRewardLoss
from torchrl_csirl.tasks import SCENARIOS, make_gym_env


@pytest.mark.parametrize("scenario", sorted(SCENARIOS))
def test_relative_features_on_real_observations(scenario):
    spec = SCENARIOS[scenario]
    feats = EgoRelativeFeatures.from_scenario(spec)
    env = make_gym_env(scenario)
    obs, _ = env.reset(seed=3)
    for _ in range(5):
        obs, *_ = env.step(env.action_space.sample() * 0)
    env.close()
    obs = torch.as_tensor(obs, dtype=torch.float32)
    out = feats(obs)
    assert out.shape == (feats.out_features,)
    assert torch.equal(out[: spec.obs_dim], obs), "the observation passes unchanged"
    rows = obs.view(spec.vehicles_count, len(spec.features))
    relative = out[spec.obs_dim :].view(spec.vehicles_count - 1, len(feats.relative_indices))
    x, presence = spec.features.index("x"), spec.features.index("presence")
    x_gain = feats.gains[feats.relative_indices.index(x)]
    half_range_x = 0.5 * (spec.features_range["x"][1] - spec.features_range["x"][0])
    assert x_gain == pytest.approx(half_range_x / 20.0 if half_range_x > 20 else 1.0)
    for i in range(1, spec.vehicles_count):
        expected = torch.clamp(x_gain * (rows[i, x] - rows[0, x]), -5, 5) if rows[i, presence] > 0 else 0.0
        assert relative[i - 1, feats.relative_indices.index(x)] == pytest.approx(float(expected), abs=1e-5)
    assert relative.abs().max() <= 5.0
    assert torch.equal(out, _plain_relative_features(feats, obs)), "the plain formula, bit for bit"


def _plain_relative_features(feats: EgoRelativeFeatures, obs: torch.Tensor) -> torch.Tensor:
    """The class docstring's formula in plain tensor operations (an index list, no views, nothing in place)."""
    rows = obs.unflatten(-1, (feats.vehicles_count, feats.num_features))
    selected = rows[..., feats.relative_indices]
    relative = ((selected[..., 1:, :] - selected[..., :1, :]) * torch.tensor(feats.gains)).clamp(-feats.clip, feats.clip)
    present = rows[..., 1:, feats.presence_index : feats.presence_index + 1] > 0
    return torch.cat([obs, torch.where(present, relative, torch.zeros_like(relative)).flatten(-2)], dim=-1)


def test_absent_vehicles_give_zero_offsets_and_batches_work():
    feats = EgoRelativeFeatures.from_scenario(SCENARIOS["merge"])
    obs = torch.zeros(4, 3, 25)
    obs[..., 0] = 1.0  # ego present at x = 0 (normalised), others absent
    obs[..., 1] = 0.3
    out = feats(obs)
    assert out.shape == (4, 3, 41)
    assert torch.equal(out[..., 25:], torch.zeros(4, 3, 16))


def test_bad_layout_and_sizes_raise():
    with pytest.raises(ValueError, match="vehicles_count"):
        EgoRelativeFeatures(1, 5, [1], [1.0])
    with pytest.raises(ValueError, match="one gain per relative index"):
        EgoRelativeFeatures(5, 5, [1, 2], [1.0])
    with pytest.raises(ValueError, match="relative_indices"):
        EgoRelativeFeatures(5, 5, [7], [1.0])
    feats = EgoRelativeFeatures.from_scenario(SCENARIOS["merge"])
    with pytest.raises(ValueError, match="observations of size 25"):
        feats(torch.zeros(2, 35))
    with pytest.raises(ValueError, match="obs_dim=35"):
        make_actor(35, 2, input_features=feats)


def _networks(spec, feats):
    torch.manual_seed(0)
    actor = make_actor(spec.obs_dim, 2, input_features=feats)
    sac = EnsembleSACLoss(actor, make_qvalue(spec.obs_dim, 2, input_features=feats), num_qvalue_nets=3)
    return actor, sac, make_reward_network(spec.obs_dim, input_features=feats)


def _batch(obs_dim: int, n: int) -> TensorDict:
    obs = torch.rand(n, obs_dim) * 2 - 1
    obs[:, 0] = 1.0
    return TensorDict(
        {
            "observation": obs,
            "action": torch.rand(n, 2) * 2 - 1,
            "next": {
                "observation": obs + 0.01 * torch.randn(n, obs_dim),
                "reward": torch.randn(n, 1),
                "matching_reward": torch.randn(n, 1),
                "done": torch.zeros(n, 1, dtype=torch.bool),
                "terminated": torch.zeros(n, 1, dtype=torch.bool),
            },
        },
        [n],
    )


def test_networks_read_the_features_and_the_meta_gradient_reaches_the_reward():
    spec = SCENARIOS["roundabout"]
    feats = EgoRelativeFeatures.from_scenario(spec)
    actor, sac, reward = _networks(spec, feats)
    first = [m for m in actor.modules() if isinstance(m, torch.nn.Linear)][0]
    assert first.in_features == feats.out_features == 35 + 4 * 4
    qvalues = sac.qvalues(_batch(spec.obs_dim, 8))
    assert qvalues.shape == (3, 8)
    meta = MetaRewardLoss(sac, reward)
    out = meta(_batch(spec.obs_dim, 16), _batch(spec.obs_dim, 8), regularizer=_batch(spec.obs_dim, 16))
    out["loss_meta"].backward()
    grads = [p.grad for p in reward.parameters()]
    assert all(g is not None for g in grads)
    assert sum(g.abs().sum() for g in grads) > 0


def test_saved_policy_keeps_its_feature_map(tmp_path):
    spec = SCENARIOS["merge"]
    feats = EgoRelativeFeatures.from_scenario(spec)
    actor, _, _ = _networks(spec, feats)
    path = save_policy(actor, tmp_path / "policy.pt", obs_dim=spec.obs_dim, action_dim=2, scenario="merge")
    loaded = load_policy(path)
    loaded_feats = [m for m in loaded.modules() if isinstance(m, EgoRelativeFeatures)]
    assert len(loaded_feats) == 1 and loaded_feats[0].config() == feats.config()
    td = TensorDict({"observation": torch.rand(6, spec.obs_dim)}, [6])
    assert torch.equal(actor(td.clone())["loc"], loaded(td.clone())["loc"])
