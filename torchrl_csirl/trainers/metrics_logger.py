"""Metrics of a run: always a JSON-lines and a CSV file in the run directory, plus a TorchRL logger."""
from __future__ import annotations

import csv
import json
import math
import os
from typing import Any

__all__ = ["MetricsLogger"]

BACKENDS = ("wandb", "csv", "none")


def _scalar(value: Any) -> Any:
    if hasattr(value, "item"):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    return value


class MetricsLogger:
    """Writes every metrics row to ``metrics.jsonl`` and ``metrics.csv`` and to a TorchRL logger.

    Both files grow row by row as the rows come (a killed run keeps what it logged):
    ``metrics.jsonl`` one JSON object per row, ``metrics.csv`` one line per row (one column per key;
    a row bringing a new key rewrites the file with the new column). With ``backend="wandb"`` the
    rows also go to TorchRL's W&B logger (:func:`torchrl.record.loggers.get_logger`, offline unless
    ``wandb_mode="online"``); ``"csv"`` and ``"none"`` keep the two files only.

    Args:
        run_dir: the run directory.
        backend: ``"wandb"``, ``"csv"`` or ``"none"``.
        exp_name: experiment name.
        config: the run configuration (sent to W&B).
        wandb_mode: ``"offline"`` (default, no network) or ``"online"``.
        project: W&B project.
        step_key: the row entry used as the logging step.
        resume_frames: on resume, rows beyond this step are dropped from ``metrics.jsonl`` (they
            were logged after the checkpoint the run continues from).

    Examples:
        >>> import tempfile, json
        >>> d = tempfile.mkdtemp()
        >>> log = MetricsLogger(d, backend="none")
        >>> log.log({"frames": 10, "loss_actor": 0.5})
        >>> log.log({"frames": 20, "loss_actor": 0.25})
        >>> open(f"{d}/metrics.csv").read().splitlines()
        ['frames,loss_actor', '10,0.5', '20,0.25']
    """

    def __init__(
        self,
        run_dir: str | os.PathLike,
        backend: str = "csv",
        exp_name: str = "csirl",
        config: dict[str, Any] | None = None,
        *,
        wandb_mode: str = "offline",
        project: str = "torchrl-csirl",
        step_key: str = "frames",
        resume_frames: int | None = None,
    ) -> None:
        if backend not in BACKENDS:
            raise ValueError(f"logger backend must be one of {BACKENDS}, got {backend!r}.")
        self.run_dir = os.fspath(run_dir)
        os.makedirs(self.run_dir, exist_ok=True)
        self.jsonl_path = os.path.join(self.run_dir, "metrics.jsonl")
        self.csv_path = os.path.join(self.run_dir, "metrics.csv")
        self.step_key = step_key
        self.rows: list[dict[str, Any]] = []
        if resume_frames is not None and os.path.exists(self.jsonl_path):
            with open(self.jsonl_path) as f:
                rows = [json.loads(line) for line in f if line.strip()]
            self.rows = [r for r in rows if r.get(step_key, 0) <= resume_frames]
        with open(self.jsonl_path, "w") as f:
            f.writelines(json.dumps(r) + "\n" for r in self.rows)
        self.backend = backend
        self._csv_columns: list[str] = []
        if self.rows:  # a resumed run: the rows kept, as metrics.jsonl
            self.write_csv()
        self.logger = self._make_logger(backend, exp_name, config, wandb_mode, project)

    def _make_logger(self, backend: str, exp_name: str, config: dict[str, Any] | None, mode: str, project: str):
        if backend != "wandb":  # metrics.csv is the CSV record: no second one
            return None
        from torchrl.record.loggers import get_logger

        if backend == "wandb":
            if mode not in ("offline", "online", "disabled"):
                raise ValueError(f"wandb mode must be offline, online or disabled, got {mode!r}.")
            logger = get_logger(
                "wandb", logger_name=self.run_dir, experiment_name=exp_name,
                wandb_kwargs={"mode": mode, "offline": mode == "offline", "project": project,
                              "config": config or {}, "log_env_packages": False},
            )
            return logger

    def log(self, row: dict[str, Any]) -> None:
        """Appends a row (numbers, tensors of one element) and sends its scalars to the logger."""
        row = {key: _scalar(value) for key, value in row.items()}
        self.rows.append(row)
        with open(self.jsonl_path, "a") as f:
            f.write(json.dumps(row) + "\n")
        self._append_csv(row)
        if self.logger is not None:
            step = int(row.get(self.step_key, len(self.rows)))
            for key, value in row.items():
                if isinstance(value, (int, float)) and key != self.step_key:
                    self.logger.log_scalar(key, value, step=step)

    def log_video(self, path: str | os.PathLike, key: str = "test_episode", step: int | None = None) -> None:
        """Sends a video file (``.mp4`` or ``.gif``) to W&B, with ``step`` as the step entry; the other
        backends keep the file where it is (TorchRL's CSV logger would need torchcodec for mp4)."""
        if self.backend != "wandb" or self.logger is None:
            return
        import wandb

        payload: dict[str, Any] = {key: wandb.Video(os.fspath(path), format=os.path.splitext(path)[1].lstrip("."))}
        if step is not None:
            payload[self.step_key] = step
        self.logger.experiment.log(payload)

    def _append_csv(self, row: dict[str, Any]) -> None:
        if any(key not in self._csv_columns for key in row):
            self.write_csv()  # a new column: the header changes
            return
        with open(self.csv_path, "a", newline="") as f:
            csv.DictWriter(f, fieldnames=self._csv_columns, lineterminator="\n").writerow(row)

    def write_csv(self) -> None:
        """Rewrites ``metrics.csv`` from the rows (union of keys, in first-seen order)."""
        columns: dict[str, None] = {}
        for row in self.rows:
            columns.update(dict.fromkeys(row))
        tmp = self.csv_path + ".tmp"
        with open(tmp, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(columns), lineterminator="\n")
            writer.writeheader()
            writer.writerows(self.rows)
        os.replace(tmp, self.csv_path)
        self._csv_columns = list(columns)

    def close(self) -> None:
        """Writes the CSV and finishes the W&B run, if any."""
        self.write_csv()
        experiment = getattr(self.logger, "experiment", None)
        if self.backend == "wandb" and experiment is not None:
            experiment.finish()
