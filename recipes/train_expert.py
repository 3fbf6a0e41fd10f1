"""An expert for any task, and its demonstrations: ``python recipes/train_expert.py env.gym_id=Hopper-v5 [key=value ...]``.

Thin by design: the script's body is :mod:`torchrl_csirl.scripts.train_expert`, so an installed wheel runs
the same thing as ``python -m torchrl_csirl.scripts.train_expert``; ``--help`` says what it accepts.
"""
from torchrl_csirl.run.run import run_script
from torchrl_csirl.scripts.train_expert import main

if __name__ == "__main__":
    run_script(main)
