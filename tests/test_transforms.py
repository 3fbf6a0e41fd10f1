"""Tests of the reward transforms: subgoal matching reward, intrinsic reward, their combination."""
from __future__ import annotations

import numpy as np
import pytest
import torch
from devices import DEVICES
from tensordict import TensorDict
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
from torchrl.envs import Compose, ParallelEnv, SerialEnv, TransformedEnv
from torchrl.envs.utils import check_env_specs
from torchrl.testing.mocking_classes import ContinuousActionVecMockEnv

from torchrl_csirl.data import ExpertDemonstrations
from torchrl_csirl.modules.reward import make_reward_network
from torchrl_csirl.transforms import (
    CombineRewards,
    IntrinsicReward,
    SubgoalMatchingReward,
    matching_reward,
    matching_target_index,
    nearest_expert_index,
)

OBS_DIM = 7  # ContinuousActionVecMockEnv


# --------------------------------------------------------------------------- numpy reference
def reference_matching_reward(obs, next_obs, expert, g, ego=None, pos=None, scale=1.0, target="next", sign=1.0):
    """Transition-by-transition numpy implementation of SPEC section 1 (independent of torch)."""
    obs, next_obs, expert = (np.asarray(x, dtype=np.float64) for x in (obs, next_obs, expert))
    ego = list(range(expert.shape[1])) if ego is None else list(ego)
    pos = list(range(expert.shape[1])) if pos is None else list(pos)
    L = expert.shape[0]
    out = np.zeros(obs.shape[0])
    for b in range(obs.shape[0]):
        best, best_d = 0, np.inf
        for j in range(L):
            d = np.sqrt(np.sum((obs[b, ego] - expert[j, ego]) ** 2))
            if d <= best_d:  # '<=' : ties go to the later index
                best, best_d = j, d
        if best < g:
            t = g
        else:
            t = min(best + 1, L - 1) if target == "next" else L - 1
        psi = np.linalg.norm(obs[b, pos] - expert[t, pos])
        psi_next = np.linalg.norm(next_obs[b, pos] - expert[t, pos])
        out[b] = sign * scale * (psi - psi_next)
    return out


def _transition_td(obs, next_obs):
    return TensorDict({"observation": obs, "next": {"observation": next_obs}}, batch_size=obs.shape[:1])


class TestMatchingMath:
    def test_hand_computed(self):
        # 1-D road, expert at x = 0, 1, 2, 3, 4; potential on x only
        expert = torch.tensor([[0.0, 9.0], [1.0, 9.0], [2.0, 9.0], [3.0, 9.0], [4.0, 9.0]])
        obs = torch.tensor([[0.1, 0.0], [2.9, 0.0], [4.0, 0.0]])
        next_obs = torch.tensor([[0.6, 0.0], [3.2, 0.0], [3.5, 0.0]])
        r = matching_reward(obs, next_obs, expert, subgoal=2, ego_feature_indices=[0], position_feature_indices=[0], scale=10.0)
        # s=0.1: j*=0 < g=2 -> target x=2: psi 1.9 -> 1.4, r = +5
        # s=2.9: j*=3 >= g -> target j*+1=4 (x=4): psi 1.1 -> 0.8, r = +3
        # s=4.0: j*=4 = L-1 -> target 4: psi 0 -> 0.5, r = -5
        torch.testing.assert_close(r, torch.tensor([5.0, 3.0, -5.0]))
        r_final = matching_reward(obs, next_obs, expert, 0, ego_feature_indices=[0], position_feature_indices=[0], target="final")
        torch.testing.assert_close(r_final, torch.tensor([0.5, 0.3, -0.5]))

    def test_ties_go_to_later_index(self):
        expert = torch.tensor([[0.0], [2.0], [2.0], [4.0]])
        # 1.0 is 1 away from indices 0, 1, 2; 2.0 matches 1 and 2; 3.0 is 1 away from 1, 2, 3
        assert nearest_expert_index(torch.tensor([[1.0], [2.0], [3.0], [0.5]]), expert).tolist() == [2, 2, 3, 0]

    def test_target_rule(self):
        nearest = torch.tensor([0, 1, 2, 3, 4])
        assert matching_target_index(nearest, 2, 5, "next").tolist() == [2, 2, 3, 4, 4]
        assert matching_target_index(nearest, 2, 5, "final").tolist() == [2, 2, 4, 4, 4]
        with pytest.raises(ValueError, match="target rule"):
            matching_target_index(nearest, 2, 5, "paper")

    @pytest.mark.parametrize("target", ["next", "final"])
    @pytest.mark.parametrize("sign", [1.0, -1.0])
    def test_against_numpy_reference(self, target, sign):
        g = torch.Generator().manual_seed(0)
        L, D, B = 12, 6, 64
        expert = torch.randn(L, D, generator=g).cumsum(0)
        expert[5:7] = expert[4]  # the expert stands still: duplicates resolve to the later index
        expert[L - 1] = expert[L - 2]
        obs = expert[torch.randint(0, L, (B,), generator=g)] + 0.5 * torch.randn(B, D, generator=g)
        obs[:8] = expert[[4, 5, 6, L - 1, L - 2, 4, 6, 0]]  # exact hits on duplicated states
        next_obs = obs + 0.3 * torch.randn(B, D, generator=g)
        ego, pos = [0, 1, 2], [1, 2]
        for subgoal in (0, 4, L - 1):
            t = SubgoalMatchingReward(
                expert, subgoal=subgoal, ego_feature_indices=ego, position_feature_indices=pos,
                scale=700.0, target=target, sign=sign,
            )
            got = t(_transition_td(obs, next_obs))["next", "matching_reward"]
            assert got.shape == (B, 1)
            want = reference_matching_reward(obs, next_obs, expert, subgoal, ego, pos, 700.0, target, sign)
            np.testing.assert_allclose(got.squeeze(-1).numpy(), want, rtol=1e-4, atol=1e-3)

    def test_multi_dim_batch(self):
        expert = torch.randn(8, 3)
        obs, next_obs = torch.randn(2, 5, 3), torch.randn(2, 5, 3)
        td = TensorDict({"observation": obs, "next": {"observation": next_obs}}, [2, 5])
        out = SubgoalMatchingReward(expert, subgoal=3)(td)["next", "matching_reward"]
        want = reference_matching_reward(obs.reshape(10, 3), next_obs.reshape(10, 3), expert, 3)
        np.testing.assert_allclose(out.reshape(-1).numpy(), want, rtol=1e-5, atol=1e-5)

    def test_accepts_expert_demonstrations(self):
        obs = torch.arange(12.0).reshape(6, 2)
        ep = {"observation": obs[:-1], "action": torch.zeros(5, 1), "next_observation": obs[1:],
              "terminated": torch.tensor([False] * 4 + [True])}
        demos = ExpertDemonstrations.from_episodes([ep])
        assert SubgoalMatchingReward(demos).length == 5
        assert SubgoalMatchingReward(demos.trajectory(0), include_final=True).length == 6
        torch.testing.assert_close(SubgoalMatchingReward(demos).expert_observations, obs[:-1])

    def test_set_subgoal_validation_and_state(self):
        t = SubgoalMatchingReward(torch.randn(5, 2))
        t.set_subgoal(4)
        assert t.subgoal == 4
        for bad, err in [(5, ValueError), (-1, ValueError), (1.0, TypeError), (True, TypeError), ("2", TypeError)]:
            with pytest.raises(err):
                t.set_subgoal(bad)
        assert t.subgoal == 4
        other = SubgoalMatchingReward(torch.randn(5, 2))
        other.load_state_dict(t.state_dict())
        assert other.subgoal == 4

    def test_bad_construction(self):
        with pytest.raises(ValueError, match="out of range"):
            SubgoalMatchingReward(torch.randn(5, 3), position_feature_indices=[3])
        with pytest.raises(ValueError, match="shape"):
            SubgoalMatchingReward(torch.randn(5))
        with pytest.raises(ValueError, match="target"):
            SubgoalMatchingReward(torch.randn(5, 3), target="paper")


# --------------------------------------------------------------------------- env usage
def _expert(seed: int = 0, length: int = 10) -> torch.Tensor:
    return torch.randn(length, OBS_DIM, generator=torch.Generator().manual_seed(seed))


def _check_rollout_rewards(rollout, transform, subgoal):
    obs = rollout["observation"].reshape(-1, OBS_DIM)
    next_obs = rollout["next", "observation"].reshape(-1, OBS_DIM)
    want = reference_matching_reward(
        obs, next_obs, transform.expert_observations, subgoal, [0, 1, 2], [0, 1], transform.scale
    )
    got = rollout["next", "matching_reward"].reshape(-1).numpy()
    assert np.abs(want).max() > 1e-3  # the transitions do move relative to the target
    np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-4)


def _matching(expert=None, subgoal=3):
    return SubgoalMatchingReward(
        _expert() if expert is None else expert, subgoal=subgoal,
        ego_feature_indices=[0, 1, 2], position_feature_indices=[0, 1], scale=10.0,
    )


class TestMatchingRewardEnv:
    def test_single_env_and_set_subgoal(self):
        torch.manual_seed(0)
        t = _matching()
        env = TransformedEnv(ContinuousActionVecMockEnv(), t)
        check_env_specs(env)
        assert env.reward_key == "reward"
        env.set_seed(0)
        rollout = env.rollout(4)
        _check_rollout_rewards(rollout, t, 3)
        # the new subgoal is used from the very next step on
        t.set_subgoal(8)
        td = env.step(env.rand_action(env.reset()))
        _check_rollout_rewards(td.unsqueeze(0), t, 8)
        rollout = env.rollout(6)
        _check_rollout_rewards(rollout, t, 8)
        args = (rollout["observation"], rollout["next", "observation"], t.expert_observations)
        assert not np.allclose(
            reference_matching_reward(*args, 8, [0, 1, 2], [0, 1], 10.0),
            reference_matching_reward(*args, 3, [0, 1, 2], [0, 1], 10.0),
        )

    def test_serial_env(self):
        t = _matching()
        env = TransformedEnv(SerialEnv(2, ContinuousActionVecMockEnv), t)
        check_env_specs(env)
        rollout = env.rollout(3)
        assert rollout["next", "matching_reward"].shape == (2, 3, 1)
        _check_rollout_rewards(rollout, t, 3)
        t.set_subgoal(0)
        _check_rollout_rewards(env.rollout(2), t, 0)
        env.close()

    def test_parallel_env_full_reward(self):
        """Matching + intrinsic + combination over a ParallelEnv (transforms in the main process)."""
        t = _matching()
        reward_net = make_reward_network(OBS_DIM)
        env = TransformedEnv(
            ParallelEnv(2, ContinuousActionVecMockEnv),
            Compose(
                t,
                IntrinsicReward(reward_net),
                CombineRewards(["matching_reward", "intrinsic_reward"], keep_original="env_reward"),
            ),
        )
        try:
            check_env_specs(env)
            assert env.reward_key == "reward"
            rollout = env.rollout(3)
            _check_rollout_rewards(rollout, t, 3)
            with torch.no_grad():
                r_w = reward_net(rollout.select("observation"))["intrinsic_reward"]
            torch.testing.assert_close(rollout["next", "intrinsic_reward"], r_w)
            torch.testing.assert_close(
                rollout["next", "reward"], rollout["next", "matching_reward"] + rollout["next", "intrinsic_reward"]
            )
            t.set_subgoal(9)
            _check_rollout_rewards(env.rollout(2), t, 9)
        finally:
            env.close()

    def test_highway_env(self):
        pytest.importorskip("highway_env")
        from torchrl.envs import FlattenObservation, GymEnv

        config = {
            "action": {"type": "ContinuousAction"},
            "observation": {"type": "Kinematics", "vehicles_count": 2, "features": ["presence", "x", "y", "vx", "vy"],
                            "absolute": True, "normalize": True},
            "vehicles_count": 2,
            "duration": 5,
        }
        base = GymEnv("highway-fast-v0", config=config)
        env = TransformedEnv(base, FlattenObservation(-2, -1, in_keys=["observation"]))
        env.set_seed(0)
        expert = env.rollout(4, break_when_any_done=False)["next", "observation"]
        t = SubgoalMatchingReward(expert, subgoal=2, ego_feature_indices=[1, 2, 3, 4], position_feature_indices=[1], scale=700.0)
        env.append_transform(t)
        check_env_specs(env)
        rollout = env.rollout(3, break_when_any_done=False)
        want = reference_matching_reward(rollout["observation"], rollout["next", "observation"], expert, 2, [1, 2, 3, 4], [1], 700.0)
        assert np.abs(want).max() > 1e-3
        np.testing.assert_allclose(rollout["next", "matching_reward"].reshape(-1).numpy(), want, rtol=1e-4, atol=1e-3)
        env.close()


# --------------------------------------------------------------------------- replay buffer usage
def _buffer_with_data(n: int = 32) -> TensorDictReplayBuffer:
    env = ContinuousActionVecMockEnv()
    env.set_seed(1)
    data = env.rollout(n, break_when_any_done=False)
    rb = TensorDictReplayBuffer(storage=LazyTensorStorage(n), batch_size=16)
    rb.extend(data)
    return rb


class TestReplayBufferTransforms:
    def test_matching_reward_recomputed_for_current_subgoal(self):
        rb = _buffer_with_data()
        t = _matching()
        rb.append_transform(t)
        for subgoal in (3, 7, 0):
            t.set_subgoal(subgoal)
            sample = rb.sample()
            _check_rollout_rewards(sample, t, subgoal)
        # the stored data is untouched
        assert "matching_reward" not in rb.storage[:]["next"].keys()

    def test_intrinsic_and_combined(self):
        rb = _buffer_with_data()
        net = make_reward_network(OBS_DIM)
        t = _matching()
        rb.append_transform(Compose(t, IntrinsicReward(net), CombineRewards(["matching_reward", "intrinsic_reward"])))
        sample = rb.sample()
        with torch.no_grad():
            expected = net(sample.select("observation"))["intrinsic_reward"]
        torch.testing.assert_close(sample["next", "intrinsic_reward"], expected)
        torch.testing.assert_close(
            sample["next", "reward"], sample["next", "matching_reward"] + sample["next", "intrinsic_reward"]
        )
        # updating the network in place is visible at the next sample (held by reference)
        with torch.no_grad():
            for p in net.parameters():
                p.zero_()
            net.module.mlp[-1].bias.fill_(0.5)
        sample = rb.sample()
        torch.testing.assert_close(sample["next", "intrinsic_reward"], torch.full((16, 1), float(np.tanh(0.5))))


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("target", ["next", "final", "path"])
def test_reward_transforms_on_the_learners_device(device, target):
    """As in the recipe with ``device=cuda``: expert states, buffer and reward network on the device."""
    env = ContinuousActionVecMockEnv()
    env.set_seed(1)
    data = env.rollout(32, break_when_any_done=False)
    rb = TensorDictReplayBuffer(storage=LazyTensorStorage(32, device=device), batch_size=16)
    rb.extend(data)
    matching = SubgoalMatchingReward(_expert().to(device), subgoal=3, ego_feature_indices=[0, 1, 2],
                                     position_feature_indices=[0, 1], scale=10.0, target=target)
    net = make_reward_network(OBS_DIM).to(device)
    rb.append_transform(Compose(matching, IntrinsicReward(net), CombineRewards(["matching_reward", "intrinsic_reward"])))
    sample = rb.sample()
    assert sample["next", "reward"].device.type == device
    on_cpu = SubgoalMatchingReward(_expert(), subgoal=3, ego_feature_indices=[0, 1, 2],
                                   position_feature_indices=[0, 1], scale=10.0, target=target)
    want = on_cpu(sample.cpu().exclude(("next", "matching_reward")))["next", "matching_reward"]
    torch.testing.assert_close(sample["next", "matching_reward"].cpu(), want, rtol=1e-5, atol=1e-5)


class TestIntrinsicReward:
    def test_network_range_and_modes(self):
        net = make_reward_network(OBS_DIM, hidden=(32, 32))
        assert net.in_keys == ["observation"] and net.out_keys == ["intrinsic_reward"]
        with torch.no_grad():
            for p in net.parameters():
                p.mul_(50)  # saturate: still strictly inside (-1, 1) up to float rounding
        out = net(TensorDict({"observation": torch.randn(64, OBS_DIM)}, [64]))["intrinsic_reward"]
        assert out.shape == (64, 1) and out.abs().max() <= 1.0
        sa = make_reward_network(OBS_DIM, action_dim=3)
        td = sa(TensorDict({"observation": torch.randn(5, OBS_DIM), "action": torch.randn(5, 3)}, [5]))
        assert td["intrinsic_reward"].shape == (5, 1)
        assert sum(p.numel() for p in make_reward_network(10).parameters()) == 10 * 256 + 256 + 256 * 256 + 256 + 256 + 1
        with pytest.raises(ValueError, match="obs_dim"):
            make_reward_network(0)
        with pytest.raises(ValueError, match="in_keys"):
            make_reward_network(4, action_dim=2, in_keys=["observation"])

    def test_state_action_in_env_and_grad_option(self):
        net = make_reward_network(OBS_DIM, action_dim=OBS_DIM)
        env = TransformedEnv(ContinuousActionVecMockEnv(), IntrinsicReward(net))
        check_env_specs(env)
        rollout = env.rollout(3)
        with torch.no_grad():
            expected = net(rollout.select("observation", "action"))["intrinsic_reward"]
        torch.testing.assert_close(rollout["next", "intrinsic_reward"], expected)
        assert not rollout["next", "intrinsic_reward"].requires_grad
        td = IntrinsicReward(net, no_grad=False)(rollout.select("observation", "action", "next").clone())
        assert td["next", "intrinsic_reward"].requires_grad
        td["next", "intrinsic_reward"].sum().backward()
        assert all(p.grad is not None for p in net.parameters())

    def test_combine_rewards_weights_and_errors(self):
        td = TensorDict({"next": {"a": torch.ones(3, 1), "b": torch.full((3, 1), 2.0)}}, [3])
        out = CombineRewards(["a", "b"], weights=[0.5, -1.0])(td)
        torch.testing.assert_close(out["next", "reward"], torch.full((3, 1), -1.5))
        with pytest.raises(KeyError, match="'c'"):
            CombineRewards(["a", "c"])(td)
        with pytest.raises(ValueError, match="weights"):
            CombineRewards(["a", "b"], weights=[1.0])


def test_matching_reward_reads_the_subgoal_of_its_owner():
    """One owner: a transform built with ``subgoal=curriculum`` follows it and cannot be set."""
    from torchrl_csirl.curriculum import SubgoalCurriculum
    from torchrl_csirl.modules import make_actor, make_qvalue
    from torchrl_csirl.objectives import EnsembleSACLoss

    expert = torch.stack([torch.tensor([float(i), 0.0]) for i in range(8)])
    actor = make_actor(2, 1, hidden=(8,))
    curriculum = SubgoalCurriculum(expert, EnsembleSACLoss(actor, make_qvalue(2, 1, hidden=(8,))), actor,
                                   initial_subgoal=2)
    t = SubgoalMatchingReward(expert, subgoal=curriculum, position_feature_indices=[0])
    assert t.subgoal_source is curriculum and t.subgoal == 2
    curriculum.set_subgoal(6)
    assert t.subgoal == 6 and "subgoal=6" in repr(t)
    td = TensorDict({"observation": torch.zeros(1, 2), "next": {"observation": torch.tensor([[1.0, 0.0]])}}, [1])
    fixed = SubgoalMatchingReward(expert, subgoal=6, position_feature_indices=[0])
    torch.testing.assert_close(t(td.clone())["next", "matching_reward"], fixed(td.clone())["next", "matching_reward"])
    with pytest.raises(RuntimeError, match="reads its subgoal from SubgoalCurriculum"):
        t.set_subgoal(3)
    assert "curriculum" not in dict(t.named_modules())  # read, not owned: not a submodule
    with pytest.raises(TypeError, match="an int or an object with an int 'subgoal' attribute"):
        SubgoalMatchingReward(expert, subgoal="three")


def test_path_rule_measures_progress_along_the_route_and_does_not_pay_cutting_a_corner():
    from torchrl_csirl.data import curriculum_trajectory
    from torchrl_csirl.tasks import SCENARIOS

    # a straight route: the same reward as "final"
    line = torch.arange(6.0).unsqueeze(-1)
    s, s_next = torch.tensor([[0.5], [2.0], [4.5]]), torch.tensor([[1.5], [2.5], [4.0]])
    rewards = {rule: matching_reward(s, s_next, line, 3, scale=10.0, target=rule) for rule in ("final", "path")}
    torch.testing.assert_close(rewards["path"], rewards["final"])
    # the intersection's left turn: from before the turn, a step straight at the exit is worth the
    # most under "final" and less than following the route under "path"
    spec = SCENARIOS["intersection"]
    expert = curriculum_trajectory("intersection")["observation"]
    pos = list(spec.position_feature_indices)
    before_turn = expert[8:9]
    step = (expert[9:10] - expert[8:9])[:, pos].norm()
    straight = before_turn.clone()
    towards_exit = expert[-1, pos] - before_turn[0, pos]
    straight[0, pos] += step * towards_exit / towards_exit.norm()

    def reward(s_next, rule):
        return matching_reward(before_turn, s_next, expert, 0, position_feature_indices=pos, target=rule).item()

    assert reward(straight, "final") > reward(expert[9:10], "final")  # the straight line pays the cut
    assert reward(straight, "path") < reward(expert[9:10], "path")  # the path does not
    assert reward(expert[9:10], "path") == pytest.approx(step.item(), rel=1e-4)  # one step along it
    # a whole expert trajectory earns its route's length, and SubgoalMatchingReward takes the rule
    transform = SubgoalMatchingReward(expert, subgoal=0, position_feature_indices=pos, target="path")
    td = TensorDict({"observation": expert[:-1], "next": {"observation": expert[1:]}}, [expert.shape[0] - 1])
    route = (expert[1:, pos] - expert[:-1, pos]).norm(dim=-1).sum()
    assert transform(td)["next", "matching_reward"].sum().item() == pytest.approx(route.item(), rel=1e-4)
    with pytest.raises(ValueError, match="target must be one of"):
        SubgoalMatchingReward(expert, target="geodesic")


def test_a_failed_termination_pays_back_the_progress_made():
    from torchrl_csirl.transforms import failed_termination_potential

    expert = torch.arange(5.0).unsqueeze(-1)  # s^e_0 .. s^e_4 at 0 .. 4, target "final" = 4
    transform = SubgoalMatchingReward(expert, subgoal=0, scale=10.0, target="final",
                                      failure_keys=("crashed", "offroad"))
    s = torch.tensor([[3.0], [3.0], [3.0], [-1.0]])
    s_next = torch.tensor([[3.5], [3.5], [3.5], [-1.5]])
    td = TensorDict({"observation": s, "next": {
        "observation": s_next,
        "crashed": torch.tensor([[False], [True], [False], [True]]),
        "offroad": torch.tensor([[False], [False], [True], [False]])}}, [4])
    reward = transform(td)["next", "matching_reward"].squeeze(-1)
    # psi(s) = 1; a failure gives s' the start's potential psi(s^e_0) = 4, not psi(s') = 0.5;
    # behind the start, psi(s') = 5.5 > 4 is kept: a failure never pays more than no failure
    assert reward.tolist() == [5.0, -30.0, -30.0, -5.0]
    # without the flags (e.g. an expert transition) nothing is a failure
    plain = transform(TensorDict({"observation": s, "next": {"observation": s_next}}, [4]))
    assert plain["next", "matching_reward"].squeeze(-1).tolist() == [5.0, 5.0, 5.0, -5.0]
    # the published behaviour is the default
    assert SubgoalMatchingReward(expert, scale=10.0, target="final")(td)["next", "matching_reward"][1].item() == 5.0
    # an episode from the start that fails keeps nothing of its progress (undiscounted)
    path = torch.tensor([0.0, 1.0, 2.0, 3.0, 3.5]).unsqueeze(-1)
    episode = TensorDict({"observation": path[:-1], "next": {
        "observation": path[1:], "crashed": torch.tensor([False, False, False, True]).unsqueeze(-1)}}, [4])
    assert transform(episode)["next", "matching_reward"].sum().item() == 0.0
    assert failed_termination_potential(torch.tensor([0.5]), torch.tensor([4.0]), torch.tensor([True])).item() == 4.0


def test_a_crash_in_highway_fast_pays_back_the_progress_in_the_env():
    from torchrl_csirl.data import curriculum_trajectory
    from torchrl_csirl.tasks import FAILURE_KEYS, SCENARIOS, make_env

    spec = SCENARIOS["highway-fast"]
    expert = curriculum_trajectory("highway-fast")["observation"]
    env = TransformedEnv(make_env("highway-fast", seed=0), SubgoalMatchingReward(
        expert, subgoal=0, ego_feature_indices=spec.position_feature_indices,
        position_feature_indices=spec.position_feature_indices, scale=spec.matching_scale, target="final",
        failure_keys=FAILURE_KEYS))
    full_throttle = TensorDict({"action": torch.tensor([1.0, 0.0])}, [])
    rollout = env.rollout(spec.max_steps, lambda td: td.update(full_throttle))
    env.close()
    assert rollout["next", "crashed"][-1].item()  # into the slower traffic ahead
    x = rollout["observation"][:, spec.position_feature_indices[0]]
    goal = expert[-1, spec.position_feature_indices[0]]
    start = expert[0, spec.position_feature_indices[0]]
    last = rollout["next", "matching_reward"][-1].item()
    assert last == pytest.approx(spec.matching_scale * ((goal - x[-1]).abs() - (goal - start).abs()).item(), rel=1e-5)
    assert rollout["next", "matching_reward"][:-1].sum().item() > 0 > last
