"""The CSIRL round hooks of :class:`~torchrl_csirl.trainers.CSIRLTrainer` (stage ``round_end``).

* :class:`SubgoalSelectionHook`: the curricular subgoal selection (Alg. 1);
* :class:`EvaluationHook`: the deterministic policy's accomplish rate.

The update steps are in :mod:`torchrl_csirl.trainers.updates`, the checkpoints in
:mod:`torchrl_csirl.trainers.checkpoint`.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

from torchrl_csirl.trainers.trainer import CSIRLTrainer

__all__ = ["EvaluationHook", "SubgoalSelectionHook"]


class SubgoalSelectionHook:
    """``round_end``: moves the subgoal with the curriculum (its only owner).

    The matching reward reads the subgoal from the curriculum
    (``SubgoalMatchingReward(..., subgoal=curriculum)``), so nothing is copied here. Keeps the
    selection history (frames, subgoal, uncertainty profile, scan ratios) for the plots, records
    ``subgoal`` and ``subgoal_changed`` in the metrics row and shows the subgoal on the bar.

    Args:
        curriculum: the :class:`~torchrl_csirl.curriculum.SubgoalCurriculum`.
    """

    def __init__(self, curriculum: Any) -> None:
        self.curriculum = curriculum
        self.history: list[dict[str, Any]] = []

    def __call__(self, trainer: CSIRLTrainer) -> None:
        selection = self.curriculum.step()
        self.history.append(
            {
                "frames": trainer.frames,
                "updates": trainer.updates,
                "round": trainer.rounds,
                "subgoal": selection.subgoal,
                "previous": selection.previous,
                "profile": selection.profile.tolist(),
                "ratios": selection.ratios.tolist(),
            }
        )
        trainer.record(subgoal=selection.subgoal, subgoal_changed=int(selection.changed))
        trainer.postfix["subgoal"] = f"{selection.subgoal}/{self.curriculum.length - 1}"

    def state_dict(self) -> dict[str, Any]:
        return {"curriculum": self.curriculum.state_dict(), "history": list(self.history)}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.curriculum.load_state_dict(state["curriculum"])
        self.history = list(state["history"])


class EvaluationHook:
    """``round_end``: evaluates the policy every ``every_rounds`` rounds.

    Args:
        evaluate: ``callable() -> dict`` of metrics (e.g. a partial of
            :func:`~torchrl_csirl.trainers.evaluate_policy`, which works on any task); the progress
            line shows its ``accomplish_rate`` and its ``env_return``.
        every_rounds: evaluation cadence in rounds.
    """

    def __init__(self, evaluate: Callable[[], dict[str, float]], every_rounds: int = 1) -> None:
        if every_rounds < 1:
            raise ValueError(f"every_rounds must be >= 1, got {every_rounds}.")
        self.evaluate = evaluate
        self.every_rounds = int(every_rounds)
        self.history: list[dict[str, Any]] = []

    def run(self, trainer: CSIRLTrainer) -> dict[str, float]:
        """Evaluates now, records ``eval_*`` metrics and the history entry."""
        metrics = self.evaluate()
        self.history.append({"frames": trainer.frames, "updates": trainer.updates, **metrics})
        trainer.record(**{f"eval_{key}": value for key, value in metrics.items()})
        rate, ret = metrics.get("accomplish_rate"), metrics.get("env_return")  # an evaluator of one's own may have neither
        if isinstance(rate, (int, float)):
            trainer.postfix["eval"] = f"{rate:.2f}"
        if isinstance(ret, (int, float)):  # the score of a task without a goal (locomotion)
            trainer.postfix["return"] = f"{ret:.0f}" if abs(ret) >= 100 else f"{ret:.2f}"
        return metrics

    def __call__(self, trainer: CSIRLTrainer) -> None:
        if (trainer.rounds + 1) % self.every_rounds == 0:
            self.run(trainer)

    def state_dict(self) -> dict[str, Any]:
        return {"history": list(self.history)}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.history = list(state["history"])
