"""Why a run failed: ``python recipes/diagnose.py <run dir>`` writes its health report (``health.json``, ``health.png``).

Thin by design: the script's body is :mod:`torchrl_csirl.scripts.diagnose`, so an installed wheel runs
the same thing as ``python -m torchrl_csirl.scripts.diagnose`` or ``torchrl-csirl diagnose``.
"""
from torchrl_csirl.run.run import run_script
from torchrl_csirl.scripts.diagnose import main

if __name__ == "__main__":
    run_script(main)
