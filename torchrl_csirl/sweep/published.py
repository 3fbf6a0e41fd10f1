"""The published numbers the benchmark's tables set beside ours: the paper's Table I on the driving scenarios
and, on the locomotion tasks, IQ-Learn's Table 3 (which ran GAIL, DAC and ValueDICE beside IQ-Learn).

Numbers only, no code that runs a cell or writes a table: :mod:`torchrl_csirl.sweep.report` prints
them, ``tests/test_tables.py`` checks the pages against them.

Examples:
    >>> PAPER_TABLE["csirl"]["merge"], PUBLISHED_LOCOMOTION["gail"]["hopper"]["return"]
    (0.92, 3252.5)
"""
from __future__ import annotations

from typing import Any

__all__ = ["PAPER_TABLE", "PUBLISHED_EXPERTS", "PUBLISHED_GAP", "PUBLISHED_LOCOMOTION", "published_gap"]

#: the paper's Table I (accomplish rate, 25 expert trajectories, 5 seeds; the expert at 1.00, so
#: read as expert-normalised): /work/shared/SPEC.md section 2, paper Table "tab:result"
PAPER_TABLE: dict[str, dict[str, float]] = {
    "expert": {"highway-fast": 1.00, "merge": 1.00, "intersection": 1.00, "roundabout": 1.00},
    "random": {"highway-fast": 0.02, "merge": 0.01, "intersection": 0.16, "roundabout": 0.04},
    "sac": {"highway-fast": 0.10, "merge": 0.06, "intersection": 0.11, "roundabout": 0.09},
    "bc": {"highway-fast": 0.10, "merge": 0.13, "intersection": 0.14, "roundabout": 0.04},
    "gail": {"highway-fast": 0.06, "merge": 0.01, "intersection": 0.09, "roundabout": 0.04},
    "dac": {"highway-fast": 0.01, "merge": 0.05, "intersection": 0.32, "roundabout": 0.03},
    "valuedice": {"highway-fast": 0.12, "merge": 0.04, "intersection": 0.32, "roundabout": 0.02},
    "sqil": {"highway-fast": 0.09, "merge": 0.13, "intersection": 0.32, "roundabout": 0.13},
    "iqlearn": {"highway-fast": 0.52, "merge": 0.49, "intersection": 0.36, "roundabout": 0.10},
    "csirl": {"highway-fast": 0.85, "merge": 0.92, "intersection": 0.86, "roundabout": 0.74},
}


#: published results on the locomotion tasks, one protocol (one full expert trajectory, gym v2): Garg et al. 2021,
#: "IQ-Learn", Table 3 (raw returns; its experts Hopper 3532.7, HalfCheetah 5098.3), which ran GAIL, DAC and
#: ValueDICE beside IQ-Learn. method -> task -> {"return": the raw return, "expert": the paper's expert's return,
#: "source"}. Other papers' own figures (other protocols and budgets) and the notes: docs/benchmark.md#published-results
PUBLISHED_EXPERTS = {"hopper": 3532.7, "halfcheetah": 5098.3}
_IQ_TABLE3 = {"gail": (3252.5, 3080.0), "dac": (3305.1, 4080.6), "valuedice": (3312.1, 3835.6), "iqlearn": (3546.4, 5076.6)}
PUBLISHED_LOCOMOTION: dict[str, dict[str, dict[str, Any]]] = {
    method: {task: {"return": value, "expert": PUBLISHED_EXPERTS[task], "source": "IQ-Learn Tab. 3"}
             for task, value in zip(("hopper", "halfcheetah"), values)}
    for method, values in _IQ_TABLE3.items()}


#: how far below its paper a baseline may sit before it is treated as a suspected implementation difference
#: a gap beyond it is bold in the report and explained in docs/benchmark.md#published-results
PUBLISHED_GAP = 0.2


def published_gap(method: str, task: str, ours: float | None) -> float | None:
    """Our raw return ``ours`` minus the published one of ``method`` on ``task``, as a fraction of the paper's
    expert's return: both sides divided by the same expert (ours differs from the paper's), ``None`` without
    a published figure or a return of ours.

    Examples:
        >>> round(published_gap("gail", "hopper", 3160.0), 3), published_gap("sqil", "hopper", 3160.0)
        (-0.026, None)
    """
    entry = PUBLISHED_LOCOMOTION.get(method, {}).get(task)
    if entry is None or ours is None:
        return None
    return (ours - entry["return"]) / entry["expert"]

