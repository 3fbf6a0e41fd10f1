"""Curricular subgoal selection from the critic ensemble's uncertainty."""
from __future__ import annotations

from torchrl_csirl.curriculum.subgoal import (
    SubgoalCurriculum,
    SubgoalSelection,
    critic_uncertainty,
    scan_subgoal,
)

__all__ = ["SubgoalCurriculum", "SubgoalSelection", "critic_uncertainty", "scan_subgoal"]
