"""Where does a locomotion policy go? The torso's x over deterministic test episodes, the return, and whether it flipped.

``python docs/studies/scripts/locomotion_probe.py <run dir> [--episodes 1] [--seed S] [--stochastic] [--critic [--plot PNG]]``

Reads a run on ``hopper`` or ``halfcheetah``: its ``policy.pt`` (a finished run) or, before the end, the actor of
its last checkpoint. For each episode (seeds ``S, S + 1, ...``; default the run's ``eval.seed``, its test
episodes) it prints the torso's x every 100 steps, the return, the length and the torso angle's range (beyond
pi / 2 the body is on its back). The actions are the policy's mean (the test's), or with ``--stochastic``
its samples (the behaviour that collected the training data). With ``--critic`` it also reads the critics
of the run's last checkpoint (any SAC-based method: CSIRL's ensemble, SAC, the imitation baselines) and
prints what they believe: ``Q(s, a)`` along the expert's demonstration, beside the discounted return to go
of the reward they learn from where it is known (CSIRL's matching reward, SAC's task reward), along the
policy's own episode, and over random actions at the policy's last state; ``--plot PNG`` draws the first two
against the step (the critics' mean and their spread).
The last line is JSON. It tells a policy that runs from one that moves a few
metres and stops (docs/benchmark.md, MuJoCo locomotion).
"""
from __future__ import annotations

import argparse
import json
import math
import os

import torch
from omegaconf import OmegaConf

from torchrl_csirl.analysis.diagnostics import discounted_returns
from torchrl_csirl.data.shipped import load_expert_demonstrations
from torchrl_csirl.methods.csirl import make_matching
from torchrl_csirl.modules import make_input_features, make_qvalue
from torchrl_csirl.run.builders import load_experts
from torchrl_csirl.scripts._policy_rollouts import policy_episodes
from torchrl_csirl.tasks import resolve_scenario

CRITIC_PREFIX = "qvalue_network_params.module."
#: the expert states at which the critic probe reports Q
EXPERT_STEPS = (0, 250, 500, 750)


def load_critics(run_dir: str, task: str) -> list[torch.nn.Module]:
    """The critics of the run's last checkpoint (``checkpoints/last/state.pt``), one module per critic."""
    path = os.path.join(run_dir, "checkpoints", "last", "state.pt")
    if not os.path.isfile(path):
        raise SystemExit(f"error: {run_dir}: no checkpoints/last/state.pt, whose critics --critic reads")
    state = torch.load(path, weights_only=False, map_location="cpu")["states"].get("loss", {})
    stacked = {k[len(CRITIC_PREFIX):]: v for k, v in state.items() if k.startswith(CRITIC_PREFIX)}
    if not stacked:
        raise SystemExit(f"error: {path}: no critic ({CRITIC_PREFIX}*) in its loss state; --critic reads SAC-based runs")
    spec = resolve_scenario(task)
    critics = []
    for k in range(next(iter(stacked.values())).shape[0]):
        critic = make_qvalue(spec.obs_dim, spec.action_dim, input_features=make_input_features(spec, ego_relative=False))
        critic.module.load_state_dict({name: value[k] for name, value in stacked.items()})
        critics.append(critic.module)
    return critics


def ensemble_q(critics: list[torch.nn.Module], observation: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
    """``Q_k(s, a)`` of every critic, ``[K, B]``."""
    return torch.stack([critic(observation, action).squeeze(-1) for critic in critics])


def random_actions(n: int, action_dim: int, seed: int = 0) -> torch.Tensor:
    """``n`` actions uniform in ``[-1, 1]``, the same on every call (a probe's figures are reproducible)."""
    return torch.rand(n, action_dim, generator=torch.Generator().manual_seed(seed)) * 2 - 1


def run_method(cfg) -> str:
    """The run's method: its ``method`` key (the imitation baselines, SAC), ``csirl`` for a CSIRL recipe's run,
    ``sac`` for an expert's training run (``recipes/train_expert.py``)."""
    return str(cfg.get("method") or ("csirl" if "csirl" in cfg else "sac"))


def run_demonstrations(cfg):
    """The run's first demonstration: its ``expert`` settings, or the task's shipped one (an expert's run)."""
    if "expert" not in cfg:
        return load_expert_demonstrations(cfg.env.task, 1).trajectory(0)
    return load_experts(cfg.expert, resolve_scenario(cfg.env.task)).trajectory(0)


def trained_reward(cfg, expert) -> tuple[str, torch.Tensor] | None:
    """The reward the run's critics learn from, along a demonstration: CSIRL's matching reward (toward the
    curriculum's last state; ``r_w`` left out), SAC's task reward; None for a learned one (the baselines)."""
    if run_method(cfg) == "csirl":  # CSIRL or CSIRL-B
        spec = resolve_scenario(cfg.env.task)
        matching = make_matching(cfg, spec, expert["observation"], len(expert) - 1)
        return "matching", matching(expert.clone())["next", "matching_reward"].reshape(-1)
    if run_method(cfg) == "sac":
        return "task", expert["next", "reward"].reshape(-1).float()
    return None


def plot_critic(path: str, title: str, q_expert: torch.Tensor, q_policy: torch.Tensor,
                known: tuple[str, torch.Tensor] | None) -> str:
    """Two panels: ``Q`` along the expert's demonstration (mean and range over the critics, the return to go
    of the known reward beside it), and along the policy's episode; written as PNG."""
    from torchrl_csirl.analysis.visualization._figure import new_figure, save_png

    fig = new_figure(1000, 360)
    fig.suptitle(title, fontsize=10)
    for i, (q, where) in enumerate(((q_expert, "the expert's demonstration"), (q_policy, "the policy's test episode"))):
        ax = fig.add_subplot(1, 2, i + 1)
        steps = torch.arange(q.shape[-1])
        ax.fill_between(steps, q.min(0).values, q.max(0).values, alpha=0.3, label="Q, range over the critics")
        ax.plot(steps, q.mean(0), label="Q(s, a), mean of the critics")
        if i == 0 and known is not None:
            ax.plot(steps, known[1], "k--", label=f"discounted return to go of the {known[0]} reward")
        ax.set_xlabel(f"step of {where}")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.subplots_adjust(left=0.07, right=0.98, bottom=0.14, top=0.88, wspace=0.2)
    return str(save_png(fig, path))


def critic_probe(run_dir: str, cfg, rollout, plot: str | None = None) -> dict:
    """What the critics believe along the expert's first demonstration (against the discounted return to go of
    the reward they learn from, where it is known) and along the policy's episode; ``plot``: draw it there."""
    critics = load_critics(run_dir, cfg.env.task)
    gamma = float((cfg.get(run_method(cfg)) or {}).get("gamma", 0.99))  # the method's own section
    expert = run_demonstrations(cfg)
    with torch.no_grad():
        q_experts = ensemble_q(critics, expert["observation"].float(), expert["action"].float())
        q_policies = ensemble_q(critics, rollout["observation"], rollout["action"])
        q_expert, q_policy = q_experts.mean(0), q_policies.mean(0)
        last = rollout["observation"][-1:].expand(256, -1)
        q_random = ensemble_q(critics, last, random_actions(256, rollout["action"].shape[-1])).mean(0)
    steps = [t for t in EXPERT_STEPS if t < len(q_expert)]
    report = {"critics": len(critics), "gamma": gamma,
              "q_expert": {str(t): round(float(q_expert[t]), 2) for t in steps},
              "q_policy": {str(t): round(float(q_policy[t]), 2) for t in (0, len(q_policy) // 2, len(q_policy) - 1)},
              "q_random_actions_at_last_state": [round(float(q_random.min()), 2), round(float(q_random.max()), 2)]}
    known = trained_reward(cfg, expert)
    if known is not None:
        known = (known[0], discounted_returns(known[1], gamma))
        report[f"{known[0]}_return_to_go_expert"] = {str(t): round(float(known[1][t]), 2) for t in steps}
    if plot is not None:
        title = f"{os.path.basename(run_dir)}: the last checkpoint's {len(critics)} critics (gamma {gamma})"
        report["plot"] = plot_critic(plot, title, q_experts, q_policies, known)
    return report


def probe(run_dir: str, episodes: int = 1, seed: int | None = None, stochastic: bool = False,
          critic: bool = False, plot: str | None = None) -> dict:
    cfg = OmegaConf.load(os.path.join(run_dir, "config.yaml"))
    task = cfg.env.task
    spec = resolve_scenario(task)
    if "x" not in spec.observation_layout:
        raise SystemExit(f"error: {task} has no torso x (a locomotion task: hopper, halfcheetah)")
    seed = int(cfg.eval.seed if seed is None else seed)
    x_at, angle_at = spec.observation_layout["x"][0], spec.observation_layout["angle"][0]
    out = []
    for i, rollout in enumerate(policy_episodes(run_dir, task, episodes, seed, stochastic)):
        obs = rollout["next", "observation"]
        x = [round(float(v), 1) for v in obs[::100, x_at]] + [round(float(obs[-1, x_at]), 1)]
        angle = obs[:, angle_at]
        out.append({"seed": seed + i, "return": round(float(rollout["next", "reward"].sum()), 1),
                    "length": int(rollout.shape[-1]), "x_every_100": x,
                    "angle_range": [round(float(angle.min()), 2), round(float(angle.max()), 2)],
                    "on_its_back": bool(angle.abs().max() > math.pi / 2)})
        print(f"seed {seed + i}: return {out[-1]['return']}, {out[-1]['length']} steps, x {x}, "
              f"angle {out[-1]['angle_range']}")
    report = {"run_dir": run_dir, "task": task, "actions": "sampled" if stochastic else "mean", "episodes": out}
    if critic:
        report["critic"] = critic_probe(run_dir, cfg, rollout, plot)
        print(f"critic: {report['critic']}")
    return report


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dir")
    parser.add_argument("--episodes", type=int, default=1)
    parser.add_argument("--seed", type=int, default=None, help="first episode's seed (default: the run's eval.seed)")
    parser.add_argument("--stochastic", action="store_true", help="sample the actions (default: the policy's mean)")
    parser.add_argument("--critic", action="store_true", help="also what the last checkpoint's critics believe")
    parser.add_argument("--plot", default=None, metavar="PNG", help="with --critic: draw Q along both episodes there")
    args = parser.parse_args()
    if args.plot is not None and not args.critic:
        parser.error("--plot draws the critic probe: give --critic too")
    torch.set_num_threads(1)
    print(json.dumps(probe(os.path.abspath(args.run_dir), args.episodes, args.seed, args.stochastic, args.critic,
                           args.plot)))


if __name__ == "__main__":
    main()
