"""The CSIRL round hooks of :class:`~torchrl_csirl.trainers.CSIRLTrainer` (stage ``round_end``).

* :class:`SubgoalSelectionHook`: the curricular subgoal selection (Alg. 1);
* :class:`EvaluationHook`: the deterministic policy's accomplish rate;
* :class:`StopAtTarget` (stage ``post_round``): ends training at the first evaluation that reaches a target;
* :class:`KeepBestPolicy`: the policy of the best evaluation, written to a file, to finish with.

The update steps are in :mod:`torchrl_csirl.trainers.updates`, the checkpoints in
:mod:`torchrl_csirl.trainers.checkpoint`.
"""
from __future__ import annotations

import os
import sys
from collections.abc import Callable
from typing import Any

import torch
from torch import nn

from torchrl_csirl.trainers.trainer import CSIRLTrainer

__all__ = ["EvaluationHook", "KeepBestPolicy", "StopAtTarget", "SubgoalSelectionHook"]


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


class StopAtTarget:
    """``post_round`` (after the round's checkpoint): ends training at the first evaluation of
    :class:`EvaluationHook` whose ``key`` reaches ``target``: the run then finishes as at its last frame
    (final test, policy, summary), at the frames reached. An expert's training stops where it is good
    enough, and the same command reproduces it.

    Args:
        evaluation: the run's evaluation hook.
        target: the value to reach.
        key: the evaluation metric compared (``"env_return"``, the mean validation return).

    Examples:
        >>> from types import SimpleNamespace
        >>> evaluation = EvaluationHook(lambda: {"env_return": 3600.0})
        >>> trainer = SimpleNamespace(frames=408_000, updates=400_000, total_frames=1_000_000, postfix={},
        ...                           record=lambda **kw: None)
        >>> _ = evaluation.run(trainer)
        >>> StopAtTarget(evaluation, 3532.7)(trainer)
        >>> trainer.total_frames
        408000
    """

    def __init__(self, evaluation: EvaluationHook, target: float, key: str = "env_return") -> None:
        self.evaluation, self.target, self.key = evaluation, float(target), key

    def __call__(self, trainer: CSIRLTrainer) -> None:
        last = _this_round_evaluation(self.evaluation, trainer, self.key)
        if last is not None and last[self.key] >= self.target:
            print(f"eval {self.key} {last[self.key]:.1f} >= {self.target:g}: training stops at {trainer.frames} frames",
                  file=sys.stderr)
            trainer.total_frames = trainer.frames


def _this_round_evaluation(evaluation: EvaluationHook, trainer: CSIRLTrainer, key: str) -> dict[str, Any] | None:
    """The evaluation made at this round's end (``None`` if the round had none or it lacks ``key``)."""
    last = evaluation.history[-1] if evaluation.history else None
    if last is None or last["frames"] != trainer.frames or not isinstance(last.get(key), (int, float)):
        return None
    return last


class KeepBestPolicy:
    """``round_end`` (after :class:`EvaluationHook`): writes the policy's weights to ``path`` whenever an
    evaluation beats every earlier one written there, so a run whose learning curve swings (SAC on the
    Hopper) can finish with its best policy instead of its last (as RL Zoo's ``EvalCallback`` keeps its
    best model). The file holds ``{"state_dict", "frames", "updates", key}``; written before the round's
    checkpoint, so a run resumed after an interruption redoes that round and writes the same weights.

    The comparison is with the file: a run that turns this on when resumed keeps the best since then.

    Args:
        evaluation: the run's evaluation hook.
        policy: the module whose ``state_dict`` is kept (the learner's actor).
        path: the file written.
        key: the evaluation metric compared (``"env_return"``, the mean validation return).

    Examples:
        >>> import tempfile, os
        >>> from types import SimpleNamespace
        >>> from torch import nn
        >>> policy, path = nn.Linear(2, 1), os.path.join(tempfile.mkdtemp(), "best_policy.pt")
        >>> returns = iter([10.0, 30.0, 20.0])
        >>> evaluation = EvaluationHook(lambda: {"env_return": next(returns)})
        >>> keep = KeepBestPolicy(evaluation, policy, path)
        >>> for frames in (1000, 2000, 3000):
        ...     trainer = SimpleNamespace(frames=frames, updates=frames, postfix={}, record=lambda **kw: None)
        ...     _ = evaluation.run(trainer)
        ...     keep(trainer)
        >>> best = keep.restore()
        >>> best["frames"], best["env_return"]
        (2000, 30.0)
    """

    def __init__(self, evaluation: EvaluationHook, policy: nn.Module, path: str | os.PathLike,
                 key: str = "env_return") -> None:
        self.evaluation, self.policy, self.path, self.key = evaluation, policy, os.fspath(path), key

    def best(self) -> dict[str, Any] | None:
        """What the file holds (``None`` before the first evaluation)."""
        if not os.path.isfile(self.path):
            return None
        return torch.load(self.path, map_location="cpu", weights_only=True)

    def __call__(self, trainer: CSIRLTrainer) -> None:
        last = _this_round_evaluation(self.evaluation, trainer, self.key)
        if last is None:
            return
        kept = self.best()
        if kept is not None and kept["frames"] != trainer.frames and last[self.key] <= kept[self.key]:
            return
        state = {k: v.detach().cpu().clone() for k, v in self.policy.state_dict().items()}
        tmp = f"{self.path}.tmp"
        torch.save({"state_dict": state, "frames": trainer.frames, "updates": trainer.updates,
                    self.key: float(last[self.key])}, tmp)
        os.replace(tmp, self.path)

    def restore(self) -> dict[str, Any]:
        """Loads the kept weights into the policy; returns the file's record (frames, updates, value)."""
        kept = self.best()
        if kept is None:
            raise FileNotFoundError(f"no best policy was kept in {self.path}: the run made no evaluation with "
                                    f"{self.key!r} while keeping the best.")
        self.policy.load_state_dict(kept["state_dict"])
        return {k: v for k, v in kept.items() if k != "state_dict"}
