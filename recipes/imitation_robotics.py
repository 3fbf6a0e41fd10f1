"""One baseline on a robotics task: ``python recipes/imitation_robotics.py method=<name> env.task=relocate [key=value ...]``.

Thin by design: the script's body is :mod:`torchrl_csirl.scripts.imitation_robotics`, so an installed wheel runs
the same thing as ``python -m torchrl_csirl.scripts.imitation_robotics``; ``--help`` says what it accepts.
"""
from torchrl_csirl.run.run import run_script
from torchrl_csirl.scripts.imitation_robotics import main

if __name__ == "__main__":
    run_script(main)
