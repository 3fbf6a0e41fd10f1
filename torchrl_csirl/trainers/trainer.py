"""A small trainer for CSIRL: the collect / update / round-end loop with named hook points.

Why not :class:`torchrl.trainers.Trainer`? TorchRL's trainer is built around one loss module and
one optimiser step per sampled batch. CSIRL needs, per update, a choice between a joint
SAC + meta-gradient step and a plain SAC step (two optimisers), and per *round* (a fixed number
of updates, not of batches) a subgoal selection, an evaluation and a checkpoint whose resume is
exact. :class:`CSIRLTrainer` keeps TorchRL's vocabulary (``register_op`` with named stages) so the
same pieces can be swapped: the update step, the round-end operations (subgoal selection,
evaluation) and the post-round operations (checkpointing) are all hooks.
"""
from __future__ import annotations

import math
import random
import sys
import time
from collections import defaultdict
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import torch
from tensordict import TensorDictBase

from torchrl_csirl.modules.input_memo import map_each_input_once

__all__ = ["CSIRLTrainer", "TrainingDivergedError", "TrainingInterrupted", "check_finite_losses", "rng_state",
           "set_rng_state"]

STAGES = ("batch_process", "post_update", "round_end", "post_round", "log", "train_end")


class TrainingDivergedError(RuntimeError):
    """Raised when a loss becomes NaN or infinite; the last good checkpoint is kept."""


class TrainingInterrupted(Exception):
    """Raised by :meth:`CSIRLTrainer.train` after :meth:`CSIRLTrainer.request_stop`, at a batch boundary:
    the trainer's state is the one of an uninterrupted run at that point, ready to be checkpointed.

    Attributes:
        reason: what :meth:`~CSIRLTrainer.request_stop` was given (e.g. ``"SIGTERM"``).
    """

    def __init__(self, reason: str) -> None:
        super().__init__(f"training stopped: {reason}")
        self.reason = reason


def check_finite_losses(losses: dict[str, torch.Tensor], where: str) -> None:
    """Raises :class:`TrainingDivergedError` naming every non-finite loss in ``losses``.

    Examples:
        >>> import torch
        >>> check_finite_losses({"loss_qvalue": torch.tensor(1.0)}, "update 3")
        >>> try:
        ...     check_finite_losses({"loss_actor": torch.tensor(float("nan"))}, "update 3")
        ... except TrainingDivergedError as err:
        ...     print(err)
        non-finite loss at update 3: loss_actor=nan
    """
    bad = {k: float(v.detach()) for k, v in losses.items() if not bool(torch.isfinite(v.detach()).all())}
    if bad:
        details = ", ".join(f"{k}={v}" for k, v in sorted(bad.items()))
        raise TrainingDivergedError(f"non-finite loss at {where}: {details}")


def rng_state() -> dict[str, Any]:
    """The global random states (torch, numpy, random) for checkpoints."""
    return {"torch": torch.get_rng_state(), "numpy": np.random.get_state(), "python": random.getstate()}


def set_rng_state(state: dict[str, Any]) -> None:
    """Restores :func:`rng_state`."""
    torch.set_rng_state(state["torch"])
    np.random.set_state(state["numpy"])
    random.setstate(state["python"])


class CSIRLTrainer:
    """Collect, update, and at every round end select the subgoal, evaluate and checkpoint.

    The loop, per collector batch:

    1. ``batch_process`` ops transform the batch; it is written to ``online_buffer``;
    2. ``round(utd_ratio * frames)`` updates (none while the buffer holds fewer than
       ``warmup_frames`` transitions), each one call of ``update_step(trainer)`` returning a dict
       of scalar losses, followed by the ``post_update`` ops;
    3. when the round holds ``updates_per_round`` updates: the ``round_end`` ops (e.g.
       :class:`~torchrl_csirl.trainers.SubgoalSelectionHook`,
       :class:`~torchrl_csirl.trainers.EvaluationHook`), then the ``post_round`` ops (e.g.
       :class:`~torchrl_csirl.trainers.CheckpointHook`);
    4. a metrics row is passed to the ``log`` ops;
    5. at a round end, one line (:meth:`round_line`) on stderr, flushed: above the progress bar
       on a terminal, alone in a log file or a cluster job's output (where the bar is off).

    Collection is reproducible per batch: before each batch the collector's environments are
    re-seeded with ``seed + 7919 * batch index`` and reset, so a resumed run collects the same data as an
    uninterrupted one (episodes cut at a batch end are simply not continued).

    Args:
        collector: a TorchRL collector (iterated once, batches of ``frames_per_batch``).
        online_buffer: the online replay buffer (sampled by ``update_step``).
        update_step: ``callable(trainer) -> dict[str, Tensor]`` doing one update.
        total_frames: environment frames to collect.
        utd_ratio: updates per collected frame.
        updates_per_round: updates between two round ends (the paper's 20 000).
        warmup_frames: transitions to hold before the first update of a round.
        clear_buffer_each_round: empty the online buffer at every round start (the paper's code).
        seed: base seed of the collection.
        progress_bar: show a tqdm bar over frames.
        round_lines: print one line per round to stderr. Defaults to ``True``.

    Examples:
        >>> # see recipes/csirl_highway.py and tests/test_trainer.py for complete set-ups
        >>> CSIRLTrainer.STAGES
        ('batch_process', 'post_update', 'round_end', 'post_round', 'log', 'train_end')
    """

    STAGES = STAGES

    def __init__(
        self,
        *,
        collector: Any,
        online_buffer: Any,
        update_step: Callable[[CSIRLTrainer], dict[str, torch.Tensor]],
        total_frames: int,
        utd_ratio: float,
        updates_per_round: int,
        warmup_frames: int = 0,
        clear_buffer_each_round: bool = False,
        seed: int = 0,
        progress_bar: bool = True,
        round_lines: bool = True,
    ) -> None:
        if total_frames <= 0:
            raise ValueError(f"total_frames must be positive, got {total_frames}.")
        if utd_ratio < 0:
            raise ValueError(f"utd_ratio must be >= 0, got {utd_ratio}.")
        if updates_per_round <= 0:
            raise ValueError(f"updates_per_round must be positive, got {updates_per_round}.")
        self.collector = collector
        self.online_buffer = online_buffer
        self.update_step = update_step
        self.total_frames = int(total_frames)
        self.utd_ratio = float(utd_ratio)
        self.updates_per_round = int(updates_per_round)
        self.warmup_frames = int(warmup_frames)
        self.clear_buffer_each_round = bool(clear_buffer_each_round)
        self.seed = int(seed)
        self.progress_bar = bool(progress_bar)
        self.round_lines = bool(round_lines)
        self._ops: dict[str, list[tuple[str, Callable]]] = {stage: [] for stage in STAGES}
        self._recorded: dict[str, Any] = {}
        self._stateful: dict[str, Any] = {}
        # counters (checkpointed)
        self.frames = 0
        self.updates = 0
        self.rounds = 0
        self.batches = 0
        self.updates_in_round = 0
        self._update_credit = 0.0
        self.last_losses: dict[str, float] = {}
        self.postfix: dict[str, Any] = {}
        self._wall = 0.0
        # wall seconds of the processes before this one (checkpointed as ``elapsed_s``), and when this
        # one's part began: the trainer's construction, close to the process start (recipes build it first)
        self.elapsed_before = 0.0
        self._created = time.perf_counter()
        self._time_collect = 0.0
        self._time_update = 0.0
        self._throughput_base = (0, 0)  # (frames, updates) not covered by the two times above
        self.stop_reason: str | None = None  # set by request_stop (e.g. from a signal handler)

    # ------------------------------------------------------------------ hooks
    def register_op(self, stage: str, op: Callable, name: str | None = None) -> None:
        """Appends ``op`` to ``stage`` (one of :attr:`STAGES`).

        ``batch_process`` ops receive and return the batch; ``post_update`` ops receive
        ``(trainer, losses)``; ``round_end``, ``post_round`` and ``train_end`` ops receive the
        trainer; ``log`` ops receive ``(trainer, row)``.
        """
        if stage not in self._ops:
            raise ValueError(f"Unknown stage {stage!r}; expected one of {STAGES}.")
        self._ops[stage].append((name or type(op).__name__, op))

    def register_state(self, name: str, obj: Any) -> None:
        """Includes ``obj.state_dict()`` in :meth:`state_dict` under ``name`` (restored on resume)."""
        if not (callable(getattr(obj, "state_dict", None)) and callable(getattr(obj, "load_state_dict", None))):
            raise TypeError(f"{name}: {type(obj).__name__} has no state_dict/load_state_dict.")
        if name in self._stateful:
            raise ValueError(f"A state named {name!r} is already registered.")
        self._stateful[name] = obj

    def record(self, **metrics: Any) -> None:
        """Adds entries to the metrics row of the current batch (for ``round_end`` ops)."""
        self._recorded.update(metrics)

    def log_now(self) -> dict[str, Any]:
        """Runs the ``log`` ops now on a row of the counters (``frames``, ``updates``, ``round``) and what was
        :meth:`record`-ed since the last row: a measurement outside a batch, e.g. an evaluation before training
        starts. Returns the row.

        Examples:
            >>> # trainer.record(eval_accomplish_rate=0.7); trainer.log_now()
            >>> # -> {"frames": 0, "updates": 0, "round": 0, "eval_accomplish_rate": 0.7} to every log op
            >>> # (tests/test_trainer.py, on a real trainer)
        """
        return self._log_row({"frames": self.frames, "updates": self.updates, "round": self.rounds})

    def _log_row(self, row: dict[str, Any]) -> dict[str, Any]:
        """``row`` with what was :meth:`record`-ed since the last row, through the ``log`` ops."""
        row.update(self._recorded)
        self._recorded = {}
        for _, op in self._ops["log"]:
            op(self, row)
        return row

    def ops(self, stage: str) -> list[str]:
        """Names of the ops registered at ``stage``, in call order."""
        return [name for name, _ in self._ops[stage]]

    def request_stop(self, reason: str = "stop requested") -> None:
        """Asks :meth:`train` to stop at the end of the current batch (its updates, round end and log
        done) with :class:`TrainingInterrupted`; safe to call from a signal handler."""
        self.stop_reason = reason

    # ------------------------------------------------------------------ state
    def counters(self) -> dict[str, Any]:
        return {
            "frames": self.frames,
            "updates": self.updates,
            "rounds": self.rounds,
            "batches": self.batches,
            "updates_in_round": self.updates_in_round,
            "update_credit": self._update_credit,
            "wall_s": self.wall_time,
            "elapsed_s": self.elapsed_time,
            "collect_s": self._time_collect,
            "update_s": self._time_update,
            "untimed_frames": self._throughput_base[0],
            "untimed_updates": self._throughput_base[1],
        }

    def state_dict(self) -> dict[str, Any]:
        """Counters, every registered state and the global RNG states."""
        return {
            "counters": self.counters(),
            "states": {name: obj.state_dict() for name, obj in self._stateful.items()},
            "rng": rng_state(),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restores :meth:`state_dict` (call it last, after building everything: it sets the RNGs)."""
        counters = state["counters"]
        self.frames = int(counters["frames"])
        self.updates = int(counters["updates"])
        self.rounds = int(counters["rounds"])
        self.batches = int(counters["batches"])
        self.updates_in_round = int(counters["updates_in_round"])
        self._update_credit = float(counters["update_credit"])
        self._wall = float(counters["wall_s"])
        # a checkpoint without process time (no elapsed_s): its training loop's seconds are the best lower bound
        self.elapsed_before = float(counters.get("elapsed_s", counters["wall_s"]))
        self._restore_timing(counters)
        missing = set(self._stateful) - set(state["states"])
        if missing:
            raise KeyError(f"checkpoint lacks the states {sorted(missing)}.")
        for name, obj in self._stateful.items():
            obj.load_state_dict(state["states"][name])
        set_rng_state(state["rng"])

    def _restore_timing(self, counters: dict[str, Any]) -> None:
        """Collection and update seconds of the runs before this one, so that :attr:`throughput` covers
        the whole run; a checkpoint without them makes it cover this process's part only."""
        if "collect_s" in counters and "update_s" in counters:
            self._time_collect = float(counters["collect_s"])
            self._time_update = float(counters["update_s"])
            self._throughput_base = (int(counters.get("untimed_frames", 0)), int(counters.get("untimed_updates", 0)))
        else:
            self._time_collect = self._time_update = 0.0
            self._throughput_base = (self.frames, self.updates)

    @property
    def wall_time(self) -> float:
        """Seconds spent in :meth:`train` (summed over resumed runs)."""
        return self._wall + (time.perf_counter() - self._t0 if getattr(self, "_t0", None) else 0.0)

    @property
    def elapsed_time(self) -> float:
        """Wall seconds of the whole run so far: the earlier processes' (up to their last checkpoint) and
        this one's since the trainer was built; unlike :attr:`wall_time`, start-up, evaluations outside
        :meth:`train` and checkpointing count too."""
        return self.elapsed_before + time.perf_counter() - self._created

    def round_line(self) -> str:
        """The line printed at a round end: counters, speed, elapsed time and the bar's postfix.

        Examples:
            >>> # after the third round of a 60 000-frame run:
            >>> # round 3: 6000/60000 frames, 2980 updates (25.1/s), 4.1 min | subgoal 12/59, eval 0.42
        """
        speed = self.throughput["updates_per_s"]
        line = (
            f"round {self.rounds}: {self.frames}/{self.total_frames} frames, {self.updates} updates "
            f"({speed:.1f}/s), {self.wall_time / 60:.1f} min"
        )
        if self.postfix:
            line += " | " + ", ".join(f"{key} {value}" for key, value in self.postfix.items())
        return line

    def _print_round_line(self, bar: Any) -> None:
        line = self.round_line()
        if not bar.disable:
            bar.write(line, file=sys.stderr)  # above the bar, which is redrawn below it
            return
        sys.stderr.write(line + "\n")
        sys.stderr.flush()

    # ------------------------------------------------------------------ loop
    def _batches(self) -> Iterator[TensorDictBase]:
        iterator = iter(self.collector)
        while self.frames < self.total_frames:
            # a pure function of (seed, batch index, policy): exact resume
            self.collector.set_seed(self.seed + 7919 * self.batches)
            self.collector.reset()
            yield next(iterator)

    def _start_round_if_due(self) -> None:
        if self.clear_buffer_each_round and self.updates_in_round == 0 and len(self.online_buffer):
            self.online_buffer.empty()

    def _num_updates(self, frames: int) -> int:
        if len(self.online_buffer) < max(self.warmup_frames, 1):
            return 0
        self._update_credit += self.utd_ratio * frames
        n = math.floor(self._update_credit + 1e-9)
        self._update_credit -= n
        return n

    def _run_updates(self, n: int) -> dict[str, float]:
        sums: dict[str, float] = defaultdict(float)
        counts: dict[str, int] = defaultdict(int)
        for _ in range(n):
            with map_each_input_once():  # the batch's observations through each input map once
                losses = self.update_step(self)
            self.updates += 1
            self.updates_in_round += 1
            for _, op in self._ops["post_update"]:
                op(self, losses)
            for key, value in losses.items():
                sums[key] += float(value)
                counts[key] += 1
        return {key: total / counts[key] for key, total in sums.items()}

    def _end_round(self) -> None:
        for _, op in self._ops["round_end"]:
            op(self)
        self.rounds += 1
        self.updates_in_round = 0
        for _, op in self._ops["post_round"]:
            op(self)

    def train(self) -> None:
        """Runs until ``total_frames`` frames are collected, then the ``train_end`` ops."""
        from tqdm.auto import tqdm

        self._t0 = time.perf_counter()
        bar = tqdm(total=self.total_frames, initial=self.frames, disable=not self.progress_bar, unit="frame")
        try:
            batches = self._batches()
            while self.frames < self.total_frames:
                self._start_round_if_due()
                t = time.perf_counter()
                batch = next(batches)
                for _, op in self._ops["batch_process"]:
                    batch = op(batch)
                self.online_buffer.extend(batch.reshape(-1))
                frames = batch.numel()
                self.frames += frames
                self.batches += 1
                t_collect = time.perf_counter() - t
                t = time.perf_counter()
                n_updates = self._num_updates(frames)
                losses = self._run_updates(n_updates)
                t_update = time.perf_counter() - t
                self._time_collect += t_collect
                self._time_update += t_update
                if losses:
                    self.last_losses = losses
                row = {
                    "frames": self.frames,
                    "updates": self.updates,
                    "round": self.rounds,
                    "collect_fps": frames / max(t_collect, 1e-9),
                    "updates_per_s": n_updates / t_update if n_updates else 0.0,
                    **losses,
                }
                round_ended = self.updates_in_round >= self.updates_per_round
                if round_ended:
                    self._end_round()
                self._log_row(row)
                bar.update(frames)
                if self.postfix:
                    bar.set_postfix(self.postfix, refresh=False)
                if round_ended and self.round_lines:
                    self._print_round_line(bar)
                if self.stop_reason is not None:
                    raise TrainingInterrupted(self.stop_reason)
        finally:
            bar.close()
            self._wall += time.perf_counter() - self._t0
            self._t0 = None
        for _, op in self._ops["train_end"]:
            op(self)

    @property
    def throughput(self) -> dict[str, float]:
        """Frames per second of collection and updates per second of optimisation, over the whole run
        (resumed parts included); ``frames_per_s`` is frames over :attr:`wall_time`."""
        frames_base, updates_base = self._throughput_base
        return {
            "collect_fps": (self.frames - frames_base) / self._time_collect if self._time_collect else 0.0,
            "updates_per_s": (self.updates - updates_base) / self._time_update if self._time_update else 0.0,
            "frames_per_s": self.frames / max(self.wall_time, 1e-9),
        }
