"""CSIRL on the ``merge`` scene from a stock TorchRL training loop (no trainer of this project).

Everything the loop touches is TorchRL's: a :class:`~torchrl.collectors.Collector`, a
:class:`~torchrl.data.TensorDictPrioritizedReplayBuffer` that prefetches its batches, an actor and
critics built from TorchRL's :class:`~torchrl.modules.MLP` (a :class:`~torchrl.modules.ProbabilisticActor`
with a :class:`~torchrl.modules.TanhNormal`), :class:`~torchrl.objectives.SoftUpdate` and the
:class:`~torchrl.record.loggers.csv.CSVLogger`. CSIRL adds its components:

* :class:`~torchrl_csirl.objectives.EnsembleSACLoss`: five independently initialised copies of the critic;
* the reward transforms, applied to each sampled batch: :class:`~torchrl_csirl.transforms.SubgoalMatchingReward` (toward the
  current subgoal), :class:`~torchrl_csirl.transforms.IntrinsicReward` (``r_w``) and
  :class:`~torchrl_csirl.transforms.CombineRewards`, recomputed at every sampling;
* :class:`~torchrl_csirl.objectives.MetaRewardLoss` called as ``loss(td)`` every other update (the
  recipe's ``csirl.meta_every=2``): SAC losses and the meta-gradient of ``r_w`` from one backward;
* :class:`~torchrl_csirl.curriculum.SubgoalCurriculum` stepped every 2 000 updates (a round);
* :func:`~torchrl_csirl.trainers.evaluate_policy` on a batched environment.

Without ``--extras`` the settings are the paper's (the recipe's ``preset=paper`` choices for these
four): the learner trains on its own transitions, reads the raw observation, keeps the temperature
fixed and the matching reward searches the whole ego row. ``--extras`` turns on the recipe's four
additions, each a few lines marked ``EXTRA`` below (docs/torchrl-loop.md: what each one does).

Run::

    python examples/csirl_torchrl_loop.py --frames 60000 --seed 0 --extras --out runs/torchrl-loop

It ends with one JSON line, also written as ``summary.json`` in its log folder: the test accomplish rate over 50
unseen episodes (raw and over the demonstrations', as the recipe's tables report it) and the run's figures.
"""
from __future__ import annotations

import argparse
import json
import os
import time
from functools import partial

import torch
from tensordict import TensorDictBase
from tensordict.nn import NormalParamExtractor, TensorDictModule
from torch import nn
from torchrl.collectors import Collector
from torchrl.data import Bounded, LazyTensorStorage, TensorDictPrioritizedReplayBuffer
from torchrl.envs import Compose
from torchrl.modules import MLP, ProbabilisticActor, TanhNormal, ValueOperator
from torchrl.objectives import SoftUpdate
from torchrl.record.loggers.csv import CSVLogger

from torchrl_csirl.curriculum import SubgoalCurriculum
from torchrl_csirl.data import load_expert_demonstrations
from torchrl_csirl.modules import make_input_features, make_reward_network
from torchrl_csirl.objectives import EnsembleSACLoss, MetaRewardLoss
from torchrl_csirl.run.run import expert_accomplish_rate
from torchrl_csirl.tasks import SCENARIOS, make_serial_env, normalized_accomplish_rate
from torchrl_csirl.trainers import evaluate_policy
from torchrl_csirl.transforms import CombineRewards, IntrinsicReward, SubgoalMatchingReward

SCENE = "merge"
HIDDEN = [256, 256]
LOGGED = ("loss_qvalue", "loss_actor", "loss_alpha", "alpha", "loss_meta", "loss_imitation", "intrinsic_reward_mean")


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--frames", type=int, default=60_000, help="environment frames to collect")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--extras", action="store_true",
                        help="the recipe's additions: expert transitions in the batch, ego-relative inputs, "
                             "learned temperature, matching on the position")
    parser.add_argument("--out", default="runs/torchrl-loop", help="where the CSV logs go")
    parser.add_argument("--frames-per-batch", type=int, default=500)
    parser.add_argument("--init-random-frames", type=int, default=1000, help="uniform random actions first")
    parser.add_argument("--updates-per-round", type=int, default=2000, help="updates between two subgoal selections")
    parser.add_argument("--eval-episodes", type=int, default=10, help="validation episodes per round")
    parser.add_argument("--test-episodes", type=int, default=50, help="episodes of the final test")
    return parser.parse_args(argv)


class ReadFeatures(nn.Module):
    """``mlp(features(observation), *others)``: a TorchRL MLP reading the observation through a fixed input map."""

    def __init__(self, features: nn.Module | None, mlp: nn.Module) -> None:
        super().__init__()
        self.features = features if features is not None else nn.Identity()
        self.mlp = mlp

    def forward(self, observation: torch.Tensor, *others: torch.Tensor) -> torch.Tensor:
        return self.mlp(self.features(observation), *others)


def make_actor(obs_features: int, action_dim: int, features: nn.Module | None) -> ProbabilisticActor:
    """TorchRL's SAC actor: an MLP writing ``loc``/``scale``, a TanhNormal on ``[-1, 1]``."""
    mlp = MLP(in_features=obs_features, out_features=2 * action_dim, num_cells=HIDDEN, activation_class=nn.ReLU)
    net = nn.Sequential(ReadFeatures(features, mlp), NormalParamExtractor())
    return ProbabilisticActor(
        TensorDictModule(net, in_keys=["observation"], out_keys=["loc", "scale"]),
        in_keys=["loc", "scale"], spec=Bounded(-1.0, 1.0, shape=(action_dim,)), distribution_class=TanhNormal,
        distribution_kwargs={"low": -1.0, "high": 1.0}, return_log_prob=True,
    )


def make_critic(obs_features: int, action_dim: int, features: nn.Module | None) -> ValueOperator:
    """One Q(s, a): a TorchRL MLP on ``[s, a]``; EnsembleSACLoss makes the other four."""
    mlp = MLP(in_features=obs_features + action_dim, out_features=1, num_cells=HIDDEN, activation_class=nn.ReLU)
    return ValueOperator(ReadFeatures(features, mlp), in_keys=["observation", "action"])


def main(argv: list[str] | None = None) -> dict[str, object]:
    args = parse_args(argv)
    torch.manual_seed(args.seed)
    spec = SCENARIOS[SCENE]
    demos = load_expert_demonstrations(SCENE, num_trajectories=25)
    curriculum_obs = demos.trajectory_observations(0, include_final=True)

    # --- networks and losses ---------------------------------------------------------------------------
    features = make_input_features(spec) if args.extras else None  # EXTRA 2: ego-relative inputs
    obs_features = features.out_features if features is not None else spec.obs_dim
    actor = make_actor(obs_features, spec.action_dim, features)
    sac = EnsembleSACLoss(
        actor, make_critic(obs_features, spec.action_dim, features), num_qvalue_nets=5,
        fixed_alpha=not args.extras,  # EXTRA 3: learned temperature (the paper fixes alpha = 0.01)
        fused=False, fused_qvalue=False,  # TorchRL's networks: SACLoss's own path, critics by torch.vmap
    )
    target_update = SoftUpdate(sac, tau=0.005)
    reward_net = make_reward_network(spec.obs_dim, input_features=features)
    meta = MetaRewardLoss(sac, reward_net, joint_sac_update=True)
    optim_sac = torch.optim.Adam(sac.parameters(), lr=3e-4)  # actor, critics (and log_alpha when learned)
    optim_reward = torch.optim.Adam(reward_net.parameters(), lr=1e-3)

    # --- curriculum and rewards ------------------------------------------------------------------------
    curriculum = SubgoalCurriculum(curriculum_obs, sac, actor, seed=args.seed)
    matching = SubgoalMatchingReward(
        curriculum_obs, subgoal=curriculum, scale=spec.matching_scale,
        # EXTRA 4: the nearest expert state by position (the paper: the whole ego row)
        ego_feature_indices=spec.position_feature_indices if args.extras else spec.ego_feature_indices,
        position_feature_indices=spec.position_feature_indices,
    )
    batch_size, expert_share = 256, (64 if args.extras else 0)  # EXTRA 1: a quarter of every batch is expert
    online_rb = TensorDictPrioritizedReplayBuffer(
        alpha=0.6, beta=0.4, storage=LazyTensorStorage(1_000_000), batch_size=batch_size - expert_share,
        prefetch=3,  # batches sampled ahead in background threads: the rewards cannot be computed there
    )
    # r_m (current subgoal) + r_w (current network), on each batch when it is used, not when it was prefetched
    rewards = Compose(matching, IntrinsicReward(reward_net), CombineRewards(["matching_reward", "intrinsic_reward"]))
    expert_rb = demos.as_replay_buffer(batch_size=32)  # the meta-loss's behavioural-cloning pairs
    expert_mix = demos.as_replay_buffer(batch_size=expert_share) if args.extras else None  # EXTRA 1

    def learner_batch(online: TensorDictBase) -> TensorDictBase:
        """The online batch, and with --extras expert transitions rewarded by the same transforms (appended)."""
        if expert_mix is None:
            return online
        expert = rewards(expert_mix.sample())  # EXTRA 1: rewarded as the online transitions
        keys = [key for key in expert.keys(True, True) if key in online.keys(True, True)]
        return torch.cat([online.select(*keys), expert.select(*keys)], 0)

    # --- collection, evaluation, logging ---------------------------------------------------------------
    collector = Collector(
        partial(make_serial_env, SCENE, 2, seed=args.seed), policy=actor,
        frames_per_batch=args.frames_per_batch, total_frames=args.frames,
        init_random_frames=args.init_random_frames,
        auto_register_policy_transforms=False,  # a feed-forward policy needs no InitTracker
    )
    eval_env = make_serial_env(SCENE, 2)  # episodes two at a time, each copy's first episode kept
    evaluate = partial(evaluate_policy, eval_env, actor, max_steps=spec.max_steps)
    logger = CSVLogger(exp_name=f"{SCENE}-{'extras' if args.extras else 'paper'}-s{args.seed}", log_dir=args.out)

    start, frames, updates, out, meta_out = time.perf_counter(), 0, 0, {}, {}
    for batch in collector:
        online_rb.extend(batch.reshape(-1))
        frames += batch.numel()
        if frames < args.init_random_frames:
            continue
        for _ in range(batch.numel() // 2):  # 0.5 updates per frame
            online = rewards(online_rb.sample())
            sac_batch = learner_batch(online)
            if updates % 2 == 0:  # every other update: SAC losses and the meta-gradient of r_w, one backward
                td = meta.meta_batch(sac_batch, expert_rb.sample(), online_rb.sample())
                out = meta_out = meta(td)  # online batch at the root, expert pairs at "expert", |r_w| on "regularizer"
                loss = out["loss_qvalue"] + out["loss_actor"] + out["loss_alpha"] + out["loss_meta"]
            else:  # a plain SAC step on ("next", "reward") = r_m + r_w, written by the reward transforms
                td = sac_batch
                out = sac(td)
                loss = out["loss_qvalue"] + out["loss_actor"] + out["loss_alpha"]
            optim_sac.zero_grad()
            optim_reward.zero_grad()
            loss.backward()
            optim_sac.step()
            optim_reward.step()
            target_update.step()
            online.set("td_error", td.get("td_error")[: online.numel()])  # the online rows' TD errors
            online_rb.update_tensordict_priority(online)
            updates += 1
            if updates % args.updates_per_round == 0:  # round end: the subgoal moves where the critics disagree
                selection = curriculum.step()
                metrics = evaluate(episodes=args.eval_episodes, seed=2_000_000)
                row = {"subgoal": selection.subgoal, "eval_accomplish_rate": metrics["accomplish_rate"],
                       **{key: float(o[key].detach()) for o in (meta_out, out) for key in LOGGED if key in o.keys()}}
                for key, value in row.items():
                    logger.log_scalar(key, value, step=frames)
                print(f"frames {frames} updates {updates} subgoal {selection.subgoal}/{curriculum.length - 1} "
                      f"accomplish {metrics['accomplish_rate']:.3f}", flush=True)
    collector.shutdown()
    test = evaluate(episodes=args.test_episodes, seed=1_000_000)  # unseen episodes, the paper's metric
    eval_env.close()
    result = {
        "scene": SCENE, "extras": args.extras, "seed": args.seed, "frames": frames, "updates": updates,
        "final_subgoal": curriculum.subgoal, "curriculum_length": curriculum.length,
        "accomplish_rate": round(test["accomplish_rate"], 4), "accomplish_rate_std": round(test["accomplish_rate_std"], 4),
        "success_rate": test["success_rate"], "crash_rate": test["crash_rate"],
        "episode_length": test["episode_length"], "wall_s": round(time.perf_counter() - start, 1),
        "log_dir": os.path.join(args.out, logger.exp_name),
    }
    result = run_summary(result, demos.metadata)
    with open(os.path.join(result["log_dir"], "summary.json"), "w") as f:
        json.dump(result, f, indent=1)
    print(json.dumps(result), flush=True)
    return result


def run_summary(result: dict[str, object], expert_metadata: dict) -> dict[str, object]:
    """The example's result with the fields of a recipe run's ``summary.json`` that the tables compare
    (``scenario``, ``method``, ``normalized_accomplish_rate``: the test accomplish rate over the demonstrations'),
    so that ``torchrl-csirl compare`` sets it beside the recipe's runs."""
    expert = expert_accomplish_rate(expert_metadata)
    normalized = round(float(normalized_accomplish_rate(result["accomplish_rate"], expert)), 4) if expert else None
    return {"scenario": SCENE, "method": "csirl-torchrl-loop" + ("-extras" if result["extras"] else ""), **result,
            "normalized_accomplish_rate": normalized}


if __name__ == "__main__":
    main()
