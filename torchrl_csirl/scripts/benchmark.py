"""The paper's comparison: methods x scenarios x seeds as Ray Tune trials, and its table and curves.

Run the sweep (local Ray by default, one trial at a time: sized for a 2-core machine)::

    python recipes/benchmark.py --methods csirl bc sac --scenarios merge roundabout --seeds 0 1 2 \\
        --output-dir runs/benchmark [key=value ...] [method:key=value ...]

Each cell (method, scenario, seed) is one run of its recipe (``recipes/csirl_highway.py`` for
``csirl`` and ``csirl-b``, ``recipes/imitation_highway.py method=<name>`` for the others; on the
robotics tasks ``--scenarios relocate antmaze-umaze``, ``recipes/csirl_robotics.py`` and
``recipes/imitation_robotics.py``) in its own
process, in ``<output-dir>/<scenario>-<method>-s<seed>``, its output in ``<output-dir>/logs``. The
``expert`` row runs for the first seed only (the expert driver is deterministic). The
sweep is resumable: a cell whose ``summary.json`` exists is not run again, a cell with a checkpoint
continues from it (``checkpoint.resume``), any other leftover is replaced. ``key=value`` overrides
go to every cell; ``<method>:key=value`` or ``<recipe>:key=value`` (``csirl_highway``,
``imitation_highway``, ``csirl_robotics``, ``imitation_robotics``) to that method's or that
recipe's cells only. ``--address`` joins an
existing Ray cluster (``ray start --head`` on it first); ``--max-concurrent`` and
``--cpus-per-trial`` size the trials. Ctrl-C or SIGTERM to the sweep (its pid: ``<output-dir>/logs/sweep.pid``)
stops it without losing work: each running cell gets SIGTERM (it checkpoints at its next batch boundary) and the
sweep exits (status 130, 143) once they have, naming the command that continues it: the same one (local Ray, Linux:
:mod:`torchrl_csirl.launch.processes`).

Write the table (method rows x scenario columns, expert-normalised accomplish rate mean +- std over
seeds, the paper's Table I beside it; on the robotics tasks the test return, the paper's metric
there; Markdown and CSV) and one learning-curve figure per scenario or task (the paper's
Figures 6 and 7)::

    python recipes/benchmark.py report runs/benchmark [more folders or run dirs] [--out runs/benchmark/report]

See docs/benchmark.md.
"""
from __future__ import annotations

import argparse
import contextlib
import csv
import json
import os
import shlex
import sys
import textwrap
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from omegaconf import OmegaConf

from torchrl_csirl.envs import TASKS, task_names
from torchrl_csirl.launch.config import SCENARIO_NAMES, EvalConfig
from torchrl_csirl.launch.processes import StopCellsOnSigterm, SweepBusyError, run_cell_process, tune_sigint_handler_off
from torchrl_csirl.launch.run import running_command
from torchrl_csirl.launch.summaries import find_summaries, mean_std, welch_test

#: the table's rows, in the paper's order, and the recipe of each
METHOD_ORDER = ("expert", "random", "sac", "bc", "gail", "dac", "valuedice", "sqil", "iqlearn", "csirl-b", "csirl")
CSIRL_RECIPE, IMITATION_RECIPE = "csirl_highway", "imitation_highway"
#: the robotics tasks' recipes (the same learners on ``env.task=relocate | antmaze-umaze``)
CSIRL_ROBOTICS_RECIPE, IMITATION_ROBOTICS_RECIPE = "csirl_robotics", "imitation_robotics"
RECIPES = (CSIRL_RECIPE, IMITATION_RECIPE, CSIRL_ROBOTICS_RECIPE, IMITATION_ROBOTICS_RECIPE)
#: CSIRL and its ablations (issue 17, section 4): cells of the CSIRL recipe with these switches
CSIRL_METHODS: dict[str, tuple[str, ...]] = {
    "csirl": (),
    "csirl-b": ("csirl.intrinsic=false",),  # no learned reward r_w
    "csirl-nocur": ("csirl.fixed_subgoal=true",),  # no curriculum: the subgoal is the last state
    "csirl-noexp": ("replay_buffer.expert_fraction=0",),  # no expert transitions in the SAC batch
    # not an ablation: CSIRL with TD3+BC-style cloning on its actor, the setting that learns Relocate
    # (docs/studies/index.md "Relocate and AntMaze: behavioural cloning against CSIRL")
    "csirl-bc": ("csirl.actor_bc_coef=10",),
}
#: the ablation and variant rows (not in the paper's table, so not in a default sweep): after csirl in a report
ABLATIONS = ("csirl-nocur", "csirl-noexp", "csirl-bc")
REFERENCE_METHODS = ("random", "expert")
#: methods whose run does not depend on the seed (the expert driver is deterministic): first seed only
SEED_FREE_METHODS = ("expert",)
#: the table's columns, in the paper's order
SCENARIO_ORDER = ("highway-fast", "merge", "intersection", "roundabout")
#: the robotics table's columns (the paper's Figure 7), scored by the test return
ROBOTICS_ORDER = ("antmaze-umaze", "relocate")
#: the locomotion table's columns (beyond the paper: gymnasium's MuJoCo tasks, where the baselines' own papers
#: published their results), scored by the test return and the expert-normalised return
LOCOMOTION_ORDER = ("hopper", "halfcheetah")
#: the locomotion tasks' names on the pages
LOCOMOTION_TITLES = {"hopper": "Hopper", "halfcheetah": "HalfCheetah"}
#: the methods of the paper's robotics comparison (Figure 7: curves, no table; SPEC section 4)
PAPER_ROBOTICS_METHODS = ("sqil", "dac", "valuedice", "iqlearn", "csirl")

#: every cell's budget (environment frames) per scene: the one place the tables' budget comes from. A sweep
#: gives each cell ``collector.total_frames=<budget>`` (before the user's overrides, which win) and the
#: report's captions state it; a row whose records ran another budget is marked in its cells. Every row of a
#: scene's column is compared at the same budget (the roundabout's own default for CSIRL, 110 000 frames, is
#: the junction study's: docs/studies/junctions.md#a-longer-budget)
TABLE_BUDGETS: dict[str, int] = {scene: 60_000 for scene in (*SCENARIO_ORDER, *ROBOTICS_ORDER)}
#: the locomotion tasks: 300 000 frames (the issue's cap). The published baselines report at 100 000 frames with
#: 5 updates per frame (ValueDICE), about 500 000 with 1 (IQ-Learn's code) or on curves to 1 000 000 (DAC):
#: none documents a plateau below the cap (docs/benchmark.md#published-results)
TABLE_BUDGETS.update({task: 300_000 for task in LOCOMOTION_ORDER})

#: what a task's cells need besides the budget (before the user's overrides). The locomotion tasks: 1 000-step
#: episodes need 1 000 frames per worker and batch (the robotics scripts' 1 400 would cut them); one expert
#: trajectory, the protocol of the published table beside ours (IQ-Learn's Table 3, also ValueDICE's); an
#: evaluation and a checkpoint every 5 rounds (10 000 updates: 10 validation episodes of 1 000 steps each); no
#: video of every cell (1 000 frames each; ``recipes/watch.py`` films a run); ValueDICE on standardised states, as
#: its authors' code runs MuJoCo (docs/baselines.md, "Standardised states"); IQ-Learn as its authors' MuJoCo
#: commands run it: the regulariser at the policy's actions, the initial-state term per task (``v0`` on the
#: Hopper, ``value`` on the HalfCheetah); DAC and ValueDICE on the Hopper with their papers' single absorbing state
#: (``absorbing_observation=placeholder``: the Hopper's expert never falls, so the state is the learner's alone; the
#: HalfCheetah never terminates), ValueDICE's with its code's 10 absorbing self-loops per learner termination
#: (``self_loops_per_termination=10``, ``absorbing_per_episode`` there; DAC keeps one, its paper's replay buffer:
#: docs/benchmark.md, "MuJoCo locomotion"). Every method updates at the
#: project's rate, ``optim.utd_ratio=0.5`` (150 000 updates): docs/benchmark.md#published-results compares the updates
TASK_OVERRIDES: dict[str, tuple[str, ...]] = {
    task: ("collector.frames_per_batch=2000", "expert.num_trajectories=1", "eval.every_rounds=5",
           "checkpoint.every_rounds=5", "eval.video=false", "valuedice:valuedice.normalize_states=true",
           "iqlearn:iqlearn.chi2_policy_actions=true")
    for task in LOCOMOTION_ORDER}
TASK_OVERRIDES["hopper"] += ("iqlearn:iqlearn.value_loss=v0", "dac:dac.absorbing_observation=placeholder",
                             "valuedice:valuedice.absorbing_observation=placeholder",
                             "valuedice:valuedice.self_loops_per_termination=10")

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


class BenchmarkError(ValueError):
    """Bad benchmark arguments (one line)."""


# ---------------------------------------------------------------------------------------- cells
def is_robotics(scenario: str) -> bool:
    """Whether ``scenario`` is scored by return and run by the robotics scripts: every task but the driving
    scenes (the robotics tasks, a task of your own, a gymnasium id).

    Examples:
        >>> is_robotics("relocate"), is_robotics("MountainCarContinuous-v0"), is_robotics("merge")
        (True, True, False)
    """
    return scenario not in SCENARIO_NAMES


def return_task_order(scenarios: list[str]) -> tuple[str, ...]:
    """The return-scored columns: the paper's robotics tasks first, then any other task, by name."""
    others = sorted({s for s in scenarios if is_robotics(s) and s not in ROBOTICS_ORDER})
    return (*ROBOTICS_ORDER, *others)


def is_gymnasium_id(scenario: str) -> bool:
    """A gymnasium id run as a task by configuration (its cells set ``env.gym_id``): not one of our task
    names, or registered by ``make_gymnasium_task`` in this process."""
    import gymnasium as gym

    if scenario in TASKS:
        return TASKS[scenario].family == "gymnasium"
    return scenario in gym.registry


def recipe_of(method: str, scenario: str = "merge") -> str:
    """The recipe that runs ``method`` on ``scenario``.

    Examples:
        >>> recipe_of("csirl-b"), recipe_of("sqil"), recipe_of("csirl", "relocate"), recipe_of("bc", "antmaze-umaze")
        ('csirl_highway', 'imitation_highway', 'csirl_robotics', 'imitation_robotics')
    """
    if is_robotics(scenario):
        return CSIRL_ROBOTICS_RECIPE if method in CSIRL_METHODS else IMITATION_ROBOTICS_RECIPE
    return CSIRL_RECIPE if method in CSIRL_METHODS else IMITATION_RECIPE


def score_key(scenario: str) -> str:
    """The summary field a scenario's table ranks by: the test return on the robotics tasks (the paper's
    metric there), the expert-normalised accomplish rate on the driving scenarios."""
    return "return" if is_robotics(scenario) else "normalized_accomplish_rate"


def known_methods() -> tuple[str, ...]:
    """Every method a cell can run: CSIRL's and those ``imitation_highway.py`` accepts."""
    from torchrl_csirl.launch.imitation import METHODS

    return (*CSIRL_METHODS, *METHODS)


@dataclass(frozen=True)
class Cell:
    """One run of the sweep: its name, directory and command line."""

    method: str
    scenario: str
    seed: int
    run_dir: str
    command: tuple[str, ...]
    resumed: bool

    @property
    def name(self) -> str:
        return os.path.basename(self.run_dir)


def split_overrides(overrides: list[str], methods: list[str], scenario: str = "merge") -> dict[str, list[str]]:
    """``method -> overrides`` on ``scenario`` from plain ``key=value`` (every cell) and ``<method|recipe>:key=value`` ones.

    Examples:
        >>> split_overrides(["seed=1", "bc:optim.lr=0.001", "csirl_highway:csirl.delta=3"], ["bc", "csirl"])
        {'bc': ['seed=1', 'optim.lr=0.001'], 'csirl': ['seed=1', 'csirl.delta=3']}
        >>> split_overrides(["csirl_highway:csirl.delta=3", "csirl_robotics:csirl.actor_bc_coef=10"], ["csirl"], "relocate")
        {'csirl': ['csirl.actor_bc_coef=10']}
    """
    out: dict[str, list[str]] = {m: [] for m in methods}
    for item in overrides:
        head, sep, rest = item.partition(":")
        if sep and "=" not in head:
            if head not in (*known_methods(), *RECIPES):
                raise BenchmarkError(f"{item}: {head!r} is neither a method ({', '.join(known_methods())}) nor "
                                     f"a recipe ({', '.join(RECIPES)})")
            for m in methods:
                if head in (m, recipe_of(m, scenario)):
                    out[m].append(rest)
        else:
            for m in methods:
                out[m].append(item)
    return out


def has_checkpoint(run_dir: str) -> bool:
    return os.path.isfile(os.path.join(run_dir, "checkpoints", "last", "state.pt"))


def table_overrides(scenario: str) -> list[str]:
    """The overrides that run a cell on ``scenario`` as its table does: its :data:`TABLE_BUDGETS` budget and its
    :data:`TASK_OVERRIDES` (none for another scenario); ``<method>:key=value`` ones go to that method's cells.

    Examples:
        >>> table_overrides("roundabout")
        ['collector.total_frames=60000']
        >>> table_overrides("hopper")[:2]
        ['collector.total_frames=300000', 'collector.frames_per_batch=2000']
    """
    budget = [f"collector.total_frames={TABLE_BUDGETS[scenario]}"] if scenario in TABLE_BUDGETS else []
    return [*budget, *TASK_OVERRIDES.get(scenario, ())]


def make_cell(method: str, scenario: str, seed: int, output_dir: str, overrides: list[str]) -> Cell | None:
    """The cell's command line, or None when its ``summary.json`` exists (done). ``overrides``: the cell's own
    (:func:`split_overrides` of the table's and the user's)."""
    run_dir = os.path.join(output_dir, f"{scenario}-{method}-s{seed}")
    if os.path.isfile(os.path.join(run_dir, "summary.json")):
        return None
    recipe = f"torchrl_csirl.scripts.{recipe_of(method, scenario)}"
    task = f"env.gym_id={scenario}" if is_gymnasium_id(scenario) else f"env.scenario={scenario}"
    args = [task, f"seed={seed}", "logger.progress_bar=false", *overrides]
    if method not in CSIRL_METHODS:
        args.insert(0, f"method={method}")
    else:
        args += CSIRL_METHODS[method]
    resumed = has_checkpoint(run_dir)
    if resumed:
        args = [f"checkpoint.resume={run_dir}", *(a for a in args if not a.startswith("method="))]
    else:  # a run killed before its first checkpoint is started again
        args += [f"logger.output_dir={output_dir}", f"logger.exp_name={os.path.basename(run_dir)}",
                 "logger.overwrite=true"]
    return Cell(method, scenario, seed, run_dir, (sys.executable, "-m", recipe, *args), resumed)


def plan_cells(methods: list[str], scenarios: list[str], seeds: list[int], output_dir: str,
               overrides: list[str]) -> tuple[list[Cell], list[str]]:
    """(cells to run, names of the cells already done)."""
    unknown = [m for m in methods if m not in known_methods()]
    if unknown:
        raise BenchmarkError(f"--methods {' '.join(unknown)}: unknown; known: {', '.join(known_methods())}")
    bad = [s for s in scenarios if s not in TASKS and not is_gymnasium_id(s)]
    if bad:
        raise BenchmarkError(f"--scenarios {' '.join(bad)}: unknown; known: {', '.join(task_names())}, or a gymnasium "
                             "id (a task of your own: its module's name as env.module=<module> among the overrides)")
    todo, done = [], []
    for scenario in scenarios:
        per_method = split_overrides([*table_overrides(scenario), *overrides], methods, scenario)
        for method in methods:
            for seed in seeds[:1] if method in SEED_FREE_METHODS else seeds:
                cell = make_cell(method, scenario, seed, output_dir, per_method[method])
                if cell is None:
                    done.append(f"{scenario}-{method}-s{seed}")
                else:
                    todo.append(cell)
    return todo, done


# ---------------------------------------------------------------------------------------- trials
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


def sweep_main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="benchmark.py", description="methods x scenarios x seeds as Ray Tune trials")
    available = [m for m in METHOD_ORDER if m in known_methods()]
    parser.add_argument("--methods", nargs="+", default=available, metavar="METHOD",
                        help=f"default: the paper's rows ({' '.join(available)}); CSIRL's ablations and variants: "
                             f"{' '.join(ABLATIONS)}")
    parser.add_argument("--scenarios", nargs="+", default=list(SCENARIO_ORDER), metavar="SCENARIO")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    parser.add_argument("--output-dir", default="runs/benchmark")
    parser.add_argument("--address", default=None, help="an existing Ray cluster (default: local Ray)")
    parser.add_argument("--max-concurrent", type=int, default=1, help="trials at once (default 1: a 2-core machine)")
    parser.add_argument("--cpus-per-trial", type=float, default=2.0, help="CPUs Ray reserves per trial")
    parser.add_argument("--dry-run", action="store_true", help="print the cells' commands, run nothing")
    parser.add_argument("overrides", nargs="*", help="key=value (every cell) or <method|recipe>:key=value")
    args = parser.parse_args(argv)
    output_dir = os.path.abspath(args.output_dir)
    cells, done = plan_cells(args.methods, args.scenarios, args.seeds, output_dir, args.overrides)
    print(f"{len(cells)} cells to run, {len(done)} already done ({output_dir})", file=sys.stderr)
    if args.dry_run:
        for cell in cells:
            print(" ".join(cell.command[1:]))
        return 0
    failed = run_sweep(cells, output_dir, address=args.address, max_concurrent=args.max_concurrent,
                       cpus_per_trial=args.cpus_per_trial, command=sweep_command(argv)) if cells else []
    print(json.dumps({"output_dir": output_dir, "ran": len(cells), "already_done": len(done), "failed": failed}))
    return 1 if failed else 0


# ---------------------------------------------------------------------------------------- report
def cell_method(summary: dict[str, Any], run_dir: str) -> str:
    """The row of a run: the label its directory's name ``<scenario>-<label>-s<seed>`` gives when
    that label is a known method (the ablations' runs say ``csirl`` in their summary) or extends the
    summary's method (``antmaze-umaze-csirl-bc-path-s0``, a ``csirl`` run, gets a row of its own
    instead of joining CSIRL's), else the summary's own method.

    Examples:
        >>> cell_method({"scenario": "merge", "seed": 0, "method": "csirl"}, "runs/merge-csirl-nocur-s0")
        'csirl-nocur'
        >>> cell_method({"scenario": "merge", "seed": 0, "method": "csirl"}, "runs/merge-csirl-mine-s0")
        'csirl-mine'
        >>> cell_method({"scenario": "merge", "seed": 0, "method": "csirl-b"}, "runs/merge-b-s0")
        'csirl-b'
    """
    method = summary["method"]
    prefix, suffix = f"{summary.get('scenario')}-", f"-s{summary.get('seed')}"
    name = os.path.basename(os.path.normpath(run_dir))
    if not (name.startswith(prefix) and name.endswith(suffix) and len(name) > len(prefix) + len(suffix)):
        return method
    label = name[len(prefix):-len(suffix)]
    return label if label in known_methods() or label.startswith(f"{method}-") else method


def read_runs(paths: list[str]) -> list[dict[str, Any]]:
    """The summaries of the finished runs under ``paths``, each with its run directory and method."""
    runs = []
    for path in find_summaries(paths):
        with open(path) as f:
            summary = json.load(f)
        summary["run_dir"] = os.path.dirname(path)
        summary["method"] = cell_method(summary, summary["run_dir"])
        runs.append(summary)
    return runs


def add_normalized_returns(runs: list[dict[str, Any]]) -> None:
    """Each locomotion run's ``normalized_return``: ``R / R_expert``, the reference the mean test return of the
    ``expert`` row on the same task (the same test episodes); none without that row. The convention of the
    published table beside ours (IQ-Learn's Table 3 gives raw returns and its expert's: R / R_expert).

    Examples:
        >>> runs = [{"method": "expert", "scenario": "hopper", "return": 3500.0},
        ...         {"method": "csirl", "scenario": "hopper", "return": 1750.0}]
        >>> add_normalized_returns(runs)
        >>> [r["normalized_return"] for r in runs]
        [1.0, 0.5]
    """
    for task in LOCOMOTION_ORDER:
        values = [float(r["return"]) for r in runs if r["scenario"] == task and r["method"] == "expert"]
        expert = sum(values) / len(values) if values else None
        expert = expert if expert is not None and expert > 0 else None  # no reference to divide by
        for run in (r for r in runs if r["scenario"] == task):
            ok = expert is not None and run.get("return") is not None
            run["normalized_return"] = float(run["return"]) / expert if ok else None
            best = best_evaluation(run["run_dir"]) if run.get("run_dir") else None
            run["best_eval_return"] = best
            run["normalized_best_eval_return"] = None if best is None or expert is None else best / expert


def best_evaluation(run_dir: str, key: str = "eval_env_return") -> float | None:
    """The highest periodic evaluation of a run (``key`` of its ``metrics.jsonl`` rows; none without any): the
    figure the published locomotion rows report (IQ-Learn's code keeps the best evaluation, SQIL's paper the best
    10-episode mean). A maximum over noisy evaluations sits above what one evaluation would expect, and the
    validation episodes that choose it score it too: an optimistic figure, beside the final policy's test return.

    Examples:
        >>> import tempfile
        >>> run_dir = tempfile.mkdtemp()
        >>> with open(os.path.join(run_dir, "metrics.jsonl"), "w") as f:
        ...     _ = f.write('{"frames": 2, "eval_env_return": 5.0}\\n{"frames": 4, "loss": 1.0}\\n'
        ...                 '{"frames": 6, "eval_env_return": 3.0}\\n')
        >>> best_evaluation(run_dir), best_evaluation(tempfile.mkdtemp())
        (5.0, None)
    """
    values = eval_curve(run_dir, key)[1]
    return max(values) if values else None


def table_rows(runs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per (method, scenario): expert-normalised and raw accomplish rate over seeds (on the locomotion
    tasks the expert-normalised return, :func:`add_normalized_returns`), cost, the paper's value."""
    add_normalized_returns(runs)
    groups: dict[tuple[str, str], list[dict]] = defaultdict(list)
    for run in runs:
        groups[(run["method"], run["scenario"])].append(run)
    rank = {m: i for i, m in enumerate((*METHOD_ORDER, *ABLATIONS))}
    column = {s: i for i, s in enumerate((*SCENARIO_ORDER, *return_task_order([r["scenario"] for r in runs])))}
    rows = []
    for (method, scenario), group in sorted(groups.items(), key=lambda kv: (rank.get(kv[0][0], 99), kv[0][0],
                                                                              column.get(kv[0][1], 99), kv[0][1])):
        row: dict[str, Any] = {"method": method, "scenario": scenario, "seeds": " ".join(
            str(s) for s in sorted(int(r["seed"]) for r in group)), "runs": len(group),
            "frames": " ".join(str(f) for f in sorted({int(r.get("frames") or 0) for r in group}))}
        for field in ("normalized_accomplish_rate", "accomplish_rate", "return", "normalized_return",
                      "normalized_best_eval_return", "best_eval_return", "success_rate", "crash_rate", "total_wall_s",
                      "updates_per_s"):
            values = [float(r[field]) for r in group if r.get(field) is not None]
            stats = mean_std(values) if values else {"mean": None, "std": None}
            row[f"{field}_mean"], row[f"{field}_std"] = stats["mean"], stats["std"]
        row["paper"] = PAPER_TABLE.get(method, {}).get(scenario)
        rows.append(row)
    add_comparison_to_csirl(rows, groups)
    return rows


def add_comparison_to_csirl(rows: list[dict[str, Any]], groups: dict[tuple[str, str], list[dict]]) -> None:
    """Each row's difference from ``csirl`` on its scenario (in its :func:`score_key`: expert-normalised on the
    driving scenarios, the return on the robotics tasks; Welch's t-test over seeds,
    :func:`~torchrl_csirl.launch.summaries.welch_test`): ``vs_csirl``, ``vs_csirl_t``, ``vs_csirl_beyond_noise``."""
    def values(method: str, scenario: str) -> list[float]:
        key = score_key(scenario)
        return [float(r[key]) for r in groups.get((method, scenario), []) if r.get(key) is not None]

    for row in rows:
        test = None
        if row["method"] != "csirl":
            test = welch_test(values(row["method"], row["scenario"]), values("csirl", row["scenario"]))
        row["vs_csirl"] = None if test is None else test["difference"]
        row["vs_csirl_t"] = None if test is None else test["t"]
        row["vs_csirl_beyond_noise"] = None if test is None else test["beyond_noise"]


def off_budget(row: dict[str, Any]) -> bool:
    """Whether a table row's training runs ran another budget than its scene's :data:`TABLE_BUDGETS` entry
    (beyond 1 %: a run ends on its last whole batch); reference rows (no training, 0 frames) never are.

    Examples:
        >>> off_budget({"scenario": "roundabout", "frames": "110000"}), off_budget({"scenario": "relocate", "frames": "60200"})
        (True, False)
        >>> off_budget({"scenario": "merge", "frames": "0"})
        False
    """
    budget = TABLE_BUDGETS.get(row["scenario"])
    frames = [int(f) for f in str(row.get("frames", "")).split() if int(f) > 0]
    return budget is not None and any(abs(f - budget) > budget / 100 for f in frames)


def budget_caption(scenarios: list[str]) -> str:
    """The budget of ``scenarios``' columns (:data:`TABLE_BUDGETS`), for a table's caption.

    Examples:
        >>> budget_caption(["merge", "roundabout"])
        'every row at 60 000 frames per run (benchmark.py TABLE_BUDGETS; a cell run at another budget says so)'
    """
    budgets = {s: f"{TABLE_BUDGETS[s]:,}".replace(",", " ") for s in scenarios if s in TABLE_BUDGETS}
    if not budgets:  # tasks outside the paper's tables: the sweep's own collector.total_frames
        return "every row at the budget its runs record (their summaries' frames)"
    if len(set(budgets.values())) == 1:
        text = f"{next(iter(budgets.values()))} frames per run"
    else:
        text = ", ".join(f"{s} {b}" for s, b in budgets.items()) + " frames per run"
    return f"every row at {text} (benchmark.py TABLE_BUDGETS; a cell run at another budget says so)"


def _has(row: dict[str, Any] | None, field: str) -> bool:
    """Whether a table row has a mean of ``field`` (some of its runs measured it)."""
    return row is not None and row.get(f"{field}_mean") is not None


def _pm(mean: float | None, std: float | None, fmt: str = ".2f") -> str:
    return "n/a" if mean is None else f"{mean:{fmt}} ± {std:{fmt}}"


def _score(row: dict[str, Any] | None, paper: float | None, field: str = "normalized_accomplish_rate",
           fmt: str = ".2f") -> str:
    """``mean ± std (n=runs) [paper]`` of a table row's ``field`` (the expert-normalised accomplish rate)."""
    ours = "—" if row is None else f"{_pm(row[f'{field}_mean'], row[f'{field}_std'], fmt)} (n={row['runs']})"
    if row is not None and off_budget(row):
        ours += f" ({row['frames']} frames)"
    return ours + (f" [{paper:.2f}]" if paper is not None else "")


def _outcomes(row: dict[str, Any] | None, second: str = "crash_rate") -> str:
    """``success / crash`` (or ``success / <second>``) of a table row, ``—`` where a rate is missing."""
    if row is None or row["success_rate_mean"] is None:
        return "—"
    other = row[f"{second}_mean"]
    return f"{row['success_rate_mean']:.2f} / " + ("—" if other is None else f"{other:.2f}")


def _cost(row: dict[str, Any] | None) -> str:
    """``wall min, updates/s`` of a table row, ``—`` without a wall time."""
    if row is None or row["total_wall_s_mean"] is None:
        return "—"
    ups = row["updates_per_s_mean"]
    return f"{row['total_wall_s_mean'] / 60:.1f} min" + (f", {ups:.0f} upd/s" if ups else "")


def _difference(row: dict[str, Any] | None, fmt: str = "+.3f") -> str:
    """``+d (t x)`` against ``csirl``, in bold beyond seed noise, ``—`` without a comparison."""
    if row is None or row.get("vs_csirl") is None:
        return "—"
    text = f"{row['vs_csirl']:{fmt}} (t {row['vs_csirl_t']:.1f})"
    return f"**{text}**" if row["vs_csirl_beyond_noise"] else text


def _method_table(caption: str, methods: list[str], scenarios: list[str],
                  entry: Callable[[str, str], str]) -> list[str]:
    """A caption, then method rows x scenario columns with ``entry(method, scenario)`` in each cell."""
    lines = [caption, "", "| method | " + " | ".join(scenarios) + " |", "|---" * (len(scenarios) + 1) + "|"]
    return lines + [f"| {m} | " + " | ".join(entry(m, s) for s in scenarios) + " |" for m in methods]


def _columns(rows: list[dict[str, Any]], order: tuple[str, ...]) -> tuple[list[str], list[str], dict]:
    """(scenario columns in ``order``, method rows, ``(method, scenario) -> row``) of the rows on those scenarios."""
    rows = [r for r in rows if r["scenario"] in order]
    scenarios = [s for s in order if any(r["scenario"] == s for r in rows)]
    return scenarios, list(dict.fromkeys(r["method"] for r in rows)), {(r["method"], r["scenario"]): r for r in rows}


def _comparison_table(rows: list[dict[str, Any]], scenarios: list[str], cell: dict, what: str,
                      fmt: str) -> list[str]:
    """The rows' difference from ``csirl`` (``what``), if any row has one."""
    compared = list(dict.fromkeys(r["method"] for r in rows if r["vs_csirl"] is not None and r["scenario"] in scenarios))
    if not compared:
        return []
    return [""] + _method_table(
        f"Difference from csirl ({what}; Welch's t over seeds; **bold**: beyond seed noise, two-sided 5 % at the "
        "Welch-Satterthwaite degrees of freedom).",
        compared, scenarios, lambda m, s: _difference(cell.get((m, s)), fmt))


def driving_tables(rows: list[dict[str, Any]]) -> list[str]:
    """The driving scenarios' tables: ``ours [paper]`` expert-normalised accomplish rate, success / crash, cost,
    difference from ``csirl`` (no lines without a driving row)."""
    scenarios, methods, cell = _columns(rows, SCENARIO_ORDER)
    if not scenarios:
        return []
    lines = _method_table("Expert-normalised test accomplish rate, mean ± std over seeds (the paper's Table I in brackets), "
                          f"{budget_caption(scenarios)}.",
                          methods, scenarios, lambda m, s: _score(cell.get((m, s)), PAPER_TABLE.get(m, {}).get(s)))
    lines += [""] + _method_table(
        "Success rate / crash rate of the test episodes, mean over seeds (an accomplish rate earned by "
        "driving far and then crashing or stalling is not expert-like).",
        methods, scenarios, lambda m, s: _outcomes(cell.get((m, s))))
    lines += [""] + _method_table(
        "Cost per run: wall time [min] (start-up and final evaluation included) and updates/s, mean over runs.",
        methods, scenarios, lambda m, s: _cost(cell.get((m, s))))
    return lines + _comparison_table(rows, scenarios, cell, "expert-normalised", "+.3f")


def _return_format(row: dict[str, Any] | None) -> str:
    """Whole numbers for Relocate-sized returns (thousands), two decimals for AntMaze's goal indicator."""
    return ".0f" if row is not None and row["return_mean"] is not None and abs(row["return_mean"]) >= 100 else ".2f"


def robotics_tables(rows: list[dict[str, Any]]) -> list[str]:
    """The robotics tasks' tables: test return (the paper's metric there), success / progress, cost,
    difference from ``csirl`` in return (no lines without a robotics row; the locomotion tasks have theirs)."""
    order = tuple(s for s in return_task_order([r["scenario"] for r in rows]) if s not in LOCOMOTION_ORDER)
    scenarios, methods, cell = _columns(rows, order)
    if not scenarios:
        return []
    if all(s in ROBOTICS_ORDER for s in scenarios):  # the paper's robotics tasks
        returns = ("Test return on the robotics tasks, mean ± std over seeds (the paper's metric there; its Figure 7 "
                   f"gives curves for {', '.join(PAPER_ROBOTICS_METHODS)}, no numbers: on Relocate only CSIRL's return "
                   f"is positive), {budget_caption(scenarios)}.")
        outcomes = ("Success rate (AntMaze: goal reached; Relocate: ball at the target) / progress (the accomplish "
                    "rate's analogue, docs/studies/robotics.md), mean over seeds.")
    else:
        returns = f"Test return (the environment's own reward), mean ± std over seeds, {budget_caption(scenarios)}."
        outcomes = ("Success rate / accomplish rate (the success rate where the task has no finish, "
                    "docs/own-task.md), mean over seeds.")
    lines = _method_table(returns, methods, scenarios,
                          lambda m, s: _score(cell.get((m, s)), None, "return", _return_format(cell.get((m, s)))))
    lines += [""] + _method_table(outcomes, methods, scenarios, lambda m, s: _outcomes(cell.get((m, s)), "accomplish_rate"))
    lines += [""] + _method_table(
        "Cost per run: wall time [min] (start-up and final evaluation included) and updates/s, mean over runs.",
        methods, scenarios, lambda m, s: _cost(cell.get((m, s))))
    return lines + _comparison_table(rows, scenarios, cell, "test return", "+.1f")


#: how far below its paper a baseline may sit before it is treated as a suspected implementation difference
#: (issue 58): a gap beyond it is bold in the report and explained in docs/benchmark.md#published-results
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


def _thousands(value: float, fmt: str = ".0f") -> str:
    """``3 252.5``: thousands apart by a space, a minus sign as on the pages."""
    return f"{value:,{fmt}}".replace(",", " ").replace("-", "−")


def _ours_against_published(method: str, task: str, ours: float | None) -> str:
    """``return (gap)`` of ours against the published figure, **bold** more than :data:`PUBLISHED_GAP` below."""
    gap = published_gap(method, task, ours)
    if gap is None:
        return "—"
    text = f"{gap:+.2f}".replace("-", "−")
    return f"{_thousands(ours)} ({f'**{text}**' if gap < -PUBLISHED_GAP else text})"


def published_table(rows: list[dict[str, Any]]) -> list[str]:
    """The published locomotion results (:data:`PUBLISHED_LOCOMOTION`, raw returns) beside ours, task by task:
    the paper's return, our final test return and our best evaluation (mean over seeds), each of ours with its
    gap to the paper as a fraction of the paper's expert's return (both sides divided by the same expert);
    **bold** more than :data:`PUBLISHED_GAP` below; ``—`` where we have no run. No lines without a locomotion row."""
    scenarios, _, cell = _columns(rows, LOCOMOTION_ORDER)
    if not scenarios:
        return []
    methods = [m for m in METHOD_ORDER if m in PUBLISHED_LOCOMOTION]
    header, rule = ["method"], ["---"]
    for task in scenarios:
        name = LOCOMOTION_TITLES.get(task, task)
        header += [f"{name}: paper (expert {_thousands(PUBLISHED_EXPERTS[task], '.1f')})", f"{name}: ours, final",
                   f"{name}: ours, best evaluation"]
        rule += ["---"] * 3
    lines = [f"| {' | '.join(header)} |", f"|{'|'.join(rule)}|"]
    for method in methods:
        cells = [method]
        for task in scenarios:
            row = cell.get((method, task))
            cells.append(_thousands(PUBLISHED_LOCOMOTION[method][task]["return"], ".1f"))
            final = _ours_against_published(method, task, None if row is None else row["return_mean"])
            cells.append(f"{final} (at {row['frames']} frames)" if row is not None and off_budget(row) else final)
            cells.append(_ours_against_published(method, task, None if row is None else row["best_eval_return_mean"]))
        lines.append(f"| {' | '.join(cells)} |")
    return lines


def locomotion_tables(rows: list[dict[str, Any]]) -> list[str]:
    """The locomotion tasks' tables: expert-normalised test return (the baselines' papers' metric) with the
    published figure beside it, the test return, cost, difference from ``csirl``; then the published results
    with their sources (no lines without a locomotion row)."""
    scenarios, methods, cell = _columns(rows, LOCOMOTION_ORDER)
    if not scenarios:
        return []
    lines = _method_table(
        "Expert-normalised test return R / R_expert, mean ± std over seeds, R_expert the expert row's mean on the "
        f"same 50 test episodes (ours: the papers' figures are compared in raw returns, below); "
        f"{budget_caption(scenarios)}.",
        methods, scenarios, lambda m, s: _score(cell.get((m, s)), None, "normalized_return"))
    lines += [""] + _method_table(
        "Test return (gymnasium's own reward), mean ± std over seeds.", methods, scenarios,
        lambda m, s: _score(cell.get((m, s)), None, "return", ".0f"))
    evaluated = [m for m in methods if any(_has(cell.get((m, s)), "normalized_best_eval_return") for s in scenarios)]
    if evaluated:
        lines += [""] + _method_table(
            "Best evaluation during training, R / R_expert, mean ± std over seeds: the highest of a run's periodic "
            "evaluations (validation episodes), the figure the published rows report; optimistic (a maximum over "
            "noisy evaluations, scored on the episodes that chose it).", evaluated, scenarios,
            lambda m, s: _score(cell[(m, s)], None, "normalized_best_eval_return")
            if _has(cell.get((m, s)), "normalized_best_eval_return") else "—")
    lines += [""] + _method_table(
        "Cost per run: wall time [min] (start-up and final evaluation included) and updates/s, mean over runs.",
        methods, scenarios, lambda m, s: _cost(cell.get((m, s))))
    lines += _comparison_table(rows, scenarios, cell, "test return", "+.0f")
    published = published_table(rows)
    if not published:
        return lines
    return lines + ["", "Published results in raw returns (IQ-Learn's Table 3: one expert trajectory, as ours; other "
                    "papers, settings and sources: docs/benchmark.md#published-results) beside ours, mean over seeds; "
                    "in brackets ours minus the paper's, divided by the paper's expert's return (**bold**: more than "
                    f"{PUBLISHED_GAP} below).", "", *published]


def markdown_table(rows: list[dict[str, Any]]) -> str:
    """Method rows x scenario columns: the driving scenarios' tables (:func:`driving_tables`), then the
    robotics tasks' (:func:`robotics_tables`), then the locomotion tasks' (:func:`locomotion_tables`)."""
    parts = [part for part in (driving_tables(rows), robotics_tables(rows), locomotion_tables(rows)) if part]
    return "\n\n".join("\n".join(part) for part in parts)


def write_csv(rows: list[dict[str, Any]], path: str) -> str:
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    return path


def eval_curve(run_dir: str, key: str = "eval_accomplish_rate") -> tuple[list[float], list[float]]:
    """(frames, ``key``) of a run's ``metrics.jsonl``, the evaluation accomplish rate by default (empty for a
    reference row)."""
    path = os.path.join(run_dir, "metrics.jsonl")
    frames, values = [], []
    if os.path.isfile(path):
        with open(path) as f:
            for line in f:
                row = json.loads(line) if line.strip() else {}
                if row.get(key) is not None:
                    frames.append(float(row["frames"]))
                    values.append(float(row[key]))
    return frames, values


def evaluation_schedule(run_dirs: list[str]) -> str:
    """How the curves' points of ``run_dirs`` were evaluated (their ``config.yaml``), for a figure's title.

    The periodic evaluations play ``eval.episodes`` episodes from ``eval.validation_seed`` (a range
    apart from the test episodes) or, in runs recorded before that key or with it null, the first
    test episodes.

    Examples:
        >>> evaluation_schedule([])
        ''
    """
    kinds = set()
    for run_dir in run_dirs:
        path = os.path.join(run_dir, "config.yaml")
        if not os.path.isfile(path):
            continue
        evaluation = OmegaConf.load(path).get("eval", {})
        where = "validation" if evaluation.get("validation_seed") is not None else "test"
        kinds.add(f"{evaluation.get('episodes', EvalConfig.episodes)} {where} episodes per point")
    if len(kinds) > 1:
        return "points of differing evaluations (" + "; ".join(sorted(kinds)) + ")"
    return next(iter(kinds), "")


def curve_kinds(scenario: str) -> list[tuple[str, str, str, str, bool]]:
    """The evaluation curves drawn for ``scenario``: ``(file prefix, summary key, curve key, y label, rate)``.

    The driving scenarios get the accomplish rate (the paper's Figure 6); the robotics tasks the return
    (its Figure 7) and, since AntMaze's return is the goal indicator (flat at 0 for most methods), the
    progress too; the locomotion tasks the return alone.

    Examples:
        >>> [kind[0] for kind in curve_kinds("merge")], [kind[0] for kind in curve_kinds("antmaze-umaze")]
        (['curves'], ['curves', 'progress'])
    """
    rate = ("accomplish_rate", "eval_accomplish_rate")
    if not is_robotics(scenario):
        return [("curves", *rate, "evaluation accomplish rate (raw)", True)]
    if scenario in LOCOMOTION_ORDER:  # no goal, no progress: the return alone
        return [("curves", "return", "eval_env_return", "evaluation return", False)]
    return [("curves", "return", "eval_env_return", "evaluation return", False),
            ("progress", *rate, "evaluation progress", True)]


#: the trained rows and CSIRL's variants, in the table's order: each keeps its colour in every figure
LEARNER_ORDER = tuple(m for m in (*METHOD_ORDER, *ABLATIONS) if m not in REFERENCE_METHODS)


def learning_curve_figures(runs: list[dict[str, Any]], out_dir: str) -> list[str]:
    """PNGs per scenario (``curve_kinds``): every trained method's evaluation curve (mean ± std over seeds),
    the reference rows as lines."""
    from torchrl_csirl.visualization import plot_method_curves

    paths = []
    order = (*SCENARIO_ORDER, *return_task_order([r["scenario"] for r in runs]))
    for scenario in [s for s in order if any(r["scenario"] == s for r in runs)]:
        schedule = evaluation_schedule([r["run_dir"] for r in runs if r["scenario"] == scenario
                                        and r["method"] not in REFERENCE_METHODS])
        for prefix, summary_key, curve_key, label, rate in curve_kinds(scenario):
            curves: dict[str, list] = defaultdict(list)
            references: dict[str, list[float]] = defaultdict(list)
            for run in (r for r in runs if r["scenario"] == scenario):
                if run["method"] in REFERENCE_METHODS:
                    if run.get(summary_key) is not None:
                        references[run["method"]].append(float(run[summary_key]))
                else:
                    curves[run["method"]].append(eval_curve(run["run_dir"], curve_key))
            path = plot_method_curves(curves, os.path.join(out_dir, f"{prefix}_{scenario}.png"),
                                      references={m: sum(v) / len(v) for m, v in references.items()},
                                      title=f"{scenario}: {label}" + (f"\n{textwrap.fill(schedule, 72)}" if schedule else ""),
                                      ylabel=label,
                                      rate=rate, method_order=LEARNER_ORDER)
            paths.append(os.fspath(path))
    return paths


def report_main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="benchmark.py report", description="the table and curves of finished runs")
    parser.add_argument("paths", nargs="+", help="sweep output folders or run directories")
    parser.add_argument("--out", default=None, help="where to write (default: <first path>/report)")
    args = parser.parse_args(argv)
    runs = read_runs(args.paths)
    out_dir = os.path.abspath(args.out or os.path.join(args.paths[0], "report"))
    os.makedirs(out_dir, exist_ok=True)
    rows = table_rows(runs)
    table = markdown_table(rows)
    with open(os.path.join(out_dir, "table.md"), "w") as f:
        f.write(table + "\n")
    files = {"markdown": os.path.join(out_dir, "table.md"), "csv": write_csv(rows, os.path.join(out_dir, "table.csv")),
             "figures": learning_curve_figures(runs, out_dir)}
    print(table, file=sys.stderr)
    print(json.dumps({"runs": len(runs), **files}))
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        if argv[:1] == ["report"]:
            return report_main(argv[1:])
        return sweep_main(argv)
    except (BenchmarkError, FileNotFoundError, SweepBusyError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
