"""How much of the reward network's meta-gradient comes from imitation, how much from the L1 term.

``python docs/studies/scripts/meta_gradient_balance.py [key=value ...]`` (the recipe's configuration keys, e.g.
``env.task=roundabout csirl.reward_l1_coef=1e-5``; ``checkpoint.resume=<run dir>`` loads a
trained run's configuration and its actor, critics and reward network instead of fresh ones).

CSIRL's meta-objective is ``scale * (BC(theta') + reward_l1_coef * mean |r_w|)``. The imitation
part reaches ``w`` only through two inner SGD steps of size ``lr_inner`` (``w -> phi' -> theta'``),
so its gradient is of order ``lr_inner**2``, while the regulariser's is of order one. This script
rolls the actor out in the scenario, applies the recipe's matching reward, and averages over
``--steps`` meta-losses the norm of each part (``MetaRewardLoss``'s ``meta_grad_norm_imitation``
and ``meta_grad_norm_l1``). Adam normalises the summed gradient, so when the ratio
``l1 / imitation`` is large the reward network follows the regulariser alone and ``r_w -> 0``.
It also reports whether ``r_w`` tells the expert's states from the policy's
(:func:`reward_separation`: mean ``r_w`` on each, and the rank AUC over all pairs).

The last line printed is a JSON object.
"""
from __future__ import annotations

import argparse
import json
import os

import torch
from tensordict import TensorDict

from torchrl_csirl.methods.csirl import CSIRL_RECIPE, make_loss_modules, make_matching
from torchrl_csirl.objectives import MetaRewardLoss
from torchrl_csirl.run.experts import load_experts
from torchrl_csirl.run.run import resolve_resume
from torchrl_csirl.tasks import SCENARIOS, make_env


def load_trained(modules, checkpoint: str) -> None:
    """Actor, critics and reward network of a run's checkpoint directory."""
    state = torch.load(os.path.join(checkpoint, "state.pt"), weights_only=False)
    modules.sac.load_state_dict(state["states"]["loss"])
    modules.reward_network.load_state_dict(state["states"]["reward_network"])


def reward_separation(reward_network, expert_obs: torch.Tensor, policy_obs: torch.Tensor) -> dict[str, float]:
    """Mean ``r_w`` on expert and on policy states, its spread, and how well it ranks the expert's above the policy's.

    ``r_w_std`` is the standard deviation of ``r_w`` over both sets of states (0 for a constant,
    e.g. dead, reward network). ``r_w_auc`` is the probability that a random expert state gets a
    higher ``r_w`` than a random policy state (ties count a half): 0.5 for a reward that does not
    tell them apart, 1.0 for one that rates every expert state above every policy state.

    Examples:
        >>> from tensordict.nn import TensorDictModule
        >>> net = TensorDictModule(lambda o: o[..., :1], in_keys=["observation"], out_keys=["intrinsic_reward"])
        >>> reward_separation(net, torch.ones(3, 2), torch.zeros(4, 2))["r_w_auc"]
        1.0
    """
    obs_key, reward_key = reward_network.in_keys[0], reward_network.out_keys[0]
    with torch.no_grad():
        r_e, r_p = (reward_network(TensorDict({obs_key: obs}, [len(obs)]))[reward_key].reshape(-1)
                    for obs in (expert_obs, policy_obs))
    diff = r_e[:, None] - r_p[None, :]
    auc = float((diff > 0).float().mean() + 0.5 * (diff == 0).float().mean())
    return {"r_w_expert_mean": float(r_e.mean()), "r_w_policy_mean": float(r_p.mean()),
            "r_w_std": float(torch.cat([r_e, r_p]).std()), "r_w_auc": auc}


def main(argv: list[str] | None = None) -> dict[str, float]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--frames", type=int, default=600, help="frames rolled out with the actor")
    parser.add_argument("--steps", type=int, default=10, help="meta-losses averaged")
    args, overrides = parser.parse_known_args(argv)
    # a trained run: its own configuration (networks, scenario), updated by the command line
    cfg = CSIRL_RECIPE.requested_config(overrides)
    torch.manual_seed(cfg.seed)
    spec = SCENARIOS[cfg.env.task]
    demos = load_experts(cfg.expert, spec)
    modules = make_loss_modules(cfg, spec, demos=demos)
    if cfg.checkpoint.resume is not None:
        load_trained(modules, resolve_resume(cfg.checkpoint.resume)[1])
    curriculum_obs = demos.trajectory_observations(0, include_final=True)
    matching = make_matching(cfg, spec, curriculum_obs, subgoal=min(5, len(curriculum_obs) - 1))
    env = make_env(spec.name, seed=cfg.seed)
    online = matching(env.rollout(args.frames, modules.actor, break_when_any_done=False).reshape(-1))
    env.close()
    expert = demos.as_replay_buffer(batch_size=cfg.expert.batch_size)
    meta = MetaRewardLoss(modules.sac, modules.reward_network, lr_inner=cfg.csirl.lr_inner,
                          scale=cfg.csirl.meta_scale, reward_l1_coef=cfg.csirl.reward_l1_coef)
    keys = ("meta_grad_norm_imitation", "meta_grad_norm_l1", "intrinsic_reward_mean", "loss_imitation")
    sums = dict.fromkeys(keys, 0.0)
    batch = cfg.replay_buffer.batch_size
    for _ in range(args.steps):
        out = meta(online[torch.randint(len(online), (batch,))], expert.sample(),
                   regularizer=online[torch.randint(len(online), (batch,))])
        for key in keys:
            sums[key] += float(out[key]) / args.steps
    summary = {
        "scenario": spec.name,
        "checkpoint": cfg.checkpoint.resume,
        "reward_l1_coef": cfg.csirl.reward_l1_coef,
        "lr_inner": cfg.csirl.lr_inner,
        **{k: float(f"{v:.4g}") for k, v in sums.items()},
        "l1_to_imitation_ratio": float(f"{sums['meta_grad_norm_l1'] / max(sums['meta_grad_norm_imitation'], 1e-30):.4g}"),
        "matching_reward_mean": float(f"{float(online['next', 'matching_reward'].mean()):.4g}"),
        **{k: float(f"{v:.4g}") for k, v in reward_separation(
            modules.reward_network, demos.transitions()["observation"], online["observation"]).items()},
    }
    print(json.dumps(summary))
    return summary


if __name__ == "__main__":
    main()
