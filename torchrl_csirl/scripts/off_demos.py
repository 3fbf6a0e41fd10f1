"""Are a run's states the demonstrations'? The health check ``states_off_the_demonstrations`` on any run.

``torchrl-csirl off-demos <run dir> [<run dir> ...] [--episodes 5] [--holdout]``

For each run (any method: its ``policy.pt``, else the actor of its last checkpoint) it rolls the deterministic policy
for ``--episodes`` episodes seeded from the run's ``eval.seed`` (the test's first episodes) and sets its states against
the run's demonstrations (:func:`torchrl_csirl.analysis.diagnostics.states_off_the_demonstrations`: per observation entry the
matching reward does not read, the mean gap to the nearest demonstration state in the demonstrations' standard
deviations, read per episode, the worst one reported). With ``--holdout`` it sets the run's last five demonstrations
(at most all but one) against the others instead of a policy: the figure an expert gets. One line per run, then the
figures as a JSON line per run (with ``first_crash_per_episode``: where the environment reports ``crashed``, each
episode's first such step, counted from 1; AntMaze's is a flipped ant). CSIRL's health report makes the same check at
the end of every run; this command makes it for the baselines too, and calibrates its threshold
(docs/own-task.md#a-cheetah-on-its-back).

Examples:
    >>> main(["runs/merge-bc-s0", "--episodes", "0"])  # refused in one line on stderr, exit status 2
    Traceback (most recent call last):
    SystemExit: 2
"""
from __future__ import annotations

import argparse
import json
import os
import sys

import torch
from omegaconf import OmegaConf

from torchrl_csirl.analysis.diagnostics import check_line, flat_observations, states_off_the_demonstrations
from torchrl_csirl.run.builders import load_experts
from torchrl_csirl.run.task_schemas import prepare_task
from torchrl_csirl.scripts._policy_rollouts import first_crash_step, policy_episodes
from torchrl_csirl.tasks import resolve_scenario

__all__ = ["check_run", "main", "policy_states"]


def policy_states(run_dir: str, cfg, episodes: int) -> tuple[list[torch.Tensor], list[int | None]]:
    """``[T_j, D]`` per episode, the deterministic policy's next observations over ``episodes`` episodes (seeds
    ``eval.seed + i``), and each episode's first ``crashed`` step (counted from 1)."""
    rollouts = list(policy_episodes(run_dir, cfg.env.scenario, episodes, int(cfg.eval.seed)))
    return [flat_observations(rollout["next"]) for rollout in rollouts], [first_crash_step(r) for r in rollouts]


def check_run(run_dir: str, episodes: int = 5, holdout: bool = False) -> dict:
    """The check on one run, as a dict (``name``, ``ok``, ``message``, ``figures``, ``run``)."""
    cfg = OmegaConf.load(os.path.join(run_dir, "config.yaml"))
    prepare_task([], run_dir=run_dir)  # a task by gymnasium id or from a module: registered as the run had it
    spec = resolve_scenario(cfg.env.scenario)
    demos = load_experts(cfg.expert, spec)
    trajectories = [flat_observations(demos.trajectory(i)) for i in range(demos.num_trajectories)]
    if holdout and len(trajectories) < 2:
        raise SystemExit(f"error: {run_dir}: one demonstration, none to hold out")
    if holdout:  # the last five (at most all but one) against the others
        kept = max(1, len(trajectories) - 5)
        states, trajectories = trajectories[kept:], trajectories[:kept]  # each held out one as an episode
        crashes = None
    else:
        states, crashes = policy_states(run_dir, cfg, episodes)
    names = [spec.feature_name(i) for i in range(spec.obs_dim)]
    check = states_off_the_demonstrations(states, trajectories, spec.position_feature_indices, names)
    return {"run": run_dir, "holdout": holdout, **check.as_dict(), "first_crash_per_episode": crashes}


def main(argv: list[str] | None = None) -> list[dict]:
    """Checks each run (``argv``: the command line, ``None`` for ``sys.argv[1:]``); returns the checks.

    Raises:
        SystemExit: one line naming the runs that could not be read (after the others' lines).
    """
    parser = argparse.ArgumentParser(prog="torchrl-csirl off-demos", description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+")
    parser.add_argument("--episodes", type=int, default=5)
    parser.add_argument("--holdout", action="store_true", help="the last five demonstrations against the others")
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error("--episodes must be at least 1")
    results, failed = [], []
    for run in args.runs:
        try:
            results.append(check_run(run, args.episodes, args.holdout))
        except SystemExit as err:  # one run that cannot be read does not stop the others
            failed.append(run)
            print(err, file=sys.stderr)
    for result in results:
        print(f"{result['run']}: {check_line(result)}")
    for result in results:
        print(json.dumps(result, default=float))
    if failed:
        raise SystemExit(f"error: {len(failed)} run(s) not read: {', '.join(failed)}")
    return results


if __name__ == "__main__":
    main()
