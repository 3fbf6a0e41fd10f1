"""Tests of the curricular subgoal selection."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from tensordict import TensorDict
from tensordict.nn import TensorDictModule
from torchrl.envs.utils import ExplorationType, set_exploration_type

from torchrl_csirl.curriculum import (
    SubgoalCurriculum,
    SubgoalSelection,
    critic_uncertainty,
    scan_subgoal,
)


class ScaledCritics:
    """A stand-in ensemble: Q_k(s, a) = k * f(s) (+ a), so Var_k = f(s)^2 * Var(0..N-1)."""

    def __init__(self, num: int = 5):
        self.num = num

    def qvalues(self, td):
        f = td["observation"][..., 0] + 0.0 * td["action"][..., 0]
        k = torch.arange(self.num, dtype=f.dtype).reshape(-1, *([1] * f.ndim))
        return k * f


def _identity_policy():
    return TensorDictModule(lambda obs: obs[..., :1].tanh(), in_keys=["observation"], out_keys=["action"])


def _expert_from_profile(sqrt_u):
    """Expert observations whose stand-in uncertainty is proportional to ``sqrt_u ** 2``."""
    return torch.tensor(sqrt_u, dtype=torch.float32).reshape(-1, 1).repeat(1, 3)


class TestScan:
    def test_ratio_tested_before_update(self):
        # with the ratio tested against U^avg_{p-1}: 6 / 1 > 5 -> subgoal 2.
        # (updating first would give U^avg = 0.2 + 0.8 * 6 = 5 and a ratio of 1.2: no subgoal)
        g, ratios = scan_subgoal(torch.tensor([1.0, 1.0, 6.0]), subgoal=0, delta=5.0, sigma=0.2)
        assert g == 2
        assert math.isnan(ratios[0]) and ratios[1:].tolist() == [1.0, 6.0]

    def test_soft_average_hand_computed(self):
        u = torch.tensor([9.0, 2.0, 4.0, 1.0, 10.0, 100.0])
        # g = 1: avg 2; p=2: 4/2 = 2, avg = 0.4 + 3.2 = 3.6; p=3: 1/3.6, avg = 0.72 + 0.8 = 1.52;
        # p=4: 10/1.52 = 6.58 > 5 -> 4
        g, ratios = scan_subgoal(u, subgoal=1)
        assert g == 4
        np.testing.assert_allclose(ratios[2:5].numpy(), [2.0, 1 / 3.6, 10 / 1.52])
        assert math.isnan(ratios[5])
        # sigma = 1 keeps U^avg = U_g = 2: 10 / 2 = 5 is not > 5, 100 / 2 is
        assert scan_subgoal(u, subgoal=1, sigma=1.0)[0] == 5

    def test_no_detection_and_last_index(self):
        u = torch.ones(6)
        assert scan_subgoal(u, subgoal=2)[0] == 2
        g, ratios = scan_subgoal(u, subgoal=5)
        assert g == 5 and torch.isnan(ratios).all()

    def test_zero_average(self):
        assert scan_subgoal(torch.tensor([0.0, 0.0, 1e-9]), 0)[0] == 2

    def test_validation(self):
        with pytest.raises(ValueError, match="subgoal"):
            scan_subgoal(torch.ones(3), 3)
        with pytest.raises(ValueError, match="sigma"):
            scan_subgoal(torch.ones(3), 0, sigma=1.5)

    def test_uncertainty_measures(self):
        q = torch.randn(5, 7, dtype=torch.float64)
        np.testing.assert_allclose(critic_uncertainty(q).numpy(), np.var(q.numpy(), axis=0))
        np.testing.assert_allclose(
            critic_uncertainty(q, "abs_cv").numpy(), np.abs(np.var(q.numpy(), axis=0) / q.numpy().mean(0))
        )
        with pytest.raises(ValueError, match="N >= 2"):
            critic_uncertainty(torch.randn(1, 3))


class TestSubgoalCurriculum:
    def test_selection_with_stand_in_ensemble(self):
        expert = _expert_from_profile([1, 1, 1, 1, 1, 1, 1, 3, 1, 4])
        cur = SubgoalCurriculum(expert, ScaledCritics(), _identity_policy(), initial_subgoal=2)
        sel = cur.step()
        assert isinstance(sel, SubgoalSelection)
        assert (sel.previous, sel.subgoal, sel.changed) == (2, 7, True)
        np.testing.assert_allclose(sel.profile.numpy(), np.var(np.arange(5)) * np.array([1, 1, 1, 1, 1, 1, 1, 9, 1, 16.0]), rtol=1e-6)
        # next round scans from 7: U^avg = 9 ... 16 / (0.2 * 9 + 0.8 * 1) is 6.15 > 5 -> 9
        sel = cur.step()
        assert (sel.previous, sel.subgoal) == (7, 9)
        # at the end: nothing left to scan, subgoal stays
        sel = cur.step()
        assert (sel.subgoal, sel.changed) == (9, False) and cur.round == 3

    def test_subgoal_never_moves_backward(self):
        expert = _expert_from_profile([1, 8, 1, 1, 1, 1])  # the only spike is behind g
        cur = SubgoalCurriculum(expert, ScaledCritics(), _identity_policy(), initial_subgoal=3)
        for _ in range(3):
            sel = cur.step()
            assert sel.subgoal == 3 and not sel.changed

    def test_initial_subgoal_seeded(self):
        expert = torch.zeros(20, 3)
        draws = [SubgoalCurriculum(expert, ScaledCritics(), _identity_policy(), seed=s).subgoal for s in range(30)]
        assert set(draws) <= {1, 2, 3, 4, 5} and len(set(draws)) >= 3
        again = [SubgoalCurriculum(expert, ScaledCritics(), _identity_policy(), seed=s).subgoal for s in range(30)]
        assert draws == again
        short = SubgoalCurriculum(torch.zeros(3, 3), ScaledCritics(), _identity_policy(), initial_range=(5, 5))
        assert short.subgoal == 2  # clipped to L - 1

    def test_validation(self):
        with pytest.raises(TypeError, match="qvalues"):
            SubgoalCurriculum(torch.zeros(5, 3), object(), _identity_policy())
        with pytest.raises(ValueError, match="dispersion"):
            SubgoalCurriculum(torch.zeros(5, 3), ScaledCritics(), _identity_policy(), dispersion="std")
        cur = SubgoalCurriculum(torch.zeros(5, 3), ScaledCritics(), _identity_policy(), initial_subgoal=1)
        with pytest.raises(ValueError):
            cur.set_subgoal(5)
        with pytest.raises(TypeError):
            cur.set_subgoal(2.0)


@pytest.fixture(scope="module")
def sac_parts():
    from torchrl_csirl.modules import make_actor, make_qvalue
    from torchrl_csirl.objectives import EnsembleSACLoss

    torch.manual_seed(0)
    actor = make_actor(6, 2, hidden=(16, 16))
    loss = EnsembleSACLoss(actor, make_qvalue(6, 2, hidden=(16, 16)), num_qvalue_nets=5)
    expert = torch.randn(12, 6, generator=torch.Generator().manual_seed(1)).cumsum(0) * 0.3
    return actor, loss, expert


class TestWithEnsembleSACLoss:
    def test_profile_matches_loss_dispersion(self, sac_parts):
        actor, loss, expert = sac_parts
        cur = SubgoalCurriculum(expert, loss, actor, deterministic_actions=True, initial_subgoal=1)
        with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
            td = actor(TensorDict({"observation": expert}, [12]))
            expected = loss.qvalue_dispersion(td, "variance")
        torch.testing.assert_close(cur.uncertainty_profile(), expected)
        cv = SubgoalCurriculum(expert, loss, actor, deterministic_actions=True, dispersion="abs_cv", initial_subgoal=1)
        with torch.no_grad():
            torch.testing.assert_close(cv.uncertainty_profile(), loss.qvalue_dispersion(td, "abs_cv"))

    def test_deterministic_given_seed_and_global_rng_untouched(self, sac_parts):
        actor, loss, expert = sac_parts
        a = SubgoalCurriculum(expert, loss, actor, seed=3)
        b = SubgoalCurriculum(expert, loss, actor, seed=3)
        c = SubgoalCurriculum(expert, loss, actor, seed=4)
        state = torch.random.get_rng_state()
        pa, pb, pc = a.uncertainty_profile(), b.uncertainty_profile(), c.uncertainty_profile()
        assert torch.equal(torch.random.get_rng_state(), state)
        assert torch.equal(pa, pb)
        assert not torch.equal(pa, pc)  # actions are sampled: another seed, other actions
        # successive rounds draw fresh actions
        assert not torch.equal(a.uncertainty_profile(round_index=1), pa)

    def test_state_dict_roundtrip(self, sac_parts):
        actor, loss, expert = sac_parts
        a = SubgoalCurriculum(expert, loss, actor, seed=5, delta=1.5)
        a.step()
        a.step()
        b = SubgoalCurriculum(expert, loss, actor, seed=99, delta=1.5)
        b.load_state_dict(a.state_dict())
        assert b.state_dict() == a.state_dict()
        sa, sb = a.step(), b.step()
        assert sa.subgoal == sb.subgoal and torch.equal(sa.profile, sb.profile)
        assert sa.subgoal >= sa.previous
