"""Watch a trained agent: ``python recipes/watch.py <run dir> [--episodes N] [--format mp4|gif]``.

Thin by design: the script's body is :mod:`torchrl_csirl.scripts.watch`, so an installed wheel runs
the same thing as ``python -m torchrl_csirl.scripts.watch``; ``--help`` says what it accepts.
"""
from torchrl_csirl.analysis.visualization.video import VideoError
from torchrl_csirl.run.run import run_script
from torchrl_csirl.scripts.watch import main

if __name__ == "__main__":
    run_script(main, known_errors=(VideoError,))
