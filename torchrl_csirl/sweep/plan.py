"""The sweep's plan: methods x scenarios x seeds as cells, each a command line of its recipe with its budget.

The table's rows and columns (:data:`METHOD_ORDER`, :data:`SCENARIO_ORDER`, :data:`ROBOTICS_ORDER`,
:data:`LOCOMOTION_ORDER`), every cell's budget (:data:`TABLE_BUDGETS`) and settings (:data:`TASK_OVERRIDES`),
which recipe runs a method on a task (:func:`recipe_of`) and the cells of a sweep (:func:`plan_cells`). Method
and task names come from their registries (:data:`torchrl_csirl.methods.baselines.METHODS`,
:data:`torchrl_csirl.tasks.TASKS`); running the cells is :mod:`torchrl_csirl.sweep.runner`'s.

Examples:
    >>> SCENARIO_ORDER, LOCOMOTION_ORDER
    (('highway-fast', 'merge', 'intersection', 'roundabout'), ('hopper', 'halfcheetah'))
"""
from __future__ import annotations

import os
import sys
from dataclasses import dataclass

from torchrl_csirl.methods.baselines import METHODS, REFERENCE_METHODS
from torchrl_csirl.sweep.published import PAPER_TABLE
from torchrl_csirl.tasks import LOCOMOTION_TASKS, TASKS, import_task_module, resolve_scenario, task_names

__all__ = ["ABLATIONS", "BASELINE_VARIANTS", "CSIRL_METHODS", "CSIRL_RECIPE", "CSIRL_ROBOTICS_RECIPE", "IMITATION_RECIPE",
           "IMITATION_ROBOTICS_RECIPE", "LOCOMOTION_ORDER", "LOCOMOTION_TITLES", "METHOD_ORDER", "PAPER_ROBOTICS_METHODS",
           "RECIPES", "REFERENCE_METHODS", "ROBOTICS_ORDER", "SCENARIO_ORDER", "SEED_FREE_METHODS", "TABLE_BUDGETS",
           "TASK_OVERRIDES", "BenchmarkError", "Cell", "has_checkpoint", "import_override_modules", "is_gymnasium_id", "is_robotics",
           "known_methods", "make_cell", "plan_cells", "recipe_of", "return_task_order", "score_key", "split_overrides",
           "table_overrides"]

#: the paper's Table I's columns, in its order
_PAPER_COLUMNS = {scene: i for i, scene in enumerate(PAPER_TABLE["csirl"])}

#: the table's rows, in the paper's order, and the recipe of each
METHOD_ORDER = ("expert", "random", "sac", "bc", "gail", "dac", "valuedice", "sqil", "iqlearn", "csirl-b", "csirl")
CSIRL_RECIPE, IMITATION_RECIPE = "csirl_highway", "imitation_highway"
#: the robotics tasks' recipes (the same learners on ``env.task=relocate | antmaze-umaze``)
CSIRL_ROBOTICS_RECIPE, IMITATION_ROBOTICS_RECIPE = "csirl_robotics", "imitation_robotics"
RECIPES = (CSIRL_RECIPE, IMITATION_RECIPE, CSIRL_ROBOTICS_RECIPE, IMITATION_ROBOTICS_RECIPE)
#: CSIRL and its ablations: cells of the CSIRL recipe with these switches
CSIRL_METHODS: dict[str, tuple[str, ...]] = {
    "csirl": (),
    "csirl-b": ("csirl.intrinsic=false",),  # no learned reward r_w
    "csirl-nocur": ("csirl.fixed_subgoal=true",),  # no curriculum: the subgoal is the last state
    "csirl-noexp": ("replay_buffer.expert_fraction=0",),  # no expert transitions in the SAC batch
    # not an ablation: CSIRL with TD3+BC-style cloning on its actor, the setting that learns Relocate
    # (docs/studies/index.md "Relocate and AntMaze: behavioural cloning against CSIRL")
    "csirl-bc": ("csirl.actor_bc_coef=10",),
}
#: baselines with one setting changed, each a row of its own: ``name -> (the baselines' method, its switches)``
BASELINE_VARIANTS: dict[str, tuple[str, tuple[str, ...]]] = {
    # SAC from demonstrations: a quarter of each batch the expert's transitions with their recorded reward; against
    # SAC it measures what the expert transitions alone give, against CSIRL-B what the matching reward adds
    "sac-exp": ("sac", ("sac.expert_fraction=0.25",)),
}
#: the ablation and variant rows (not in the paper's table, so not in a default sweep): after csirl in a report
ABLATIONS = ("csirl-nocur", "csirl-noexp", "csirl-bc", *BASELINE_VARIANTS)
#: methods whose run does not depend on the seed (the expert driver is deterministic): first seed only
SEED_FREE_METHODS = ("expert",)
#: the table's columns: the task registry's driving scenes (:func:`~torchrl_csirl.tasks.task_names`), in the
#: paper's order (its Table I's columns)
SCENARIO_ORDER = tuple(sorted(task_names(driving=True), key=lambda s: (_PAPER_COLUMNS.get(s, len(_PAPER_COLUMNS)), s)))
#: the robotics table's columns (the paper's Figure 7), scored by the test return
ROBOTICS_ORDER = ("antmaze-umaze", "relocate")
#: the locomotion table's columns (beyond the paper: gymnasium's MuJoCo tasks, where the baselines' own papers
#: published their results), scored by the test return and the expert-normalised return
LOCOMOTION_ORDER = tuple(LOCOMOTION_TASKS)
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
#: the locomotion tasks: 300 000 frames (the benchmark's cap). The published baselines report at 100 000 frames with
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


class BenchmarkError(ValueError):
    """Bad benchmark arguments (one line)."""


def is_robotics(scenario: str) -> bool:
    """Whether ``scenario`` is scored by return and run by the robotics scripts: every task but the driving
    scenes (the robotics tasks, a task of your own, a gymnasium id), by the task's ``family`` in the registry
    (:func:`~torchrl_csirl.tasks.resolve_scenario`); a name the registry does not know yet counts as one.

    Examples:
        >>> is_robotics("relocate"), is_robotics("MountainCarContinuous-v0"), is_robotics("merge")
        (True, True, False)
    """
    try:
        return resolve_scenario(scenario).family != "driving"
    except ValueError:  # not a task (yet): a gymnasium id, or a task its module registers in the cell
        return True


def return_task_order(scenarios: list[str]) -> tuple[str, ...]:
    """The return-scored columns: the paper's robotics tasks first, then any other task, by name."""
    others = sorted({s for s in scenarios if is_robotics(s) and s not in ROBOTICS_ORDER})
    return (*ROBOTICS_ORDER, *others)


def is_gymnasium_id(scenario: str) -> bool:
    """A gymnasium id run as a task by configuration (its cells set ``env.gym_id``): not one of our task
    names, or registered by ``make_gymnasium_task`` in this process."""
    import gymnasium as gym

    from torchrl_csirl.tasks.gym_ids import import_gym_provider

    if scenario in TASKS:
        return TASKS[scenario].family == "gymnasium"
    import_gym_provider(scenario)  # an id of an installed package that registers ids when imported (PointMaze)
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
    """Every method a cell can run: CSIRL's, those ``imitation_highway.py`` accepts and their variants."""
    return (*CSIRL_METHODS, *METHODS, *BASELINE_VARIANTS)


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
    task = f"env.gym_id={scenario}" if is_gymnasium_id(scenario) else f"env.task={scenario}"
    args = [task, f"seed={seed}", "logger.progress_bar=false", *overrides]
    if method in CSIRL_METHODS:
        args += CSIRL_METHODS[method]
    elif method in BASELINE_VARIANTS:
        base, switches = BASELINE_VARIANTS[method]
        args = [f"method={base}", *args, *switches]
    else:
        args.insert(0, f"method={method}")
    resumed = has_checkpoint(run_dir)
    if resumed:
        args = [f"checkpoint.resume={run_dir}", *(a for a in args if not a.startswith("method="))]
    else:  # a run killed before its first checkpoint is started again
        args += [f"logger.output_dir={output_dir}", f"logger.exp_name={os.path.basename(run_dir)}",
                 "logger.overwrite=true"]
    return Cell(method, scenario, seed, run_dir, (sys.executable, "-m", recipe, *args), resumed)


def import_override_modules(overrides: list[str]) -> None:
    """Imports every ``env.module=<module>`` among ``overrides`` (plain or scoped to a method), so that the tasks
    and gymnasium ids the module registers are known here, as they will be in the cells.

    Raises:
        BenchmarkError: one line when a module cannot be imported.
    """
    for item in overrides:
        key, sep, value = item.rpartition(":")[2].partition("=")
        if sep and key.strip() == "env.module" and value.strip():
            try:
                import_task_module(value.strip())
            except ValueError as err:
                raise BenchmarkError(str(err)) from None


def plan_cells(methods: list[str], scenarios: list[str], seeds: list[int], output_dir: str,
               overrides: list[str]) -> tuple[list[Cell], list[str]]:
    """(cells to run, names of the cells already done)."""
    unknown = [m for m in methods if m not in known_methods()]
    if unknown:
        raise BenchmarkError(f"--methods {' '.join(unknown)}: unknown; known: {', '.join(known_methods())}")
    import_override_modules(overrides)
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

