"""One baseline on a driving scenario: ``python recipes/imitation_highway.py method=<name> [key=value ...]``.

Thin by design: the script's body is :mod:`torchrl_csirl.scripts.imitation_highway`, so an installed wheel runs
the same thing as ``python -m torchrl_csirl.scripts.imitation_highway``; ``--help`` says what it accepts.
"""
from torchrl_csirl.run.run import run_script
from torchrl_csirl.scripts.imitation_highway import main

if __name__ == "__main__":
    run_script(main)
