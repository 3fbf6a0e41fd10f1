"""CSIRLTrainer's loop and hook points, on TorchRL's mock env (fast)."""
from __future__ import annotations

import os

import pytest
import torch
from tensordict.nn import TensorDictModule
from torchrl.collectors import Collector
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
from torchrl.testing.mocking_classes import ContinuousActionVecMockEnv

from torchrl_csirl.trainers import CheckpointHook, CSIRLTrainer, load_checkpoint


def make_trainer(tmp_path=None, **kwargs) -> tuple[CSIRLTrainer, list]:
    env = ContinuousActionVecMockEnv()
    policy = TensorDictModule(torch.nn.LazyLinear(env.action_spec.shape[-1]), ["observation"], ["action"])
    policy(env.reset())
    collector = Collector(env, policy, frames_per_batch=10, total_frames=-1, auto_register_policy_transforms=False)
    buffer = TensorDictReplayBuffer(storage=LazyTensorStorage(1000), batch_size=4)
    calls = []

    def update(trainer):
        sample = trainer.online_buffer.sample()
        calls.append(("update", trainer.updates))
        return {"loss_fake": sample["observation"].sum() * 0 + trainer.updates}

    options = {"total_frames": 50, "utd_ratio": 0.3, "updates_per_round": 4, "progress_bar": False}
    options.update(kwargs)
    trainer = CSIRLTrainer(collector=collector, online_buffer=buffer, update_step=update, **options)
    return trainer, calls


def test_updates_follow_the_update_to_data_ratio_and_rounds_end_on_time():
    trainer, calls = make_trainer()
    ends, rows = [], []
    trainer.register_op("round_end", lambda t: ends.append((t.updates, t.frames)), "spy")
    trainer.register_op("log", lambda t, row: rows.append(row), "rows")
    trainer.train()
    trainer.collector.shutdown()
    assert trainer.frames == 50 and trainer.updates == 15  # 3 updates per 10-frame batch
    assert [u for _, u in calls] == list(range(15))
    assert ends == [(6, 20), (12, 40)]  # a round ends at the batch where it reaches 4 updates
    assert [r["loss_fake"] for r in rows] == [1.0, 4.0, 7.0, 10.0, 13.0]  # batch means


@pytest.mark.parametrize("progress_bar", [False, True])
def test_one_line_per_round_on_stderr(capsys, progress_bar):
    """A run whose output is a file (no bar) still shows its progress: one line per round, as it happens."""
    trainer, _ = make_trainer(progress_bar=progress_bar)
    seen = []
    trainer.register_op("round_end", lambda t: t.postfix.update(subgoal=f"{t.rounds + 3}/9"))
    trainer.register_op("post_round", lambda t: seen.append(capsys.readouterr().err))
    trainer.train()
    trainer.collector.shutdown()
    err = "".join(seen) + capsys.readouterr().err
    lines = [line for line in err.replace("\r", "\n").splitlines() if line.startswith("round ")]
    assert len(lines) == trainer.rounds == 2
    assert lines[0].startswith("round 1: 20/50 frames, 6 updates (") and lines[0].endswith("| subgoal 3/9")
    assert lines[1].startswith("round 2: 40/50 frames, 12 updates (") and lines[1].endswith("| subgoal 4/9")
    assert "round " not in seen[0]  # printed after the round's ops (its eval, its subgoal), not before

    quiet, _ = make_trainer(round_lines=False)
    quiet.train()
    quiet.collector.shutdown()
    assert "round " not in capsys.readouterr().err


def test_ops_run_in_stage_order_and_batch_process_transforms_the_batch():
    trainer, _ = make_trainer(total_frames=20, updates_per_round=1)
    order = []
    trainer.register_op("batch_process", lambda b: (order.append("batch_process"), b.exclude("reward"))[1])
    trainer.register_op("post_update", lambda t, losses: order.append("post_update"))
    trainer.register_op("round_end", lambda t: order.append("round_end"))
    trainer.register_op("post_round", lambda t: order.append("post_round"))
    trainer.register_op("log", lambda t, row: order.append("log"))
    trainer.register_op("train_end", lambda t: order.append("train_end"))
    trainer.train()
    trainer.collector.shutdown()
    assert order[:7] == ["batch_process", "post_update", "post_update", "post_update", "round_end", "post_round", "log"]
    assert order[-1] == "train_end"
    assert "reward" not in trainer.online_buffer[:]  # removed by the op before the buffer


def test_log_now_logs_the_counters_and_what_was_recorded_outside_a_batch():
    trainer, _ = make_trainer(total_frames=10, updates_per_round=1)
    rows = []
    trainer.register_op("log", lambda t, row: rows.append(dict(row)))
    trainer.record(eval_accomplish_rate=0.7)  # an evaluation before training (a warm-started actor's)
    assert trainer.log_now()["eval_accomplish_rate"] == 0.7
    trainer.train()
    trainer.collector.shutdown()
    assert rows[0] == {"frames": 0, "updates": 0, "round": 0, "eval_accomplish_rate": 0.7}
    assert rows[1]["frames"] == 10 and "eval_accomplish_rate" not in rows[1]  # the record went to one row only


def test_clear_buffer_each_round_keeps_only_the_current_round():
    trainer, _ = make_trainer(total_frames=40, utd_ratio=1.0, updates_per_round=15, clear_buffer_each_round=True)
    sizes = []
    trainer.register_op("log", lambda t, row: sizes.append(len(t.online_buffer)))
    trainer.train()
    trainer.collector.shutdown()
    assert sizes == [10, 20, 10, 20]  # rounds of two batches: emptied when a round starts


def test_bad_stage_and_duplicate_state_are_refused():
    trainer, _ = make_trainer()
    with pytest.raises(ValueError, match="Unknown stage 'pre_batch'"):
        trainer.register_op("pre_batch", print)
    trainer.register_state("module", torch.nn.Linear(2, 2))
    with pytest.raises(ValueError, match="already registered"):
        trainer.register_state("module", torch.nn.Linear(2, 2))
    with pytest.raises(TypeError, match="no state_dict"):
        trainer.register_state("number", 3)
    trainer.collector.shutdown()


def test_checkpoint_round_trip_restores_counters_states_and_rng(tmp_path):
    trainer, _ = make_trainer(total_frames=30)
    net = torch.nn.Linear(2, 2)
    trainer.register_state("net", net)
    trainer.train()
    hook = CheckpointHook(tmp_path, trainer.online_buffer)
    hook.save(trainer)
    expected_rng = torch.rand(3)
    trainer.collector.shutdown()

    other, _ = make_trainer(total_frames=30)
    other_net = torch.nn.Linear(2, 2)
    other.register_state("net", other_net)
    load_checkpoint(other, hook.path, other.online_buffer)
    other.collector.shutdown()
    assert (other.frames, other.updates, other.rounds) == (trainer.frames, trainer.updates, trainer.rounds)
    assert torch.equal(other_net.weight, net.weight)
    assert len(other.online_buffer) == len(trainer.online_buffer) == 30
    torch.testing.assert_close(torch.rand(3), expected_rng)
    with pytest.raises(FileNotFoundError, match="No checkpoint"):
        load_checkpoint(other, tmp_path / "nothing")


def test_throughput_covers_the_resumed_parts_of_a_run(tmp_path):
    """A run resumed from its checkpoint (even a finished one) reports rates over all its parts."""
    trainer, _ = make_trainer(total_frames=30)
    trainer.train()
    first = trainer.throughput
    hook = CheckpointHook(tmp_path, trainer.online_buffer)
    hook.save(trainer)
    trainer.collector.shutdown()
    assert first["updates_per_s"] > 0 and first["collect_fps"] > 0

    finished, _ = make_trainer(total_frames=30)
    load_checkpoint(finished, hook.path, finished.online_buffer)
    finished.train()  # nothing left to do: the rates are the first part's
    finished.collector.shutdown()
    assert finished.throughput["updates_per_s"] == pytest.approx(first["updates_per_s"])
    assert finished.throughput["collect_fps"] == pytest.approx(first["collect_fps"])

    resumed, _ = make_trainer(total_frames=60)
    load_checkpoint(resumed, hook.path, resumed.online_buffer)
    resumed.train()
    resumed.collector.shutdown()
    assert resumed.updates == 2 * trainer.updates
    assert resumed.throughput["updates_per_s"] == pytest.approx(resumed.updates / resumed._time_update)
    assert resumed._time_update > trainer._time_update  # both parts' seconds


def test_elapsed_time_of_a_resumed_run_includes_the_earlier_process(tmp_path):
    """``elapsed_s`` (a summary's ``total_wall_s``) is carried in the checkpoint, not restarted by a resume."""
    trainer, _ = make_trainer(total_frames=30)
    trainer.train()
    hook = CheckpointHook(tmp_path, trainer.online_buffer)
    hook.save(trainer)
    trainer.collector.shutdown()
    counters = torch.load(os.path.join(hook.path, "state.pt"), weights_only=False)["counters"]
    assert counters["elapsed_s"] >= counters["wall_s"] > 0

    resumed, _ = make_trainer(total_frames=60)
    load_checkpoint(resumed, hook.path, resumed.online_buffer)
    assert resumed.elapsed_before == counters["elapsed_s"]
    resumed.train()
    resumed.collector.shutdown()
    this_process = resumed.wall_time - counters["wall_s"]  # its own training loop
    assert this_process > 0
    assert resumed.elapsed_time >= counters["elapsed_s"] + this_process
    assert resumed.elapsed_time >= resumed.wall_time
    # a checkpoint from before elapsed_s was saved: its training-loop seconds stand in for it
    state = resumed.state_dict()
    del state["counters"]["elapsed_s"]
    again, _ = make_trainer(total_frames=60)
    again.load_state_dict(state)
    again.collector.shutdown()
    assert again.elapsed_before == state["counters"]["wall_s"]


def test_throughput_after_a_checkpoint_without_timing_counts_this_process_only(tmp_path):
    trainer, _ = make_trainer(total_frames=30)
    trainer.train()
    state = trainer.state_dict()
    trainer.collector.shutdown()
    for key in ("collect_s", "update_s"):
        del state["counters"][key]  # a checkpoint written before they were saved
    resumed, _ = make_trainer(total_frames=60)
    resumed.load_state_dict(state)
    resumed.train()
    resumed.collector.shutdown()
    assert resumed.throughput["updates_per_s"] == pytest.approx((resumed.updates - trainer.updates) / resumed._time_update)
    again, _ = make_trainer(total_frames=60)  # resumed once more: the untimed part stays out
    again.load_state_dict(resumed.state_dict())
    again.collector.shutdown()
    assert again.throughput["updates_per_s"] == pytest.approx(resumed.throughput["updates_per_s"])


def test_actor_behaviour_cloning_pulls_the_deterministic_action_to_the_expert_and_scales_with_the_actor_loss():
    from torchrl.envs.utils import ExplorationType, set_exploration_type
    from torchrl.objectives import BCLoss

    from torchrl_csirl.data import ExpertDemonstrations
    from torchrl_csirl.modules import make_actor
    from torchrl_csirl.objectives import ActorBehaviourCloning

    torch.manual_seed(0)
    obs = torch.randn(20, 4)
    episode = {"observation": obs, "action": torch.tanh(obs[:, :2]), "next_observation": obs.roll(1, 0),
               "terminated": torch.zeros(20, dtype=torch.bool)}
    expert = ExpertDemonstrations.from_episodes([episode])
    actor = make_actor(4, 2, hidden=(32,))
    term = ActorBehaviourCloning(BCLoss(actor, loss_function="l2"), expert.as_replay_buffer(batch_size=20), coef=0.5)
    optim = torch.optim.Adam(actor.parameters(), lr=1e-2)
    mses = []
    for _ in range(100):
        losses, logs = term(torch.tensor(-2.0))  # |L_actor| = 2: weight 0.5 * 2 = 1
        torch.testing.assert_close(losses["loss_actor_bc"], logs["actor_bc_mse"] * 1.0, atol=1e-6, rtol=1e-6)
        optim.zero_grad()
        losses["loss_actor_bc"].backward()
        optim.step()
        mses.append(logs["actor_bc_mse"].item())
    assert mses[-1] < 0.1 * mses[0]
    with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
        action = actor(expert.transitions().select("observation"))["action"]
    assert (action - episode["action"]).pow(2).mean() == pytest.approx(mses[-1], rel=0.5, abs=1e-3)
    # the weight follows |L_actor| (detached) and nothing flows into it
    loss_actor = torch.tensor(-40.0, requires_grad=True)
    losses, logs = term(loss_actor)
    torch.testing.assert_close(losses["loss_actor_bc"], 20.0 * logs["actor_bc_mse"], rtol=1e-5, atol=1e-6)
    losses["loss_actor_bc"].backward()
    assert loss_actor.grad is None
    with pytest.raises(ValueError, match="coef must be positive"):
        ActorBehaviourCloning(term.bc_loss, expert.as_replay_buffer(batch_size=4), coef=0.0)


def test_actor_cloning_scaled_by_the_critics_is_td3_bcs_mean_absolute_q_where_the_actor_loss_cancels():
    """``csirl.actor_bc_scale=qvalue``: the weight is ``coef * mean |min_k Q_k(s, mu(s))|`` over the training batch,
    whatever the actor loss; ``|L_actor|`` (the default) vanishes where values of either sign cancel."""
    from tensordict import TensorDict
    from torchrl.envs.utils import ExplorationType, set_exploration_type
    from torchrl.objectives import BCLoss

    from torchrl_csirl.data import ExpertDemonstrations
    from torchrl_csirl.modules import make_actor, make_qvalue
    from torchrl_csirl.objectives import ActorBehaviourCloning, EnsembleSACLoss

    torch.manual_seed(0)
    obs = torch.randn(20, 4)
    episode = {"observation": obs, "action": torch.tanh(obs[:, :2]), "next_observation": obs.roll(1, 0),
               "terminated": torch.zeros(20, dtype=torch.bool)}
    expert = ExpertDemonstrations.from_episodes([episode]).as_replay_buffer(batch_size=20)
    actor = make_actor(4, 2, hidden=(32,))
    sac = EnsembleSACLoss(actor, make_qvalue(4, 2, hidden=(32,)), num_qvalue_nets=3)
    term = ActorBehaviourCloning(BCLoss(actor, loss_function="l2"), expert, coef=0.5, critic=sac)
    batch = TensorDict({"observation": torch.randn(64, 4)}, [64])
    losses, logs = term(torch.tensor(0.0), batch)  # an actor loss that cancels to 0: the anchor holds
    with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
        acted = actor(batch.clone())
        expected = 0.5 * sac.qvalues(acted).min(0).values.abs().mean()
    assert expected > 0
    torch.testing.assert_close(logs["actor_bc_weight"], expected)
    torch.testing.assert_close(losses["loss_actor_bc"], expected * logs["actor_bc_mse"])
    assert set(batch.keys()) == {"observation"}  # the batch is not written to
    losses["loss_actor_bc"].backward()  # the gradient reaches the actor only, through the cloning error
    assert all(p.grad is not None for p in actor.parameters())
    assert all(p.grad is None for p in sac.qvalue_network_params.values(True, True))
    default = ActorBehaviourCloning(term.bc_loss, expert, coef=0.5)
    assert default(torch.tensor(0.0))[1]["actor_bc_weight"] == 0.0
    with pytest.raises(ValueError, match="pass batch="):
        term(torch.tensor(-1.0))



def test_a_stop_request_ends_at_the_batch_boundary_and_its_checkpoint_resumes_exactly(tmp_path):
    from torchrl_csirl.trainers import TrainingInterrupted

    def build(stop_at=None):
        trainer, _ = make_trainer(total_frames=60, updates_per_round=100)  # one round, never ended
        rows = []
        trainer.register_op("log", lambda t, row: rows.append(
            {k: v for k, v in row.items() if k not in ("collect_fps", "updates_per_s")}), "rows")
        if stop_at is not None:  # as a signal handler would, in the middle of a batch
            trainer.register_op("batch_process", lambda b: (trainer.frames == stop_at and trainer.request_stop("SIGTERM"), b)[1])
        return trainer, rows

    full, full_rows = build()
    full.train()
    full.collector.shutdown()

    stopped, _ = build(stop_at=20)
    with pytest.raises(TrainingInterrupted, match="SIGTERM") as raised:
        stopped.train()
    stopped.collector.shutdown()
    assert raised.value.reason == "SIGTERM"
    # the batch in progress was finished: collected, its updates done and logged
    assert (stopped.frames, stopped.updates, stopped.rounds, stopped.updates_in_round) == (30, 9, 0, 9)
    checkpoint = CheckpointHook(tmp_path, stopped.online_buffer).save(stopped)

    resumed, resumed_rows = build()
    load_checkpoint(resumed, checkpoint, resumed.online_buffer)
    resumed.train()
    resumed.collector.shutdown()
    assert (resumed.frames, resumed.updates, resumed.rounds) == (full.frames, full.updates, full.rounds) == (60, 18, 0)
    assert resumed_rows == [row for row in full_rows if row["frames"] > 30]
    # the mock env's observations are not seeded: the buffer holds the stopped run's 30 rows, then 30 new ones
    assert len(resumed.online_buffer) == 60
    assert torch.equal(resumed.online_buffer[:30]["observation"], stopped.online_buffer[:]["observation"])
