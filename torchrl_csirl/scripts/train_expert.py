"""An expert for any task, and its demonstrations: ``python recipes/train_expert.py env.gym_id=Hopper-v5 [key=value ...]``.

SAC on the task's own reward (the baselines' learner, published SAC defaults, two critics,
256 x 256 networks) with the run layer's machinery: collector workers, checkpoints with the replay
buffer every ``checkpoint.every_rounds`` rounds (exact resume with ``checkpoint.resume=<run dir>``;
experts take hours on 2 cores), metrics, a learning curve of the test return, ``policy.pt`` and
``summary.json``. At the end the deterministic policy is rolled for ``demos.episodes`` episodes from
seed ``demos.seed`` and written as demonstrations (``demos.path``, default
``<run dir>/demos_<episodes>.npz``; ``demos.minari_id`` also writes a local Minari dataset), the file
every imitation script reads with ``expert.path=``.

The task: ``env.gym_id=<id>`` (any gymnasium id with flat ``Box`` spaces), ``env.task=<name>`` (a
robotics task, ``ant-goal``, or with ``env.module=<module>`` a task of your own). A batch must cover an
episode per environment: ``collector.frames_per_batch`` >= workers x the episode limit.

Examples::

    python recipes/train_expert.py env.gym_id=Hopper-v5 collector.frames_per_batch=2000
    python recipes/train_expert.py checkpoint.resume=runs/Hopper-v5-sac-s0-...        # continue
"""
from __future__ import annotations

import sys

from torchrl_csirl.methods.expert import EXPERT_RECIPE, ExpertTrainingConfig  # noqa: F401 - the schema, for the docs
from torchrl_csirl.run import config as config_lib
from torchrl_csirl.run.lifecycle import run_recipe
from torchrl_csirl.run.run import run_script, write_summary

__all__ = ["main"]


def main(argv: list[str] | None = None) -> dict[str, object]:
    command = config_lib.parse_command_line(sys.argv[1:] if argv is None else argv)  # the one parse
    if config_lib.help_requested(command, __doc__, ExpertTrainingConfig):
        return {}
    summary = run_recipe(EXPERT_RECIPE, command)
    demos = f"; {summary['demos_episodes']} demonstrations in {summary['demos_path']}" if "demos_path" in summary else ""
    print(f"{summary['scenario']}: test return {summary['return']:.1f} (success {summary['success_rate']:.2f}) after "
          f"{summary['frames']} frames / {summary['updates']} updates{demos}", file=sys.stderr)
    return write_summary(summary, summary["run_dir"])


if __name__ == "__main__":
    run_script(main)
