"""A short tour of torchrl-csirl's components on a real driving scenario (about a minute).

It composes, with stock TorchRL machinery:

* a :class:`~torchrl_csirl.tasks.YieldingParallelEnv` of 2 workers stepping the ``merge`` scenario, driven by a
  :class:`~torchrl.collectors.Collector` with the current policy;
* a replay buffer whose transform recomputes the matching reward at sampling time
  (:class:`SubgoalMatchingReward`, for the current subgoal); the meta-loss adds ``r_w(s)`` itself,
  with its graph (a plain SAC step would instead sum both with :class:`IntrinsicReward` and
  :class:`CombineRewards`, as in the README);
* :class:`EnsembleSACLoss` (5 critics) and :class:`MetaRewardLoss` (meta-gradient of the reward net);
* :class:`SubgoalCurriculum` moving the subgoal from the critics' disagreement;
* an evaluation of the deterministic policy with the paper's accomplish rate.

The budget is far too small to learn to drive: this checks that the parts fit together and
shows how. The full training recipe is ``recipes/csirl_highway.py``.

Run::

    python recipes/demo_components.py --scenario merge --frames 1200

It ends with one JSON line (frames, updates, subgoal history, losses, accomplish rate).
"""
from __future__ import annotations

import argparse
import json
import time
from functools import partial

import torch
from tensordict.nn import TensorDictModule
from torchrl.collectors import Collector
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
from torchrl.envs import ExplorationType, ParallelEnv, set_exploration_type
from torchrl.objectives import SoftUpdate

from torchrl_csirl.curriculum import SubgoalCurriculum
from torchrl_csirl.data import load_expert_demonstrations
from torchrl_csirl.modules import make_actor, make_qvalue, make_reward_network
from torchrl_csirl.objectives import EnsembleSACLoss, MetaRewardLoss
from torchrl_csirl.tasks import SCENARIOS, YieldingParallelEnv, accomplish_rate_from_rollout, make_env
from torchrl_csirl.transforms import SubgoalMatchingReward

LOGGED_LOSSES = ("loss_qvalue", "loss_actor", "loss_meta", "loss_imitation")


def parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--scenario", default="merge", choices=sorted(SCENARIOS))
    parser.add_argument("--frames", type=int, default=1200, help="environment frames to collect")
    parser.add_argument("--frames-per-batch", type=int, default=200)
    parser.add_argument("--updates-per-batch", type=int, default=25)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    return parser.parse_args()


def make_parallel_env(scenario: str, workers: int, seed: int) -> ParallelEnv:
    """Stateless workers: the reward transforms stay in the main process (replay buffer)."""
    env = YieldingParallelEnv(workers, partial(make_env, scenario))
    env.set_seed(seed)
    return env


def evaluate(scenario: str, actor: TensorDictModule, seed: int) -> float:
    """Accomplish rate of one deterministic episode."""
    env = make_env(scenario, seed=seed)
    with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
        rollout = env.rollout(SCENARIOS[scenario].max_steps, actor)
    env.close()
    return float(accomplish_rate_from_rollout(rollout))


def main() -> None:
    args = parse_args()
    torch.manual_seed(args.seed)
    spec = SCENARIOS[args.scenario]
    demos = load_expert_demonstrations(args.scenario, num_trajectories=5)
    curriculum_obs = demos.trajectory_observations(0, include_final=True)

    actor = make_actor(spec.obs_dim, spec.action_dim)
    sac = EnsembleSACLoss(actor, make_qvalue(spec.obs_dim, spec.action_dim), num_qvalue_nets=5)
    target_updater = SoftUpdate(sac, tau=0.005)
    reward_network = make_reward_network(spec.obs_dim)
    meta = MetaRewardLoss(sac, reward_network, joint_sac_update=True)
    curriculum = SubgoalCurriculum(curriculum_obs, sac, actor, seed=args.seed)
    matching = SubgoalMatchingReward(
        curriculum_obs,
        subgoal=curriculum,  # the curriculum owns the subgoal; the reward reads it
        ego_feature_indices=spec.ego_feature_indices,
        position_feature_indices=spec.position_feature_indices,
        scale=spec.matching_scale,
    )

    online = TensorDictReplayBuffer(
        storage=LazyTensorStorage(100_000),
        batch_size=256,
        transform=matching,  # r_m(s, s'; g) for the subgoal current at sampling time
    )
    expert = demos.as_replay_buffer(batch_size=32)
    optim_sac = torch.optim.Adam(sac.parameters(), lr=3e-4)
    optim_reward = torch.optim.Adam(reward_network.parameters(), lr=1e-3)

    collector = Collector(
        partial(make_parallel_env, args.scenario, args.workers, args.seed),
        policy=actor,
        frames_per_batch=args.frames_per_batch,
        total_frames=args.frames,
        auto_register_policy_transforms=False,  # a feed-forward policy needs no primer
    )
    start, updates, subgoals, losses = time.perf_counter(), 0, [curriculum.subgoal], {}
    for batch in collector:
        online.extend(batch.reshape(-1))
        for _ in range(args.updates_per_batch):
            # one joint step: real SAC losses and the meta-gradient share the critic pass
            out = meta(online.sample(), expert.sample(), regularizer=online.sample())
            optim_sac.zero_grad()
            optim_reward.zero_grad()
            (out["loss_qvalue"] + out["loss_actor"] + out["loss_meta"]).backward()
            optim_sac.step()
            optim_reward.step()
            target_updater.step()
            updates += 1
        # round end: move the subgoal where the critics start to disagree
        selection = curriculum.step()  # the matching reward reads the new subgoal from the curriculum
        subgoals.append(selection.subgoal)
        losses = {key: float(out[key].detach()) for key in LOGGED_LOSSES}
    collector.shutdown()
    wall = time.perf_counter() - start
    result = {
        "scenario": args.scenario,
        "frames": args.frames,
        "updates": updates,
        "subgoals": subgoals,
        "curriculum_length": curriculum.length,
        **losses,
        "accomplish_rate": evaluate(args.scenario, actor, args.seed),
        "wall_s": round(wall, 1),
    }
    print(json.dumps(result))


if __name__ == "__main__":
    main()
