"""CSIRL on a driving scenario, end to end: ``python recipes/csirl_highway.py [key=value ...]``.

Thin by design: the script's body is :mod:`torchrl_csirl.scripts.csirl_highway`, so an installed wheel runs
the same thing as ``python -m torchrl_csirl.scripts.csirl_highway``; ``--help`` says what it accepts.
"""
from torchrl_csirl.run.run import run_script
from torchrl_csirl.scripts.csirl_highway import main

if __name__ == "__main__":
    run_script(main)
