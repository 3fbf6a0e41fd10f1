"""The imitation baselines (docs/baselines.md): each loss's defining property on a tiny problem."""
from __future__ import annotations

import copy
import math
from types import SimpleNamespace

import pytest
import torch
from tensordict import TensorDict
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
from torchrl.envs import Compose

from torchrl_csirl.data import ExpertDemonstrations
from torchrl_csirl.modules import make_actor, make_qvalue
from torchrl_csirl.objectives import GAILHyperparameters
from torchrl_csirl.trainers.imitation import IMITATION_METHODS, make_imitation_method
from torchrl_csirl.transforms import DiscriminatorReward, absorbing_self_loops

OBS, ACT, HIDDEN = 3, 1, (32, 32)


@pytest.fixture(autouse=True, scope="module")
def one_thread():
    """Tiny networks: one intra-op thread is faster, and much faster on a busy machine."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def transitions(n: int, obs: torch.Tensor | float, action: torch.Tensor | float, terminated_every: int = 0,
                step: float = 0.1) -> TensorDict:
    """``n`` transitions ``s -> s + step``; ``obs``/``action`` are broadcast; every ``terminated_every``-th one terminates."""
    obs = torch.as_tensor(obs, dtype=torch.float32).expand(n, OBS).clone()
    action = torch.as_tensor(action, dtype=torch.float32).expand(n, ACT).clone()
    terminated = torch.zeros(n, 1, dtype=torch.bool)
    if terminated_every:
        terminated[terminated_every - 1::terminated_every] = True
    return TensorDict({
        "observation": obs, "action": action,
        "next": {"observation": obs + step, "terminated": terminated, "truncated": torch.zeros_like(terminated),
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
    with pytest.raises(ValueError, match="observations of size 4"):
        make_imitation_method("gail", make_actor(OBS, ACT, hidden=HIDDEN), lambda: make_qvalue(OBS, ACT), obs_dim=4,
                              action_dim=ACT)
    method = build("valuedice")
    online, expert = buffers(method, transitions(10, 0.0, 0.0), transitions(10, 1.0, 0.5))
    with pytest.raises(ValueError, match="valuedice needs expert demonstrations: the expert buffer is empty"):
        method.make_update_step(online, TensorDictReplayBuffer(storage=LazyTensorStorage(10)))
    no_done = TensorDictReplayBuffer(storage=LazyTensorStorage(10))
    no_done.extend(transitions(10, 1.0, 0.5).exclude(("next", "done")))
    with pytest.raises(ValueError, match=r"lack the keys \[\('next', 'done'\)\]"):
        method.make_update_step(online, no_done)
    from omegaconf import OmegaConf

    assert build("dac", OmegaConf.create({"gp_lambda": 5})).hyperparameters.gp_lambda == 5  # a recipe's config node
    with pytest.raises(ValueError, match="action_dim"):
        make_imitation_method("sqil", make_actor(OBS, 2, hidden=HIDDEN), lambda: make_qvalue(OBS, 2), obs_dim=OBS,
                              action_dim=ACT)


@pytest.mark.parametrize("name", IMITATION_METHODS)
def test_every_method_updates_and_checkpoints(name):
    method = build(name, {"batch_size": 16})
    online, expert = buffers(method, transitions(40, torch.randn(40, OBS), torch.rand(40, ACT) * 2 - 1, 10),
                             transitions(30, torch.randn(30, OBS), 0.5, 15))
    step = method.make_update_step(online, expert)
    losses = run_updates(step, trainer(online), 2)
    assert losses and all(torch.isfinite(v).all() and not v.requires_grad for v in losses.values())
    # a fresh method restored from the trained one's states holds the same tensors (the checkpoint's job)
    fresh = build(name, {"batch_size": 16})
    assert fresh.states.keys() == method.states.keys()
    for key, state in method.states.items():
        fresh.states[key].load_state_dict(copy.deepcopy(state.state_dict()))
        assert_same_state(fresh.states[key].state_dict(), state.state_dict(), key)


def assert_same_state(a, b, where: str = "") -> None:
    """Two (nested) ``state_dict``s hold equal tensors and values, and differ from nothing."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys(), where
        for k in a:
            assert_same_state(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, (list, tuple)):
        assert isinstance(b, (list, tuple)) and len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            assert_same_state(x, y, f"{where}[{i}]")
    elif isinstance(a, torch.Tensor):
        assert torch.equal(a, b), where
    else:
        assert a == b, where


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


# ------------------------------------------------------------------------------ GAIL, DAC
def expert_vs_random(n: int = 200):
    """Agent: random actions in [-1, 0]; expert: action 0.8; states from the same distribution."""
    gen = torch.Generator().manual_seed(1)
    obs = torch.randn(n, OBS, generator=gen)
    return (transitions(n, torch.randn(n, OBS, generator=gen), -torch.rand(n, ACT, generator=gen)),
            transitions(n, obs, 0.8))


def reward_transform(method):
    """The method's :class:`~torchrl_csirl.transforms.DiscriminatorReward` (an online-buffer transform)."""
    return next(tr for tr in method.online_transforms if isinstance(tr, DiscriminatorReward))


@pytest.mark.parametrize("name", ["gail", "dac"])
def test_discriminator_separates_expert_from_random(name):
    method = build(name, {"batch_size": 32, "discriminator_batch_size": 64, "discriminator_lr": 1e-3})
    online_data, expert_data = expert_vs_random()
    online, expert = buffers(method, online_data, expert_data)
    step = method.make_update_step(online, expert)
    t = trainer(online)
    reward = reward_transform(method)

    def reward_gap():
        return float(reward(expert.sample())["next", "reward"].mean() - reward(online.sample())["next", "reward"].mean())

    gap_before = reward_gap()
    for _ in range(300):  # DAC's gradient penalty (weight 10) first pulls the tiny net's slopes up to 1: slower
        step.discriminator_step(t)
    probability = method.states["discriminator"](online_data.select("observation", "action").update(
        {"absorbing": torch.zeros(200, 1, dtype=torch.bool)}))
    assert abs(gap_before) < 0.2 and reward_gap() > 0.5
    if name == "gail":  # D(s, a) -> 1 on expert pairs, lower on random ones
        d_agent = probability["d_logits"].mean()
        d_expert = method.states["discriminator"](expert_data.select("observation", "action"))["d_logits"].mean()
        assert d_expert > d_agent + 0.2


def test_gail_gradient_penalty_keeps_the_agent_reward():
    """Without the penalty the discriminator saturates on separable pairs and the agent's reward
    ``softplus(logit)`` vanishes (what stalls GAIL on HalfCheetah); the default penalty keeps it, and the gap."""
    online_data, expert_data = expert_vs_random()
    rewards = {}
    for use_grad_penalty in (False, True):
        method = build("gail", {"discriminator_batch_size": 64, "discriminator_lr": 1e-3,
                                "use_grad_penalty": use_grad_penalty})
        online, expert = buffers(method, online_data, expert_data)
        step, t = method.make_update_step(online, expert), trainer(online)
        for _ in range(400):
            out = step.discriminator_step(t)
        assert ("gp_loss" in out) == use_grad_penalty
        reward = reward_transform(method)
        with torch.no_grad():
            rewards[use_grad_penalty] = [float(reward(d.clone())["next", "reward"].mean()) for d in (online_data, expert_data)]
    assert GAILHyperparameters().use_grad_penalty
    assert rewards[False][0] < 0.01 and rewards[False][1] > 3.0
    assert rewards[True][0] > 0.1 and rewards[True][1] > rewards[True][0] + 0.5


@pytest.mark.parametrize("name", ["gail", "dac"])
def test_discriminator_step_touches_only_the_discriminator(name):
    method = build(name, {"batch_size": 16, "discriminator_batch_size": 16})
    online, expert = buffers(method, *expert_vs_random(50))
    step = method.make_update_step(online, expert)
    sac, discriminator = method.states["loss"], method.states["discriminator"]
    before = {n: p.detach().clone() for n, p in sac.named_parameters()}
    step.discriminator_step(trainer(online))
    assert all(torch.equal(p, before[n]) for n, p in sac.named_parameters())
    assert all(p.grad is None or p.grad.abs().sum() == 0 for p in sac.parameters())
    assert any(p.grad is not None and p.grad.abs().sum() > 0 for p in discriminator.parameters())


@pytest.mark.parametrize("absorbing_observation", ["placeholder", "terminal"])
def test_dac_absorbing_states_on_expert_and_online_batches(absorbing_observation):
    from torchrl_csirl.objectives._imitation import sample

    hp = {"batch_size": 16, "gamma": 0.9, "absorbing_observation": absorbing_observation}
    method = build("dac", hp)
    online, expert = buffers(method, transitions(40, 0.0, 0.0, terminated_every=4), transitions(40, 1.0, 0.8, 10))
    for data, transforms in ((transitions(40, 1.0, 0.0, 4), method.online_transforms[:1]),
                             (expert.storage[:], method.expert_transforms)):
        into = Compose(*transforms)(data.clone())["next", "absorbing"].squeeze(-1)
        torch.testing.assert_close(into, data["next", "terminated"].squeeze(-1))
    # the absorbing state's observation: the placeholder, or the terminal observation (s + 0.1 here)
    for buffer, terminal_observation in ((online, 0.1), (expert, 1.1)):
        batch = sample(buffer, 40)
        into = batch["next", "absorbing"].squeeze(-1)
        expected = 0.0 if absorbing_observation == "placeholder" else terminal_observation
        assert not batch["absorbing"].any()
        torch.testing.assert_close(batch["next", "observation"][into], torch.full((int(into.sum()), OBS), expected))
    # the absorbing state has its own learned reward r_a; entering it pays r + gamma r_a / (1 - gamma)
    discriminator, loss = method.states["discriminator"], method.make_update_step(online, expert).discriminator_step.loss
    with torch.no_grad():
        discriminator.module.indicator_weight.fill_(3.0)
    loop_observation = 0.0 if absorbing_observation == "placeholder" else 0.1
    loop = TensorDict({"observation": torch.full((1, OBS), loop_observation),
                       "absorbing": torch.ones(1, 1, dtype=torch.bool), "action": torch.zeros(1, ACT)}, [1])
    r_a = float(discriminator(loop)["discriminator_logit"])
    batch = sample(online, 40)
    into = batch["next", "absorbing"].squeeze(-1)
    real = discriminator(batch.select("observation", "absorbing", "action"))["discriminator_logit"].squeeze(-1)
    torch.testing.assert_close(batch["next", "reward"].squeeze(-1), real + into.float() * r_a * 0.9 / 0.1)
    # the discriminator sees one absorbing sample per terminal transition, on both sides
    td = TensorDict({"expert": sample(expert, 40), "collector": batch}, [])
    logits = [loss._logit(loss._with_self_loops(td[side])) for side in ("expert", "collector")]
    n_into = [int(td[side]["next", "absorbing"].sum()) for side in ("expert", "collector")]
    assert [len(x) for x in logits] == [40 + n_into[0], 40 + n_into[1]]
    torch.testing.assert_close(logits[1][40:], torch.full((n_into[1],), r_a))
    out = loss(td)
    for key in ("loss_discriminator", "loss_gradient_penalty"):  # r_a is learned, and regularised
        (grad,) = torch.autograd.grad(out[key], discriminator.module.indicator_weight, retain_graph=True)
        assert grad.abs().item() > 0, key


@pytest.mark.parametrize("absorbing_observation", ["placeholder", "terminal"])
def test_dac_absorbing_reward_of_an_expert_success_and_an_agent_failure(absorbing_observation):
    """Demonstrations ending in a terminating success (at s = 1.1), an agent terminating early (at s = 0.1).

    With the paper's single absorbing state both endings share one learned reward ``r_a``; with
    one absorbing state per terminal observation the discriminator tells the expert's ending
    (expert-like, ``r_a > 0``) from the agent's (``r_a < 0``).
    """
    from torchrl_csirl.objectives._imitation import sample

    method = build("dac", {"batch_size": 64, "discriminator_batch_size": 64,
                           "absorbing_observation": absorbing_observation})
    online, expert = buffers(method, transitions(200, 0.0, 0.0, terminated_every=4),
                             transitions(200, 1.0, 0.8, terminated_every=20))
    run_updates(method.make_update_step(online, expert).discriminator_step, trainer(online), 200)
    discriminator = method.states["discriminator"]
    with torch.no_grad():
        r_a = [discriminator(absorbing_self_loops(sample(buffer, 200)).select(*discriminator.in_keys))[
            "discriminator_logit"].mean().item() for buffer in (online, expert)]
    if absorbing_observation == "placeholder":
        assert r_a[0] == pytest.approx(r_a[1])
    else:
        assert r_a[0] < -0.3 and r_a[1] > 0.3


def test_dac_gradient_penalty_one_weight_per_sample():
    from torchrl_csirl.objectives import DACDiscriminatorLoss

    class Linear(torch.nn.Module):  # logit = w . [obs, act]: its input gradient is w everywhere
        def __init__(self):
            super().__init__()
            self.w = torch.nn.Parameter(torch.tensor([3.0, 0.0, 0.0, 4.0]))

        def forward(self, observation, action):
            return (torch.cat([observation, action], -1) * self.w).sum(-1, keepdim=True)

    from tensordict.nn import TensorDictModule
    disc = TensorDictModule(Linear(), in_keys=["observation", "action"], out_keys=["discriminator_logit"])
    loss = DACDiscriminatorLoss(disc, gp_lambda=10.0)
    td = TensorDict({"expert": transitions(8, 1.0, 0.5).select("observation", "action"),
                     "collector": transitions(8, 0.0, 0.0).select("observation", "action")}, [])
    torch.testing.assert_close(loss(td)["loss_gradient_penalty"], torch.tensor(10.0 * (5.0 - 1.0) ** 2))
    with pytest.raises(KeyError, match="lacks the keys"):
        loss(TensorDict({"expert": td["expert"].exclude("action"), "collector": td["collector"]}, []))


# ------------------------------------------------------------------------------ IQ-Learn, ValueDICE
def deterministic_action(policy) -> float:
    from torchrl.envs.utils import ExplorationType, set_exploration_type

    with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
        return float(policy(TensorDict({"observation": torch.zeros(1, OBS)}, [1]))["action"])


@pytest.mark.parametrize(("name", "hyperparameters", "updates"), [
    ("iqlearn", {"batch_size": 64, "lr": 1e-3, "actor_lr": 1e-3}, 100),
    # the paper's actor rate (1e-5) is too slow for a unit test; at 1e-3 the tanh policy overshoots and saturates
    ("valuedice", {"batch_size": 64, "actor_lr": 1e-4}, 150),
])
def test_policy_moves_toward_the_expert_action_on_a_one_state_task(name, hyperparameters, updates):
    """One state that loops on itself; the expert always plays 0.5, the replay holds random actions."""
    method = build(name, hyperparameters)
    gen = torch.Generator().manual_seed(0)
    online, expert = buffers(method, transitions(200, 0.0, torch.rand(200, ACT, generator=gen) * 2 - 1, step=0.0),
                             transitions(50, 0.0, 0.5, step=0.0))
    step, t = method.make_update_step(online, expert), trainer(online)
    before = abs(deterministic_action(method.policy) - 0.5)
    run_updates(step, t, updates)
    after = abs(deterministic_action(method.policy) - 0.5)
    assert after < before - 0.08, (before, after)


def test_iqlearn_losses_reach_only_their_networks():
    from torchrl_csirl.objectives._imitation import sample

    method = build("iqlearn", {"batch_size": 16})
    online, expert = buffers(method, *expert_vs_random(40))
    loss = method.states["loss"]
    td = TensorDict({"expert": sample(expert, 8), "collector": sample(online, 8)}, [])
    names, params = zip(*[(n, p) for n, p in loss.named_parameters()])
    for key, reached in (("loss_qvalue", "qvalue"), ("loss_actor", "actor")):
        grads = torch.autograd.grad(loss(td)[key], params, allow_unused=True)
        touched = {n.split("_network")[0] for n, g in zip(names, grads) if g is not None and g.abs().sum() > 0}
        assert touched == {reached}, (key, touched)
    with pytest.raises(ValueError, match="num_qvalue_nets must be >= 2"):
        build("iqlearn", {"num_qvalue_nets": 1})


@pytest.mark.parametrize("use_target_value", [True, False])
def test_iqlearn_reads_the_successor_value_from_the_target_critics(use_target_value):
    """The authors' setting: ``V(s')`` from the Polyak-averaged critics; ``Q(s, a)`` from the trained ones."""
    from torchrl_csirl.objectives._imitation import sample

    method = build("iqlearn", {"batch_size": 16, "use_target_value": use_target_value})
    online, expert = buffers(method, *expert_vs_random(40))
    loss = method.states["loss"]
    td = TensorDict({"expert": sample(expert, 8), "collector": sample(online, 8)}, [])
    torch.manual_seed(0)
    before = loss(td)["loss_qvalue"].detach()
    with torch.no_grad():
        for param in loss.target_qvalue_network_params.values(True, True):
            param.add_(0.5)
    torch.manual_seed(0)  # the same sampled actions
    after = loss(td)["loss_qvalue"].detach()
    assert (not torch.allclose(before, after)) == use_target_value
    # the actor learns at the authors' slower rate, the critics at SAC's
    assert sorted(group["lr"] for group in method.states["optim_sac"].param_groups) == [3e-5, 3e-4]


def test_iqlearn_v0_and_the_policy_actions_regulariser_as_the_authors_code():
    """The authors' Hopper form: ``-E_E[r] + (1 - gamma) E_E[V(s)] + E_mix[r^2] / (4 c)`` (``"value"``: the
    mixture's ``V(s) - gamma V(s')``), the same sampled actions; their regulariser at the policy's actions."""
    from torchrl_csirl.objectives._imitation import concat_shared, sample
    from torchrl_csirl.objectives.iq_learn import inverse_soft_q_objective

    gamma = 0.9
    method = build("iqlearn", {"batch_size": 16, "gamma": gamma, "value_loss": "v0"})
    online, expert = buffers(method, *expert_vs_random(40))
    loss = method.states["loss"]
    td = TensorDict({"expert": sample(expert, 8), "collector": sample(online, 8)}, [])
    torch.manual_seed(0)
    got = loss(td)["loss_qvalue"]
    torch.manual_seed(0)
    reward, value, next_value, policy_q = loss._implicit_reward(concat_shared(td["expert"], td["collector"]))
    torch.testing.assert_close(got, inverse_soft_q_objective(reward[:, :8], (1 - gamma) * value[:, :8], reward, 0.5))
    assert not torch.allclose(got, inverse_soft_q_objective(reward[:, :8], value - next_value, reward, 0.5))
    # the authors' code regularises the replay part at the policy's actions: Q(s, a ~ pi) - gamma V(s')
    loss.chi2_policy_actions = True
    torch.manual_seed(0)
    got = loss(td)["loss_qvalue"]
    at_policy = torch.cat([reward[:, :8], (policy_q - next_value)[:, 8:]], -1)
    torch.testing.assert_close(got, inverse_soft_q_objective(reward[:, :8], (1 - gamma) * value[:, :8], at_policy, 0.5))
    with pytest.raises(ValueError, match="value_loss must be one of"):
        build("iqlearn", {"value_loss": "v1"})


@pytest.mark.parametrize("absorbing_states", [True, False])
def test_valuedice_residual_after_a_termination(absorbing_states):
    """With absorbing states (the paper's): ``nu(s, a) - gamma nu(s_a, 0)`` after a termination and one
    self-loop sample ``(1 - gamma) nu(s_a, 0)`` per termination; without: ``nu(s, a)``."""
    from torchrl_csirl.objectives._imitation import sample

    gamma = 0.9
    method = build("valuedice", {"batch_size": 16, "gamma": gamma, "absorbing_states": absorbing_states})
    online, _ = buffers(method, transitions(40, 0.0, 0.3, terminated_every=4), transitions(40, 1.0, 0.8, 10))
    loss = method.states["loss"]
    assert loss.reads_absorbing == absorbing_states
    batch = sample(online, 40)
    ends = batch["next", "terminated"].squeeze(-1)
    with torch.no_grad():
        residual, successor = loss._residual(batch)
        here = loss.nu(batch["observation"], batch["action"])
        terminal_obs = batch["next", "observation"][ends]  # 0.1: the absorbing state's observation
        if absorbing_states:
            s_a = loss.nu(terminal_obs, torch.zeros(len(terminal_obs), ACT), torch.ones(len(terminal_obs), 1))
            assert residual.shape == (40 + int(ends.sum()),)
            torch.testing.assert_close(residual[:40][ends], here[ends] - gamma * s_a)
            torch.testing.assert_close(residual[40:], (1 - gamma) * s_a)
            assert successor["action"][ends].eq(0).all() and successor["absorbing"].squeeze(-1).eq(ends).all()
        else:
            assert residual.shape == (40,)
            torch.testing.assert_close(residual[ends], here[ends])
    # the gradient penalty reaches the indicator's weight (it bounds the absorbing state's nu)
    if absorbing_states:
        with torch.no_grad():  # at w = 0 the penalty's derivative in w vanishes
            loss.nu_network.module.indicator_weight.fill_(3.0)
        td = TensorDict({"expert": sample(online, 16), "collector": batch,
                         "initial": TensorDict({"observation": torch.zeros(4, OBS)}, [4])}, [])
        (grad,) = torch.autograd.grad(loss(td)["loss_gradient_penalty"], loss.nu_network.module.indicator_weight)
        assert grad.abs().item() > 0


@pytest.mark.parametrize("name", ["dac", "valuedice"])
def test_self_loops_per_termination_weights_the_learners_absorbing_state(name):
    """``self_loops_per_termination=k`` (the authors' later code: 10): k absorbing self-loop samples per learner
    transition entering the absorbing state, one per expert one, in the objective the method trains on."""
    from torchrl_csirl.objectives import dac_discriminator_loss, valuedice_objective
    from torchrl_csirl.objectives._imitation import sample

    with pytest.raises(ValueError, match="self_loops_per_termination must be an integer >= 1, got 0"):
        build(name, {"self_loops_per_termination": 0})
    k = 10
    method = build(name, {"self_loops_per_termination": k, "absorbing_observation": "placeholder"})
    online, expert = buffers(method, transitions(40, 0.0, 0.3, terminated_every=4), transitions(40, 1.0, 0.8, 10))
    agent, demos = sample(online, 40), sample(expert, 40)
    into = [int(td["next", "absorbing"].sum()) for td in (demos, agent)]
    assert all(into)
    if name == "dac":
        loss = method.make_update_step(online, expert).discriminator_step.loss
        assert loss.self_loops_per_termination == k
        sides = [loss._with_self_loops(demos), loss._with_self_loops(agent, k)]
        assert [s.numel() for s in sides] == [40 + into[0], 40 + k * into[1]]
        assert sides[1]["absorbing"][40:].all()
        expected = dac_discriminator_loss(*(loss._logit(s) for s in sides))
        out = loss(TensorDict({"expert": demos, "collector": agent}, []))
        torch.testing.assert_close(out["loss_discriminator"], expected)
        return
    loss = method.states["loss"]
    assert loss.self_loops_per_termination == k
    initial = TensorDict({"observation": torch.zeros(4, OBS)}, [4])
    with torch.no_grad():
        torch.manual_seed(1)
        expert_residual, _ = loss._residual(demos)
        replay_residual, _ = loss._residual(agent, k)
        initial_nu = loss.nu(initial["observation"], loss._policy_sample(initial["observation"])["action"])
        expected = valuedice_objective(expert_residual, replay_residual, initial_nu, loss.gamma,
                                       loss.replay_regularization)
    torch.manual_seed(1)
    out = loss(TensorDict({"expert": demos, "collector": agent, "initial": initial}, []))
    assert expert_residual.numel() == 40 + into[0] and replay_residual.numel() == 40 + k * into[1]
    torch.testing.assert_close(replay_residual[40:], replay_residual[40:40 + into[1]].repeat(k))
    torch.testing.assert_close(out["loss_nu"].detach(), expected)


def test_valuedice_placeholder_is_the_zero_standardised_state():
    """ValueDICE's code standardises the states, then appends its absorbing state (zeros and the indicator): with
    ``normalize_states`` the placeholder is the raw observation the standardisation maps to zero, on both buffers."""
    from torchrl_csirl.modules import StandardizeFeatures
    from torchrl_csirl.objectives._imitation import sample

    torch.manual_seed(0)
    norm = StandardizeFeatures(torch.tensor([2.0, -1.0, 5.0]), torch.tensor([0.5, 2.0, 4.0]))
    actor = make_actor(OBS, ACT, hidden=HIDDEN, input_features=copy.deepcopy(norm))
    method = make_imitation_method("valuedice", actor, lambda: make_qvalue(OBS, ACT, hidden=HIDDEN,
                                                                           input_features=copy.deepcopy(norm)),
                                   obs_dim=OBS, action_dim=ACT,
                                   hyperparameters={"batch_size": 16, "normalize_states": True,
                                                    "absorbing_observation": "placeholder"})
    online, expert = buffers(method, transitions(40, 0.0, 0.3, terminated_every=4), transitions(40, 1.0, 0.8, 10))
    for buffer in (online, expert):
        batch = sample(buffer, 40)
        ends = batch["next", "terminated"].squeeze(-1)
        assert ends.any() and batch["next", "absorbing"].squeeze(-1).eq(ends).all()
        torch.testing.assert_close(batch["next", "observation"][ends], norm.loc.expand(int(ends.sum()), OBS))
        torch.testing.assert_close(norm(batch["next", "observation"][ends]), torch.zeros(int(ends.sum()), OBS))
        torch.testing.assert_close(batch["next", "observation"][~ends], batch["observation"][~ends] + 0.1)
    unstandardised = build("valuedice", {"absorbing_observation": "placeholder"})
    assert unstandardised.online_transforms[0].absorbing_observation == 0.0


def test_valuedice_update_moves_each_network_by_its_own_objective():
    from torchrl_csirl.objectives._imitation import sample
    from torchrl_csirl.objectives.valuedice import initial_observations

    method = build("valuedice", {"batch_size": 16})
    online, expert = buffers(method, *expert_vs_random(40))
    loss = method.states["loss"]
    td = TensorDict({"expert": sample(expert, 16), "collector": sample(online, 16),
                     "initial": TensorDict({"observation": initial_observations(expert.storage[:])}, [1])}, [])
    out = loss(td)
    torch.testing.assert_close(out["loss_actor"], -out["loss_nu"])  # min over nu, max over pi
    assert not out["policy_scale"].requires_grad and float(out["policy_scale"]) > 0  # a metric, logged by the step
    nu_params = list(loss.nu_network.parameters())
    assert all(g is None for g in torch.autograd.grad(out["loss_gradient_penalty"], list(loss.actor_network.parameters()),
                                                      allow_unused=True, retain_graph=True))
    assert all(g is None for g in torch.autograd.grad(out["loss_orthogonal"], nu_params, allow_unused=True))
    step = method.make_update_step(online, expert)
    assert set(step(trainer(online))) == {"loss_nu", "loss_gradient_penalty", "loss_actor", "loss_orthogonal", "policy_scale"}
    batch = step.batch()  # default: every expert state is an initial state (the authors' code)
    assert step.initial_observations is None and torch.equal(batch["initial", "observation"], batch["expert", "observation"])
    starts = build("valuedice", {"batch_size": 16, "initial_states": "episode_starts"}).make_update_step(online, expert)
    assert len(starts.initial_observations) == 1  # one expert trajectory: one episode start
    with pytest.raises(ValueError, match="initial_states must be one of"):
        build("valuedice", {"initial_states": "first"})
    with pytest.raises(KeyError, match="initial states"):
        loss(td.exclude("initial").set("initial", TensorDict({}, [1])))


# ------------------------------------------------------------------------------ end to end
@pytest.mark.parametrize("name", IMITATION_METHODS)
def test_method_trains_in_the_csirl_trainer_on_a_mock_env(name):
    """Collector -> online buffer (with the method's transforms) -> update steps, and a checkpoint round trip."""
    from torchrl.collectors import Collector
    from torchrl.testing.mocking_classes import ContinuousActionVecMockEnv

    from torchrl_csirl.trainers import CSIRLTrainer

    torch.manual_seed(0)
    env = ContinuousActionVecMockEnv()
    obs_dim, act_dim = env.observation_spec["observation"].shape[-1], env.action_spec.shape[-1]
    expert_episode = env.rollout(20, lambda td: td.set("action", torch.full((act_dim,), 0.5)))
    demos = ExpertDemonstrations.from_episodes([expert_episode])
    method = make_imitation_method(name, make_actor(obs_dim, act_dim, hidden=(16, 16)),
                                   lambda: make_qvalue(obs_dim, act_dim, hidden=(16, 16)), obs_dim=obs_dim,
                                   action_dim=act_dim, hyperparameters={"batch_size": 8})
    online = TensorDictReplayBuffer(storage=LazyTensorStorage(1000), batch_size=8,
                                    transform=Compose(*method.online_transforms))
    expert = demos.as_replay_buffer(batch_size=8, transform=Compose(*method.expert_transforms))
    collector = Collector(env, method.policy, frames_per_batch=10, total_frames=-1, auto_register_policy_transforms=False)
    t = CSIRLTrainer(collector=collector, online_buffer=online, update_step=method.make_update_step(online, expert),
                     total_frames=40, utd_ratio=0.5, updates_per_round=5, progress_bar=False)
    for key, state in method.states.items():
        t.register_state(key, state)
    try:
        t.train()
    finally:
        collector.shutdown()
    assert t.updates == 20 and t.last_losses and all(map(math.isfinite, t.last_losses.values()))
    # the trainer's state restored into a fresh method and trainer: the same counters and tensors
    saved = copy.deepcopy(t.state_dict())
    fresh = make_imitation_method(name, make_actor(obs_dim, act_dim, hidden=(16, 16)),
                                  lambda: make_qvalue(obs_dim, act_dim, hidden=(16, 16)), obs_dim=obs_dim,
                                  action_dim=act_dim, hyperparameters={"batch_size": 8})
    restored = CSIRLTrainer(collector=collector, online_buffer=online, update_step=lambda trainer: {},
                            total_frames=40, utd_ratio=0.5, updates_per_round=5, progress_bar=False)
    for key, state in fresh.states.items():
        restored.register_state(key, state)
    restored.load_state_dict(saved)
    assert restored.updates == 20 and restored.frames == t.frames
    assert_same_state(restored.state_dict()["states"], saved["states"], name)


def test_baselines_page_example_runs():
    """docs/baselines.md's example runs as written (one DAC update on the shipped merge demonstrations)."""
    from markdown_examples import _run_python_blocks

    namespace = _run_python_blocks("docs/baselines.md")
    assert {"loss_discriminator", "loss_gradient_penalty", "loss_qvalue", "loss_actor"} <= set(namespace["losses"])


# ------------------------------------------------------------------------------ exploration
def test_mean_action_noise_explores_around_the_deterministic_action_within_bounds():
    """ValueDICE's code acts with the mean action plus N(0, 0.1) noise, clipped: through TorchRL's collector the
    actions sit around the deterministic ones with that spread; evaluation (deterministic) gets no noise."""
    from torchrl.collectors import Collector
    from torchrl.envs.utils import ExplorationType, set_exploration_type
    from torchrl.testing.mocking_classes import ContinuousActionVecMockEnv

    from torchrl_csirl.modules import MeanActionGaussianNoise

    torch.manual_seed(0)
    env = ContinuousActionVecMockEnv()
    obs_dim, act_dim = env.observation_spec["observation"].shape[-1], env.action_spec.shape[-1]
    actor = make_actor(obs_dim, act_dim, hidden=(16,))
    explorer = MeanActionGaussianNoise(actor, sigma=0.1)
    assert explorer.sigma == pytest.approx(0.1) and set(actor.parameters()) == set(explorer.parameters())
    collector = Collector(env, explorer, frames_per_batch=400, total_frames=400, auto_register_policy_transforms=False)
    batch = next(iter(collector))
    collector.shutdown()
    with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
        mean = actor(batch.select("observation").clone())["action"]
        torch.testing.assert_close(explorer(batch.select("observation").clone())["action"], mean)
    action = batch["action"]
    assert bool((action.abs() <= 1).all())
    inside = (mean.abs() < 0.7)  # away from the bounds the projection leaves the noise as drawn
    assert 0.08 < float((action - mean)[inside].std()) < 0.12
    with pytest.raises(ValueError, match="sigma must be > 0"):
        MeanActionGaussianNoise(actor, sigma=0.0)


def test_valuedice_exploration_noise_wraps_the_acting_policy_only():
    method = build("valuedice", {"exploration_noise": 0.1})
    from torchrl_csirl.modules import MeanActionGaussianNoise

    acting = method.behaviour(method.policy)
    assert isinstance(acting, MeanActionGaussianNoise) and acting.policy is method.policy
    assert build("valuedice").behaviour is None  # the harness's default: the policy samples
    with pytest.raises(ValueError, match="exploration_noise must be > 0 or None"):
        build("valuedice", {"exploration_noise": -0.1})
