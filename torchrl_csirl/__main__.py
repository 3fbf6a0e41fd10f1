"""``python -m torchrl_csirl <command> ...``: the ``torchrl-csirl`` command (:mod:`torchrl_csirl.scripts.cli`)."""
from torchrl_csirl.scripts.cli import main

if __name__ == "__main__":
    main()
