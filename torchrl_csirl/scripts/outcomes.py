"""How a policy's test episodes end: any driving scenario, AntMaze U-maze or Adroit Relocate.

``torchrl-csirl outcomes <run dir or policy.pt> [--episodes 50] [--seed 1000000]``

Rolls out the saved deterministic policy on the recipe's test episodes (seeds ``seed .. seed + episodes - 1``, as
the final evaluation does) and reports how they end, by the policy's task: a driving scene's outcomes (success,
crash, off-road, time-out), speeds and where the off-road episodes left the road
(:mod:`torchrl_csirl.scripts.driving_outcomes`); AntMaze's goal, flipped or short and where the ant ended, or
Relocate's ball at the target, lost or never there (:mod:`torchrl_csirl.scripts.robotics_outcomes`). A Markdown
table goes to stderr; the last line is JSON (with the policy's ``scenario`` for a driving one, its ``task`` for a
robotics one).

Examples:
    >>> sorted({module.__name__.rpartition(".")[2] for module in FAMILIES.values()})
    ['driving_outcomes', 'robotics_outcomes']
"""
from __future__ import annotations

from types import ModuleType

from torchrl_csirl.scripts import driving_outcomes, robotics_outcomes
from torchrl_csirl.scripts._policy_rollouts import load_test_policy
from torchrl_csirl.tasks import SCENARIOS

__all__ = ["FAMILIES", "main"]

#: task -> the module that reads its episodes
FAMILIES: dict[str, ModuleType] = {**dict.fromkeys(SCENARIOS, driving_outcomes),
                                   **dict.fromkeys(robotics_outcomes.OUTCOMES, robotics_outcomes)}


def main(argv: list[str] | None = None) -> dict:
    """Rolls the policy (``argv``: the command line, ``None`` for ``sys.argv[1:]``); returns the JSON line's statistics.

    Raises:
        SystemExit: status 2, one line on stderr, for a policy of another task or ``--episodes`` below 1.
    """
    args, policy, task = load_test_policy(__doc__.splitlines()[0], argv, FAMILIES,
                                          "driving scenarios and robotics tasks", prog="torchrl-csirl outcomes")
    return FAMILIES[task].report(args, policy, task)
