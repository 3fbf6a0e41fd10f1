"""What the commands that roll a saved policy out on the recipe's test episodes share (``torchrl-csirl outcomes``,
``torchrl-csirl off-demos``, the study probes of docs/studies/scripts): the arguments, the policy and its task,
checked; a run's actor (its ``policy.pt`` or its last checkpoint's); the test episodes; and the small formatting
helpers of their tables.

Examples:
    >>> format_cell(None, ".2f"), format_cell(0.5, ".2f"), mean_or_none([])
    ('-', '0.50', None)
"""
from __future__ import annotations

import argparse
import os
from collections.abc import Callable, Collection, Iterator
from typing import Any

import torch
from tensordict import TensorDictBase
from torchrl.envs import EnvBase, ExplorationType, set_exploration_type

from torchrl_csirl.modules import load_policy, make_actor, make_input_features
from torchrl_csirl.tasks import make_env, resolve_scenario, sample_lane_centres

__all__ = ["first_crash_step", "format_cell", "load_actor", "load_test_policy", "mean_or_none", "policy_episodes",
           "roll_test_episodes"]

#: where a checkpoint's ``loss`` state keeps the actor's weights
ACTOR_PREFIXES = ("actor_network_params.", "actor_network.")


def load_test_policy(description: str, argv: list[str] | None, tasks: Collection[str],
                     kind: str, prog: str | None = None) -> tuple[argparse.Namespace, Any, str]:
    """Parses ``<policy> [--episodes N] [--seed S]``, loads the policy and checks its task is one of ``tasks``.

    Args:
        description: the script's one-line description (``--help``).
        argv: the arguments (``None``: ``sys.argv[1:]``).
        tasks: the tasks the script handles.
        kind: what they are, for the error (e.g. ``"driving scenarios"``).
        prog: the command's name in its usage (``None``: the script's file name).

    Returns:
        The parsed arguments, the policy (deterministic at test) and its task. Sets torch to one
        thread (the rollouts are small batches).

    Examples:
        >>> import os, tempfile
        >>> from torchrl_csirl.modules import make_actor, save_policy
        >>> path = save_policy(make_actor(25, 2), os.path.join(tempfile.mkdtemp(), "p.pt"),
        ...                    obs_dim=25, action_dim=2, scenario="merge")
        >>> args, policy, task = load_test_policy("demo", [path, "--episodes", "3"], ["merge"], "driving scenarios")
        >>> args.episodes, task
        (3, 'merge')
    """
    parser = argparse.ArgumentParser(prog=prog, description=description)
    parser.add_argument("policy", help="a run directory or its policy.pt")
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--seed", type=int, default=1_000_000, help="seed of the first episode (the recipe's eval.seed)")
    args = parser.parse_args(argv)
    if args.episodes <= 0:
        parser.error(f"--episodes must be positive, got {args.episodes}")
    policy = load_policy(args.policy, lane_centres=sample_lane_centres)  # lane features saved by name only
    task = policy.metadata.get("scenario")
    if task not in tasks:
        parser.error(f"{args.policy}: a policy for {task!r}, not one of the {kind} {sorted(tasks)}")
    torch.set_num_threads(1)
    return args, policy, task


def roll_test_episodes(policy, task: str, episodes: int, seed: int, max_steps: int,
                       at_reset: Callable[[EnvBase], Any] | None = None,
                       exploration: ExplorationType = ExplorationType.DETERMINISTIC,
                       ) -> Iterator[tuple[EnvBase, TensorDictBase, Any]]:
    """Rolls ``policy`` over the recipe's test episodes of ``task``, one at a time.

    Episode ``i`` is seeded with ``seed + i`` as the recipe's final evaluation does; each rollout
    stops at the episode's end. Yields ``(env, rollout, at_reset(env))``: the environment as the
    episode left it, the rollout, and what ``at_reset`` read from the scene just after the reset
    (``None`` without it). The environment is closed at the end. The policy acts with its mean
    action (the test's) unless ``exploration`` says otherwise (``ExplorationType.RANDOM``: sampled).

    Examples:
        >>> from torchrl_csirl.modules import make_actor
        >>> _ = torch.manual_seed(0)  # the actor's initial weights
        >>> [r.shape[-1] for _, r, _ in roll_test_episodes(make_actor(25, 2), "merge", 2, 0, max_steps=3)]
        [3, 3]
    """
    env = make_env(task)
    try:
        with set_exploration_type(exploration), torch.no_grad():
            for i in range(episodes):
                env.set_seed(seed + i)  # the reset below is the one of evaluate_policy's rollout
                start = env.reset()
                before = at_reset(env) if at_reset is not None else None
                rollout = env.rollout(max_steps, policy, auto_reset=False, tensordict=start,
                                      break_when_any_done=True)
                yield env, rollout, before
    finally:
        env.close()


def load_actor(run_dir: str, task: str) -> torch.nn.Module:
    """The run's policy: ``policy.pt``, else the actor in its last checkpoint's ``loss`` state.

    Raises:
        SystemExit: one line, for a run with neither, or a checkpoint without an actor.

    Examples:
        >>> import tempfile
        >>> load_actor(tempfile.mkdtemp(), "hopper")  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        SystemExit: error: ...: neither policy.pt nor checkpoints/last/state.pt
    """
    if os.path.isfile(os.path.join(run_dir, "policy.pt")):
        return load_policy(run_dir)
    path = os.path.join(run_dir, "checkpoints", "last", "state.pt")
    if not os.path.isfile(path):
        raise SystemExit(f"error: {run_dir}: neither policy.pt nor checkpoints/last/state.pt")
    state = torch.load(path, weights_only=False, map_location="cpu")["states"].get("loss", {})
    for prefix in ACTOR_PREFIXES:
        weights = {k[len(prefix):]: v for k, v in state.items() if k.startswith(prefix)}
        if weights:
            break
    else:
        raise SystemExit(f"error: {path}: no actor in its loss state; probe the finished run (policy.pt)")
    spec = resolve_scenario(task)
    actor = make_actor(spec.obs_dim, spec.action_dim, input_features=make_input_features(spec, ego_relative=False))
    actor.load_state_dict(weights)
    return actor


def policy_episodes(run_dir: str, task: str, episodes: int, seed: int,
                    stochastic: bool = False) -> Iterator[TensorDictBase]:
    """The run's policy (:func:`load_actor`) over ``episodes`` episodes, each on its own seed (``seed + i``, as
    the test's), yielded one rollout at a time; its mean action unless ``stochastic``.

    Examples:
        >>> import os, tempfile
        >>> from torchrl_csirl.modules import save_policy
        >>> run = tempfile.mkdtemp()
        >>> _ = save_policy(make_actor(25, 2), os.path.join(run, "policy.pt"), obs_dim=25, action_dim=2, scenario="merge")
        >>> [r.shape[-1] for r in policy_episodes(run, "merge", 1, 0)] >= [1]
        True
    """
    mode = ExplorationType.RANDOM if stochastic else ExplorationType.DETERMINISTIC
    episodes_rolled = roll_test_episodes(load_actor(run_dir, task), task, episodes, seed,
                                         resolve_scenario(task).max_steps, exploration=mode)
    yield from (rollout for _, rollout, _ in episodes_rolled)


def first_crash_step(rollout: TensorDictBase) -> int | None:
    """The step (counted from 1) at which the environment first reports ``("next", "crashed")``; ``None``
    if it never does or has no such entry (AntMaze: the ant flipped; highway: a collision).

    Examples:
        >>> from tensordict import TensorDict
        >>> crashed = torch.tensor([[False], [False], [True], [True]])
        >>> first_crash_step(TensorDict({"next": {"crashed": crashed}}, [4]))
        3
    """
    if ("next", "crashed") not in rollout.keys(True):
        return None
    crashed = rollout["next", "crashed"].reshape(-1).nonzero()
    return int(crashed[0, 0]) + 1 if crashed.numel() else None


def mean_or_none(values: list[float]) -> float | None:
    """The mean, or ``None`` for no values."""
    return sum(values) / len(values) if values else None


def format_cell(value: object, fmt: str) -> str:
    """A table cell: ``value`` formatted, ``"-"`` for ``None``."""
    return "-" if value is None else format(value, fmt)
