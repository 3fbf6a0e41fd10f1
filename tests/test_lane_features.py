"""LaneFeatures: the ego's offset from the road's centre lines, on the real scenarios' roads and demonstrations,
inside the networks (meta-gradient included) and in a saved policy."""
from __future__ import annotations

import numpy as np
import pytest
import torch
from tensordict import TensorDict

from torchrl_csirl.data import load_expert_demonstrations
from torchrl_csirl.modules import (
    FeatureChain,
    LaneFeatures,
    load_policy,
    make_actor,
    make_input_features,
    make_qvalue,
    make_reward_network,
    save_policy,
)
from torchrl_csirl.objectives import EnsembleSACLoss, MetaRewardLoss
from torchrl_csirl.tasks import SCENARIOS, make_gym_env, sample_lane_centres


def _observation_at(spec, x: float, y: float, heading: float) -> torch.Tensor:
    """An observation with the ego at (x, y) [m] heading ``heading`` [rad], no other vehicle."""
    obs = torch.zeros(spec.obs_dim)
    features = list(spec.features)
    for name, value in (("x", x), ("y", y)):
        low, high = spec.features_range[name]
        obs[features.index(name)] = 2 * (value - low) / (high - low) - 1
    obs[features.index("presence")] = 1.0
    obs[features.index("cos_h")], obs[features.index("sin_h")] = np.cos(heading), np.sin(heading)
    return obs


@pytest.mark.parametrize("scenario", sorted(SCENARIOS))
def test_the_expert_drives_within_its_lanes(scenario):
    spec = SCENARIOS[scenario]
    feats = LaneFeatures.from_scenario(spec)
    obs = torch.as_tensor(load_expert_demonstrations(scenario, 5).transitions()["observation"], dtype=torch.float32)
    extra = feats(obs)[:, spec.obs_dim:]
    assert extra.shape == (len(obs), 3 if "cos_h" in spec.features else 1)
    lateral = extra[:, 0]
    # the expert keeps to the road: within a half lane width of some centre line (1.01: the roundabout's
    # exit bend at 30 m/s, docs/studies/index.md), mostly well inside it
    assert lateral.abs().max() <= 1.05 and (lateral.abs() < 1).float().mean() > 0.98
    if extra.shape[1] == 3:  # and heads along its lane
        assert extra[:, 1].mean() > 0.9 and torch.allclose(extra[:, 1] ** 2 + extra[:, 2] ** 2, torch.ones(len(obs)))


def test_the_roundabout_exit_departure_is_off_the_lane():
    spec = SCENARIOS["roundabout"]
    feats = LaneFeatures.from_scenario(spec)
    # on the exit lane's centre line (x 4.6 m at y -36.1 m), and 2.6 m to its left where the policies left the road
    on, off = feats(torch.stack([_observation_at(spec, 4.63, -36.14, -1.82), _observation_at(spec, 1.8, -37.1, -1.7)]))
    assert abs(on[spec.obs_dim]) < 0.05 and off[spec.obs_dim] < -1.0
    # matches highway-env's own lateral coordinate (its sign too) where one lane is nearest
    env = make_gym_env("roundabout")
    env.reset(seed=0)
    lane = env.unwrapped.road.network.get_lane(("nx", "nxs", 0))
    env.close()
    point = lane.position(10.0, 0.7)
    _, lateral = lane.local_coordinates(point)
    out = feats(_observation_at(spec, *point, lane.heading_at(10.0)))
    assert out[spec.obs_dim].item() == pytest.approx(lateral / 2, abs=0.02) and out[spec.obs_dim + 1] > 0.999


def test_chained_after_the_ego_relative_map_in_every_network_and_the_meta_gradient():
    spec = SCENARIOS["intersection"]
    chain = make_input_features(spec, ego_relative=True, lane=True)
    assert isinstance(chain, FeatureChain) and chain.out_features == 35 + 4 * 4 + 3
    actor = make_actor(spec.obs_dim, 2, input_features=chain)
    sac = EnsembleSACLoss(actor, make_qvalue(spec.obs_dim, 2, input_features=chain), num_qvalue_nets=3)
    reward = make_reward_network(spec.obs_dim, input_features=chain)
    batch = TensorDict({
        "observation": torch.rand(8, spec.obs_dim) * 0.2, "action": torch.rand(8, 2) * 2 - 1,
        ("next", "observation"): torch.rand(8, spec.obs_dim) * 0.2, ("next", "reward"): torch.rand(8, 1),
        ("next", "matching_reward"): torch.rand(8, 1),
        ("next", "done"): torch.zeros(8, 1, dtype=torch.bool), ("next", "terminated"): torch.zeros(8, 1, dtype=torch.bool),
    }, [8])
    assert sac.qvalues(batch).shape == (3, 8)
    out = MetaRewardLoss(sac, reward)(batch.clone(), batch[:4].clone(), regularizer=batch.clone())
    out["loss_meta"].backward()
    assert sum(p.grad.abs().sum() for p in reward.parameters()) > 0


def test_a_saved_policy_holds_its_chained_map_and_its_lane_points(tmp_path):
    spec = SCENARIOS["roundabout"]
    actor = make_actor(spec.obs_dim, 2, input_features=make_input_features(spec, ego_relative=True, lane=True))
    path = save_policy(actor, tmp_path / "policy.pt", obs_dim=spec.obs_dim, action_dim=2, scenario="roundabout")
    payload = torch.load(path, weights_only=True)
    lane = payload["input_features"]["maps"][1]
    assert payload["input_features"]["kind"] == "chain" and lane["scenario"] == "roundabout"
    assert np.allclose(lane["centres"], spec.lane_centres())  # loading needs no environment
    td = TensorDict({"observation": torch.rand(6, spec.obs_dim) * 0.2}, [6])
    assert torch.equal(actor(td.clone())["loc"], load_policy(path)(td.clone())["loc"])
    # a policy saved with the scenario's name only (before the points were stored) takes them from the road
    lane["centres"] = None
    torch.save(payload, tmp_path / "by_name.pt")
    with pytest.raises(ValueError, match="pass lane_centres=torchrl_csirl.tasks.sample_lane_centres"):
        load_policy(tmp_path / "by_name.pt")
    loaded = load_policy(tmp_path / "by_name.pt", lane_centres=sample_lane_centres)
    assert torch.equal(actor(td.clone())["loc"], loaded(td.clone())["loc"])


def test_bad_inputs_raise():
    centres = np.array([[0.0, 0.0, 0.0, 2.0]], dtype=np.float32)
    with pytest.raises(ValueError, match=r"non-empty \(P, 4\) array"):
        LaneFeatures(np.zeros((0, 4)), obs_dim=2, x_index=0, y_index=1, x_range=(-1, 1), y_range=(-1, 1))
    with pytest.raises(ValueError, match="give both or neither"):
        LaneFeatures(centres, obs_dim=3, x_index=0, y_index=1, x_range=(-1, 1), y_range=(-1, 1), cos_index=2)
    feats = LaneFeatures(centres, obs_dim=2, x_index=0, y_index=1, x_range=(-1, 1), y_range=(-1, 1))
    with pytest.raises(ValueError, match="expects inputs of size 2, got 3"):
        feats(torch.zeros(3))
