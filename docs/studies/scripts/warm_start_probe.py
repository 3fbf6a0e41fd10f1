"""What CSIRL's actor warm start gives before any reinforcement update: a robotics task's test episodes.

``python docs/studies/scripts/warm_start_probe.py [--task antmaze-umaze] [--updates 30000] [--seed 0] [--episodes 50] [--out DIR]
[key=value ...]``

Builds CSIRL's learner exactly as a run does (the CSIRL recipe's configuration with ``seed``, the task and the
overrides; ``torch.manual_seed(seed)``; the demonstrations, the loss modules, the expert buffer), runs its
warm start (``csirl.actor_pretrain_updates`` behavioural-cloning updates of the actor) and nothing else, saves the
actor as ``DIR/policy.pt`` and rolls it over the recipe's 50 test episodes as ``torchrl-csirl outcomes``
does. It tells "the warm start does not imitate" from "the reinforcement updates undo it": a run's first evaluation
comes only after a round of SAC updates (docs/studies/outside-driving.md, AntMaze U-maze).

The last line is JSON; a Markdown table goes to stderr.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile

import torch

from torchrl_csirl.methods.csirl import make_loss_modules, warm_start_actor
from torchrl_csirl.modules import load_policy, save_policy
from torchrl_csirl.run.builders import load_experts
from torchrl_csirl.run.recipes import load_config_for
from torchrl_csirl.scripts.robotics_outcomes import OUTCOMES, classify_episodes, print_table, summarize
from torchrl_csirl.tasks import resolve_scenario


def warm_started_policy(task: str, updates: int, seed: int, overrides: list[str], out_dir: str) -> str:
    """CSIRL's actor after its warm start and before anything else, saved as ``out_dir/policy.pt`` (its path)."""
    cfg = load_config_for("csirl")([f"env.task={task}", f"seed={seed}",
                                    f"csirl.actor_pretrain_updates={updates}", *overrides])
    torch.manual_seed(cfg.seed)
    spec = resolve_scenario(cfg.env.task)
    demos = load_experts(cfg.expert, spec)
    modules = make_loss_modules(cfg, spec, "cpu", demos)
    warm_start_actor(cfg, modules, demos.as_replay_buffer(batch_size=cfg.expert.batch_size))
    return save_policy(modules.actor, os.path.join(out_dir, "policy.pt"), obs_dim=spec.obs_dim,
                       action_dim=spec.action_dim, scenario=task)


def main(argv: list[str] | None = None) -> dict[str, object]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="antmaze-umaze", choices=sorted(OUTCOMES))
    parser.add_argument("--updates", type=int, default=30_000, help="csirl.actor_pretrain_updates")
    parser.add_argument("--seed", type=int, default=0, help="the run's seed")
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--test-seed", type=int, default=1_000_000, help="seed of the first test episode (eval.seed)")
    parser.add_argument("--out", default=None, help="where policy.pt goes (default: a temporary directory)")
    parser.add_argument("overrides", nargs="*", help="key=value overrides of the CSIRL recipe")
    args = parser.parse_args(argv)
    if args.updates <= 0:
        parser.error(f"--updates must be positive, got {args.updates}")
    torch.set_num_threads(1)
    out_dir = args.out or tempfile.mkdtemp(prefix="warm-start-")
    os.makedirs(out_dir, exist_ok=True)
    path = warm_started_policy(args.task, args.updates, args.seed, args.overrides, out_dir)
    stats = summarize(args.task, classify_episodes(load_policy(path), args.task, args.episodes, args.test_seed))
    stats.update(policy=path, updates=args.updates, seed=args.seed)
    print_table(args.task, stats)
    print(json.dumps(stats), file=sys.stdout)
    return stats


if __name__ == "__main__":
    main()
