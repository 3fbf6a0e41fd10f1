"""A run's life outside the training loop: its directory, device, resume point, summary and exit.

Shared by every recipe: a run directory is never silently replaced, ``checkpoint.resume`` points at
a run directory or a checkpoint, the final summary goes to ``summary.json`` and, last, to stdout as
one JSON line, and :func:`run_script` turns the known errors into one ``error:`` line and an exit
status (2: bad configuration or data, 3: training diverged) while keeping logs and checkpoints.
"""
from __future__ import annotations

import json
import os
import shlex
import shutil
import signal
import sys
import time
import traceback
from collections.abc import Callable
from typing import Any

import torch

from torchrl_csirl.run.config import ConfigError

__all__ = [
    "ExpertDataError",
    "expert_accomplish_rate",
    "make_run_dir",
    "resolve_device",
    "resolve_resume",
    "resume_command",
    "running_command",
    "run_script",
    "stop_with_checkpoint",
    "write_summary",
]

#: files whose presence marks a directory as holding a run
RUN_MARKERS = ("config.yaml", "metrics.jsonl", "summary.json", "checkpoints")


class ExpertDataError(ValueError):
    """A missing, malformed or mismatched expert file."""


def holds_a_run(path: str) -> bool:
    """Whether ``path`` already holds a run's artefacts."""
    return os.path.isdir(path) and any(os.path.exists(os.path.join(path, m)) for m in RUN_MARKERS)


def make_run_dir(output_dir: str, exp_name: str | None, default_name: str, overwrite: bool = False) -> str:
    """``<output_dir>/<exp_name>``, created; never another run's directory unless ``overwrite``.

    With no ``exp_name`` the name is ``default_name`` (made unique with a ``-2``, ``-3``... suffix).
    A named directory that already holds a run is refused with a :class:`ConfigError` that says how
    to continue it or replace it.

    Examples:
        >>> import tempfile
        >>> out = tempfile.mkdtemp()
        >>> a = make_run_dir(out, None, "merge-csirl-s0")
        >>> open(os.path.join(a, "config.yaml"), "w").close()
        >>> os.path.basename(make_run_dir(out, None, "merge-csirl-s0"))
        'merge-csirl-s0-2'
        >>> make_run_dir(out, "merge-csirl-s0", "")  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        torchrl_csirl.run.config.ConfigError: logger.exp_name=merge-csirl-s0: .../merge-csirl-s0 already holds a run; ...
    """
    if exp_name:
        run_dir = os.path.abspath(os.path.join(output_dir, exp_name))
        if holds_a_run(run_dir):
            if not overwrite:
                raise ConfigError(
                    f"logger.exp_name={exp_name}: {run_dir} already holds a run; continue it with "
                    f"checkpoint.resume={run_dir}, choose another logger.exp_name, or replace it with "
                    "logger.overwrite=true")
            shutil.rmtree(run_dir)
    else:
        base = os.path.abspath(os.path.join(output_dir, default_name))
        run_dir, k = base, 1
        while holds_a_run(run_dir):
            k += 1
            run_dir = f"{base}-{k}"
    os.makedirs(run_dir, exist_ok=True)
    return run_dir


def default_run_name(scenario: str, method: str, seed: int) -> str:
    """``<scenario>-<method>-s<seed>-<date>-<time>``."""
    return f"{scenario}-{method}-s{seed}-{time.strftime('%Y%m%d-%H%M%S')}"


def resolve_resume(path: str) -> tuple[str, str]:
    """(run directory, checkpoint directory) of ``checkpoint.resume`` (a run or a checkpoint).

    Raises:
        ConfigError: when no checkpoint or no ``config.yaml`` is there.
    """
    path = os.path.abspath(os.path.expanduser(path))
    if os.path.isfile(os.path.join(path, "state.pt")):
        checkpoint, run_dir = path, os.path.dirname(os.path.dirname(path))
    else:
        run_dir, checkpoint = path, os.path.join(path, "checkpoints", "last")
    if not os.path.isfile(os.path.join(checkpoint, "state.pt")):
        raise ConfigError(f"checkpoint.resume={path}: no checkpoint there (looked for {checkpoint}/state.pt)")
    if not os.path.isfile(os.path.join(run_dir, "config.yaml")):
        raise ConfigError(f"checkpoint.resume={path}: {run_dir} has no config.yaml")
    return run_dir, checkpoint


def running_command(default_script: str = "recipes/<recipe>.py") -> list[str]:
    """How this process was started, to print a command that runs it again: ``["python", "-m", <module>]``
    or ``["python", <script>]`` (relative to the working directory when it is inside it).

    Examples:
        >>> running_command()[0]
        'python'
    """
    main_module = sys.modules.get("__main__")
    spec = getattr(main_module, "__spec__", None)
    if spec is not None and spec.name and spec.name != "__main__":  # python -m torchrl_csirl.scripts.<name>
        return ["python", "-m", spec.name]
    script = getattr(main_module, "__file__", None) or default_script
    relative = os.path.relpath(script)
    return ["python", script if relative.startswith("..") else relative]


def resume_command(run_dir: str) -> str:
    """The command that continues the run of ``run_dir`` with the running recipe script.

    Examples:
        >>> resume_command("/tmp/runs/merge-csirl-s0").endswith(" checkpoint.resume=/tmp/runs/merge-csirl-s0")
        True
    """
    return shlex.join([*running_command(), f"checkpoint.resume={run_dir}"])


def stop_with_checkpoint(checkpoint: str, run_dir: str, signum: int | None) -> None:
    """Says where an interrupted run's checkpoint is and how to resume it, then exits with ``128 + signum``
    (130 for Ctrl-C, 143 for SIGTERM)."""
    signum = signum or signal.SIGINT
    print(f"{signal.Signals(signum).name}: training stopped; checkpoint saved at {checkpoint}\n"
          f"resume with: {resume_command(run_dir)}", file=sys.stderr, flush=True)
    sys.exit(128 + signum)


def resolve_device(name: str) -> torch.device:
    """``device``: ``cpu``, ``cuda`` (or ``cuda:K``), or ``auto`` (CUDA when present).

    Examples:
        >>> resolve_device("cpu")
        device(type='cpu')
    """
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name.startswith("cuda") and not torch.cuda.is_available():
        raise ConfigError(f"device={name}: CUDA is not available on this machine (use device=cpu or device=auto)")
    return torch.device(name)


def expert_accomplish_rate(metadata: dict) -> float | None:
    """Mean accomplish rate of the demonstrations recorded in traffic (None if not recorded).

    Examples:
        >>> expert_accomplish_rate({"episodes": [{"accomplish_rate": 0.9}, {"accomplish_rate": 1.0, "empty_road": True}]})
        0.9
    """
    episodes = [e for e in metadata.get("episodes", []) if isinstance(e, dict) and "accomplish_rate" in e]
    traffic = [e["accomplish_rate"] for e in episodes if not e.get("empty_road")]
    rates = traffic or [e["accomplish_rate"] for e in episodes]
    return sum(rates) / len(rates) if rates else None


def write_summary(summary: dict[str, Any], run_dir: str) -> dict[str, Any]:
    """Writes ``summary.json`` and prints the summary as the last stdout line (JSON)."""
    from torchrl_csirl.trainers.metrics_logger import _scalar

    summary = {k: _scalar(v) for k, v in summary.items()}
    with open(os.path.join(run_dir, "summary.json"), "w") as f:
        json.dump(summary, f, indent=2)
    print(json.dumps(summary))
    return summary


def run_script(main: Callable[[], Any], known_errors: tuple[type[BaseException], ...] = ()) -> None:
    """Runs a recipe's ``main`` as a script: SIGTERM unwinds like Ctrl-C (workers shut down, logs
    and checkpoints kept); a known error is one ``error:`` line and exit status 2 (3 for a
    diverged training; a collector worker's failure is a known error). ``CSIRL_TRACEBACK=1`` shows the
    traceback too."""
    from torchrl_csirl.trainers import CheckpointError, CollectorWorkerError, TrainingDivergedError

    signal.signal(signal.SIGTERM, lambda signum, frame: sys.exit(128 + signum))
    errors = (ConfigError, ExpertDataError, TrainingDivergedError, CheckpointError, CollectorWorkerError,
              FileNotFoundError, *known_errors)
    try:
        main()
    except errors as error:
        print(f"error: {error}", file=sys.stderr)
        if os.environ.get("CSIRL_TRACEBACK"):
            traceback.print_exc()
        sys.exit(3 if isinstance(error, TrainingDivergedError) else 2)
