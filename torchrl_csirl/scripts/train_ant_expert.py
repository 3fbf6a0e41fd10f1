"""Trains the AntMaze expert's goal-reaching ant: ``python recipes/train_ant_expert.py [key=value ...]``.

TorchRL's SAC (the baselines' learner: :func:`~torchrl_csirl.objectives._imitation.make_sac_learner`,
published SAC defaults, two critics, 256 x 256 networks) on the ``ant-goal`` task
(:class:`~torchrl_csirl.tasks.robotics.AntGoalEnv`: chains of 4 goals, each 0.9-6.3 m on, in the U-maze,
reward = speed toward the goal, +10 on arrival), with the shared recipe machinery: collector
workers, checkpoints every ``checkpoint.every_rounds`` rounds with the replay buffer (exact resume
with ``checkpoint.resume=<run dir>``; the run takes hours on 2 cores), metrics CSV/JSONL, wandb
offline, a learning curve of the chain success (all 4 goals reached), ``policy.pt`` and ``summary.json``.

At the end, the trained policy drives the ant through the U-maze as
:class:`~torchrl_csirl.tasks.robotics.WaypointAntExpert` on ``expert_eval.episodes`` AntMaze
episodes from seed ``expert_eval.seed`` (unseen: the training task draws its own hops), and the
summary reports that success rate (the expert's acceptance figure, docs/studies/robotics.md) beside the
chain success (``hop_success_rate``: the share of test episodes that reached all 4 goals).
``device=auto`` trains on a GPU when there is one.

Examples::

    python recipes/train_ant_expert.py                                   # 1 M frames, CPU or GPU
    python recipes/train_ant_expert.py checkpoint.resume=runs/ant-goal-sac-s0-...   # continue
    python recipes/generate_experts.py --scenario antmaze-umaze --ant-policy runs/ant-goal-sac-s0-... \\
        --episodes 100 --seed 10000                                     # the expert on unseen seeds
"""
from __future__ import annotations

import sys

from torchrl_csirl.methods.ant_expert import AntExpertConfig  # noqa: F401 - the schema, for the docs
from torchrl_csirl.methods.expert import ANT_EXPERT_RECIPE
from torchrl_csirl.run import config as config_lib
from torchrl_csirl.run.lifecycle import run_recipe
from torchrl_csirl.run.run import run_script, write_summary

__all__ = ["main"]


def main(argv: list[str] | None = None) -> dict[str, object]:
    command = config_lib.parse_command_line(sys.argv[1:] if argv is None else argv)  # the one parse
    if config_lib.help_requested(command, __doc__, AntExpertConfig):
        return {}
    summary = run_recipe(ANT_EXPERT_RECIPE, command)
    maze = summary.get("antmaze_success_rate")
    print(f"ant-goal: 4-goal chain success {summary['hop_success_rate']:.2f}"
          + (f", AntMaze with waypoints {maze:.2f}" if maze is not None else "")
          + f" after {summary['frames']} frames / {summary['updates']} updates", file=sys.stderr)
    return write_summary(summary, summary["run_dir"])


if __name__ == "__main__":
    run_script(main)
