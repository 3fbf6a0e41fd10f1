"""CSIRL on a robotics task, end to end: ``python recipes/csirl_robotics.py env.task=relocate [key=value ...]``.

Thin by design: the script's body is :mod:`torchrl_csirl.scripts.csirl_robotics`, so an installed wheel runs
the same thing as ``python -m torchrl_csirl.scripts.csirl_robotics``; ``--help`` says what it accepts.
"""
from torchrl_csirl.run.run import run_script
from torchrl_csirl.scripts.csirl_robotics import main

if __name__ == "__main__":
    run_script(main)
