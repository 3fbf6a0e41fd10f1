"""Checkpoints of a :class:`~torchrl_csirl.trainers.CSIRLTrainer`: written atomically with the
online replay buffer (:class:`CheckpointHook`), restored exactly (:func:`load_checkpoint`)."""
from __future__ import annotations

import os
import shutil
from typing import Any

import torch

from torchrl_csirl.trainers.trainer import CSIRLTrainer

__all__ = ["CheckpointError", "CheckpointHook", "load_checkpoint", "read_checkpoint_state"]


class CheckpointError(RuntimeError):
    """A checkpoint that cannot be read (truncated or corrupted file): one line naming it."""


class CheckpointHook:
    """``post_round`` / ``train_end``: writes the trainer state and the online buffer, atomically.

    The checkpoint is the directory ``<directory>/last``: ``state.pt`` (counters, modules,
    optimisers, curriculum, histories, RNG states) and ``online_buffer/`` (the replay buffer's own
    ``dumps``). It is written to a temporary directory first and swapped in by rename, so a run
    killed while saving keeps its previous checkpoint.

    Args:
        directory: where ``last`` lives (the run's ``checkpoints`` directory).
        online_buffer: buffer to save (None: not saved).
        every_rounds: cadence in rounds (0: only at the end of training).
    """

    def __init__(self, directory: str | os.PathLike, online_buffer: Any = None, every_rounds: int = 1) -> None:
        self.directory = os.fspath(directory)
        self.online_buffer = online_buffer
        self.every_rounds = int(every_rounds)
        self.saved = 0

    @property
    def path(self) -> str:
        return os.path.join(self.directory, "last")

    def save(self, trainer: CSIRLTrainer) -> str:
        """Writes the checkpoint now and returns its path."""
        os.makedirs(self.directory, exist_ok=True)
        tmp = os.path.join(self.directory, "last.tmp")
        shutil.rmtree(tmp, ignore_errors=True)
        os.makedirs(tmp)
        torch.save(trainer.state_dict(), os.path.join(tmp, "state.pt"))
        if self.online_buffer is not None:
            self.online_buffer.dumps(os.path.join(tmp, "online_buffer"))
        old = os.path.join(self.directory, "last.old")
        shutil.rmtree(old, ignore_errors=True)
        if os.path.exists(self.path):
            os.replace(self.path, old)
        os.replace(tmp, self.path)
        shutil.rmtree(old, ignore_errors=True)
        self.saved += 1
        return self.path

    def __call__(self, trainer: CSIRLTrainer) -> None:
        if self.every_rounds and trainer.rounds % self.every_rounds == 0:
            self.save(trainer)


def _unreadable(what: str, path: str, err: BaseException) -> CheckpointError:
    """The one-line error of an unreadable checkpoint part, naming the previous checkpoint if one is kept
    (``last.old`` beside it survives only a run killed while swapping a new checkpoint in)."""
    reason = (str(err).strip().splitlines() or [type(err).__name__])[0]
    previous = os.path.join(os.path.dirname(os.path.normpath(path)), "last.old")
    kept = (f"the previous checkpoint is kept at {previous} (resume with checkpoint.resume={previous})"
            if os.path.isfile(os.path.join(previous, "state.pt")) else "no previous checkpoint is kept")
    return CheckpointError(f"{what} cannot be read ({type(err).__name__}: {reason}); the file is truncated or "
                           f"corrupted; {kept}.")


def read_checkpoint_state(path: str | os.PathLike) -> dict[str, Any]:
    """The trainer state of the checkpoint directory ``path`` (its ``state.pt``), on the CPU.

    Raises:
        FileNotFoundError: when ``path`` holds no ``state.pt``.
        CheckpointError: when ``state.pt`` cannot be read, naming it (and the previous checkpoint, if kept).
    """
    path = os.fspath(path)
    state_file = os.path.join(path, "state.pt")
    if not os.path.isfile(state_file):
        raise FileNotFoundError(f"No checkpoint at {path!r} (expected {state_file}).")
    try:
        state = torch.load(state_file, weights_only=False, map_location="cpu")
        if not isinstance(state, dict) or "counters" not in state:
            raise ValueError("not a trainer state (no counters)")
    except Exception as err:  # noqa: BLE001 - torch.load / unpickling raise many kinds; re-raised as one line
        raise _unreadable(f"checkpoint {state_file}", path, err) from None
    return state


def load_checkpoint(trainer: CSIRLTrainer, path: str | os.PathLike, online_buffer: Any = None) -> None:
    """Restores a :class:`CheckpointHook` checkpoint into a trainer built like the saved one.

    Raises:
        FileNotFoundError: when ``path`` holds no ``state.pt``.
        CheckpointError: when the state or the online buffer cannot be read, naming the file.
    """
    path = os.fspath(path)
    state = read_checkpoint_state(path)
    buffer_dir = os.path.join(path, "online_buffer")
    if online_buffer is not None and os.path.isdir(buffer_dir):
        try:
            online_buffer.loads(buffer_dir)
        except Exception as err:  # noqa: BLE001 - re-raised as one line naming the directory
            raise _unreadable(f"checkpoint buffer {buffer_dir}", path, err) from None
    # saved tensors come back on the CPU; load_state_dict copies them to the modules' devices
    trainer.load_state_dict(state)
