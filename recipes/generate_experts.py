"""Roll a task's expert and write expert demonstrations: ``python recipes/generate_experts.py --scenario merge``.

Thin by design: the script's body is :mod:`torchrl_csirl.scripts.generate_experts`, so an installed wheel runs
the same thing as ``python -m torchrl_csirl.scripts.generate_experts``; ``--help`` says what it accepts.
"""
from torchrl_csirl.scripts.generate_experts import main

if __name__ == "__main__":
    main()
