"""Running a sweep's cells: each one its recipe in a subprocess, as a Ray Tune trial (local Ray by default, or
an existing cluster), stopped without losing work on SIGTERM or Ctrl-C (local Ray, Linux:
:mod:`torchrl_csirl.run.processes`).

The cells come from :func:`torchrl_csirl.sweep.plan.plan_cells`; the trial workers import
:func:`run_cell` from this module.

Examples:
    >>> sweep_command(["--seeds", "0"]).endswith(" --seeds 0")
    True
"""
from __future__ import annotations

import contextlib
import json
import os
import shlex
from typing import Any

from torchrl_csirl.run.processes import StopCellsOnSigterm, run_cell_process, tune_sigint_handler_off
from torchrl_csirl.run.run import running_command
from torchrl_csirl.sweep.plan import Cell

__all__ = ["run_cell", "run_sweep", "sweep_command"]


def run_cell(config: dict[str, Any]) -> None:
    """The Ray Tune trainable: one cell's recipe in a subprocess; reports its final summary.

    The recipe's output goes to ``<output-dir>/logs/<cell>.log``; a failed recipe fails the trial
    with the end of that log.
    """
    from ray import tune

    cell = config["cell"]
    log_path = cell["log"]
    os.makedirs(os.path.dirname(log_path), exist_ok=True)
    env = {**os.environ, "WANDB_SILENT": "true", "MPLBACKEND": "Agg"}
    returncode, stdout = run_cell_process(cell["command"], log_path, env=env, cwd=cell["cwd"])
    if returncode != 0:
        with open(log_path) as f:
            tail = f.read()[-2000:]
        raise RuntimeError(f"{cell['name']}: exit status {returncode}; see {log_path}:\n{tail}")
    summary = json.loads(stdout.strip().splitlines()[-1])
    metrics = {k: summary[k] for k in ("accomplish_rate", "normalized_accomplish_rate", "success_rate", "crash_rate", "return",
                                       "frames", "updates", "wall_s") if summary.get(k) is not None}
    tune.report({**metrics, "run_dir": summary["run_dir"]})


def sweep_command(argv: list[str]) -> str:
    """The command line that runs the sweep of ``argv`` again (it continues the unfinished cells), with the
    running script (``python recipes/benchmark.py``) or module (``python -m ...``).

    Examples:
        >>> sweep_command(["--seeds", "0", "1", "eval.tag=a b"]).endswith(" --seeds 0 1 'eval.tag=a b'")
        True
    """
    return shlex.join([*running_command(os.path.join("recipes", "benchmark.py")), *argv])


def run_sweep(cells: list[Cell], output_dir: str, *, address: str | None, max_concurrent: int,
              cpus_per_trial: float, command: str | None = None) -> list[str]:
    """Runs ``cells`` as Ray Tune trials; returns the names of the failed cells. On local Ray, SIGTERM or
    Ctrl-C checkpoints the running cells and exits, naming ``command`` to continue (:class:`StopCellsOnSigterm`)."""
    import ray
    from ray import tune

    # the trial workers import this module (``run_cell``) from the installed package; a PYTHONPATH
    # set by the user travels with them
    worker_env = {"RAY_worker_niceness": "0"}
    if os.environ.get("PYTHONPATH"):
        worker_env["PYTHONPATH"] = os.environ["PYTHONPATH"]
    ray.init(address=address, num_cpus=None if address else max(1, int(max_concurrent * cpus_per_trial)),
             include_dashboard=False, ignore_reinit_error=True, log_to_driver=False,
             # Ray starts its workers at niceness 15: a trial's recipe would then get the CPU only
             # when nothing else wants it (on a shared machine, 6 frames/s instead of ~1 000)
             runtime_env={"env_vars": worker_env})
    local = address is None and not os.environ.get("RAY_ADDRESS")  # the cells run here: SIGTERM stops them first
    try:  # the stopper after ray.init, which installs a SIGTERM handler of its own; Tune's SIGINT handler off
        with (StopCellsOnSigterm(output_dir, shutdown=ray.shutdown, command=command) if local else contextlib.nullcontext(),
              tune_sigint_handler_off() if local else contextlib.nullcontext()):
            space = [{"name": c.name, "command": list(c.command), "cwd": os.getcwd(),
                      "log": os.path.join(output_dir, "logs", f"{c.name}.log")} for c in cells]
            tuner = tune.Tuner(
                tune.with_resources(run_cell, {"cpu": cpus_per_trial}),
                param_space={"cell": tune.grid_search(space)},
                tune_config=tune.TuneConfig(max_concurrent_trials=max_concurrent),
                run_config=tune.RunConfig(name="benchmark", storage_path=os.path.join(output_dir, "ray"), verbose=0),
            )
            results = tuner.fit()
            return [r.config["cell"]["name"] for r in results if r.error is not None]
    finally:
        ray.shutdown()

