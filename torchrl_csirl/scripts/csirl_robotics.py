"""``recipes/csirl_highway.py`` with ``relocate`` as its default task: ``python recipes/csirl_robotics.py env.task=relocate``.

The same script (one CSIRL script takes every task; the task's family picks the schema,
:class:`~torchrl_csirl.methods.csirl.CSIRLTaskConfig` for every task but the driving scenes); the one
difference is the task when the command line names none: ``relocate``. It accepts every command line that
``recipes/csirl_highway.py`` accepts.
"""
from __future__ import annotations

from functools import partial

from torchrl_csirl.methods.csirl import CSIRLRoboticsConfig  # noqa: F401 - the schema, for the docs
from torchrl_csirl.run.run import run_script
from torchrl_csirl.scripts import csirl_highway

__all__ = ["main"]

main = partial(csirl_highway.main, default_task="relocate")

if __name__ == "__main__":
    run_script(main)
