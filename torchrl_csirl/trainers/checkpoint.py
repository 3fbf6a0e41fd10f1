"""Checkpoints of a :class:`~torchrl_csirl.trainers.CSIRLTrainer`: written atomically with the
online replay buffer (:class:`CheckpointHook`), restored exactly (:func:`load_checkpoint`)."""
from __future__ import annotations

import os
import shutil
from typing import Any

import torch

from torchrl_csirl.trainers.trainer import CSIRLTrainer

__all__ = ["CheckpointHook", "load_checkpoint"]


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


def load_checkpoint(trainer: CSIRLTrainer, path: str | os.PathLike, online_buffer: Any = None) -> None:
    """Restores a :class:`CheckpointHook` checkpoint into a trainer built like the saved one.

    Raises:
        FileNotFoundError: when ``path`` holds no ``state.pt``.
    """
    path = os.fspath(path)
    state_file = os.path.join(path, "state.pt")
    if not os.path.isfile(state_file):
        raise FileNotFoundError(f"No checkpoint at {path!r} (expected {state_file}).")
    buffer_dir = os.path.join(path, "online_buffer")
    if online_buffer is not None and os.path.isdir(buffer_dir):
        online_buffer.loads(buffer_dir)
    # saved tensors come back on the CPU; load_state_dict copies them to the modules' devices
    trainer.load_state_dict(torch.load(state_file, weights_only=False, map_location="cpu"))
