"""Trains the AntMaze expert's goal-reaching ant: ``python recipes/train_ant_expert.py [key=value ...]``.

Thin by design: the script's body is :mod:`torchrl_csirl.scripts.train_ant_expert`, so an installed wheel runs
the same thing as ``python -m torchrl_csirl.scripts.train_ant_expert``; ``--help`` says what it accepts.
"""
from torchrl_csirl.run.run import run_script
from torchrl_csirl.scripts.train_ant_expert import main

if __name__ == "__main__":
    run_script(main)
