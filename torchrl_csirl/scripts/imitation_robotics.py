"""``recipes/imitation_highway.py`` with ``relocate`` as its default task:
``python recipes/imitation_robotics.py method=bc env.task=relocate``.

The same script (one baselines script takes every task; the task's family picks the schema,
:class:`~torchrl_csirl.methods.baselines.ImitationTaskConfig` for every task but the driving scenes); the
one difference is the task when the command line names none: ``relocate``. Two rows differ from driving
on a robotics task: ``sac`` learns from the environment's own reward and ``expert`` is the task's expert
(docs/experts.md); the summary's ``return`` is the paper's metric there. It accepts every command line
that ``recipes/imitation_highway.py`` accepts.
"""
from __future__ import annotations

from functools import partial

from torchrl_csirl.methods.baselines import ImitationRoboticsConfig  # noqa: F401 - the schema, for the docs
from torchrl_csirl.run.run import run_script
from torchrl_csirl.scripts import imitation_highway

__all__ = ["main"]

main = partial(imitation_highway.main, default_task="relocate")

if __name__ == "__main__":
    run_script(main)
