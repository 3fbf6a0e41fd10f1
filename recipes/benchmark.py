"""The comparison, methods x tasks x seeds as Ray Tune trials, and its tables and curves:
``python recipes/benchmark.py --methods csirl bc --scenarios merge --seeds 0 1 2`` (``report <dirs>`` for the tables).

Thin by design: the script's body is :mod:`torchrl_csirl.scripts.benchmark`, so an installed wheel runs
the same thing as ``python -m torchrl_csirl.scripts.benchmark``; ``--help`` says what it accepts.
"""
import sys

from torchrl_csirl.scripts.benchmark import main

if __name__ == "__main__":
    sys.exit(main())
