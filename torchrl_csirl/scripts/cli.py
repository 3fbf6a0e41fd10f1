"""``torchrl-csirl``: one command for every script (also ``python -m torchrl_csirl``).

Usage::

    torchrl-csirl train [method=<name>] [key=value ...]   # CSIRL (default), csirl-b, or a baseline, on any task
    torchrl-csirl benchmark [--methods ...] [report ...]  # the methods x tasks x seeds sweep, its report
    torchrl-csirl watch <run dir or policy.pt> [...]      # videos of a trained agent
    torchrl-csirl expert [key=value ...]                  # SAC on a task's own reward, then its demonstrations
    torchrl-csirl expert ant [key=value ...]              # the AntMaze expert's walking ant
    torchrl-csirl expert demos --scenario <task> [...]    # demonstrations of a shipped scripted expert
    torchrl-csirl diagnose <run dir>                      # why a run failed: its health report
    torchrl-csirl off-demos <run dir> [...]               # are a run's states the demonstrations'? (any method)
    torchrl-csirl outcomes <run dir or policy.pt>         # how a policy's test episodes end
    torchrl-csirl summarize <runs>                        # mean ± std over seeds, per scenario and configuration
    torchrl-csirl compare <runs> --against <runs>         # two seed sets: Welch's test, the verdict, what differs
    torchrl-csirl curves --group LABEL <runs> ... --output PNG  # evaluation curves of groups of runs
    torchrl-csirl record <runs> --into docs/runs/<group>  # finished runs' records, kept in the repository
    torchrl-csirl health-table <records>                  # how often each health check flags failed / good runs

Each command is the script of the same name (``python -m torchrl_csirl.scripts.<name>``, ``recipes/<name>.py``):
``train`` is ``csirl_highway`` (``method=csirl``, the default, or ``csirl-b``) or ``imitation_highway`` (any other
method); a hyphenated command is the module with an underscore (``health-table``: ``health_table``);
``<command> --help`` lists what it accepts.

Examples:
    >>> split_method(["method=csirl-b", "env.task=hopper"])
    ('csirl-b', ['env.task=hopper'])
    >>> split_method(["seed=1"])
    ('csirl', ['seed=1'])
"""
from __future__ import annotations

import importlib
import sys
from collections.abc import Callable
from functools import partial
from typing import Any

__all__ = ["COMMANDS", "main", "split_method"]

#: command -> (what it does, in a few words)
COMMANDS = {
    "train": "train CSIRL (method=csirl | csirl-b) or a baseline (method=<name>) on any task",
    "benchmark": "the methods x tasks x seeds sweep, and its report (benchmark report <dirs>)",
    "watch": "videos of a trained agent",
    "expert": "an expert for a task: SAC on its own reward (expert), the AntMaze walker (expert ant), "
              "a scripted expert's demonstrations (expert demos)",
    "diagnose": "why a run failed: its health report (health.json, health.png) from its metrics and checkpoint",
    "off-demos": "are a run's states the demonstrations'? the health check on any method's run",
    "outcomes": "how a saved policy's test episodes end (driving: crash, off-road...; AntMaze, Relocate)",
    "summarize": "runs' mean ± std over seeds, per scenario, method, preset and configuration variant",
    "compare": "two sets of runs: Welch's test, the verdict, every difference of configuration and code",
    "curves": "evaluation curves of groups of runs in one figure, mean ± std over seeds",
    "record": "finished runs' records (summary, config, provenance, curves, rounds) into docs/runs/<group>",
    "health-table": "how often each health check flags failed and succeeded runs, from their records",
}


def usage() -> str:
    """The one-screen help: each command and what it does."""
    width = max(map(len, COMMANDS))
    rows = "\n".join(f"  {name:<{width}} {text}" for name, text in COMMANDS.items())
    return f"usage: torchrl-csirl <command> [arguments]\n\ncommands:\n{rows}\n\n<command> --help: what it accepts"


def split_method(argv: list[str]) -> tuple[str, list[str]]:
    """``train``'s ``method=<name>`` (default ``csirl``) and the other arguments."""
    method, rest = "csirl", []
    for item in argv:
        if item.startswith("method="):
            method = item.partition("=")[2]
        else:
            rest.append(item)
    return method, rest


def _script(name: str) -> Any:
    return importlib.import_module(f"torchrl_csirl.scripts.{name}")


def _train(argv: list[str]) -> None:
    from torchrl_csirl.run.config import ConfigError
    from torchrl_csirl.run.recipes import known_methods, recipe_for
    from torchrl_csirl.run.run import run_script

    method, rest = split_method(argv)
    try:
        recipe = recipe_for(method)
    except KeyError:
        run_script(partial(_raise, ConfigError(f"method={method}: unknown; one of {', '.join(known_methods())}")))
        return
    script = _script(recipe.script.rpartition(".")[2])
    run_script(partial(script.main, [*recipe.method_overrides(method), *rest]))


def _raise(error: BaseException) -> None:
    raise error


def _expert(argv: list[str]) -> None:
    from torchrl_csirl.run.run import run_script

    if argv[:1] == ["demos"]:
        _script("generate_experts").main(argv[1:])
    elif argv[:1] == ["ant"]:
        run_script(partial(_script("train_ant_expert").main, argv[1:]))
    else:
        run_script(partial(_script("train_expert").main, argv))


def _benchmark(argv: list[str]) -> None:
    sys.exit(_script("benchmark").main(argv))


def _watch(argv: list[str]) -> None:
    from torchrl_csirl.analysis.visualization.video import VideoError
    from torchrl_csirl.run.run import run_script

    run_script(partial(_script("watch").main, argv), known_errors=(VideoError,))


def _diagnose(argv: list[str]) -> None:
    from torchrl_csirl.run.run import run_script

    run_script(partial(_script("diagnose").main, argv))


def _exit_status(main: Callable[[list[str]], Any], argv: list[str]) -> None:
    status = main(argv)
    if isinstance(status, int) and not isinstance(status, bool) and status:
        sys.exit(status)


def _analysis(argv: list[str], name: str) -> None:
    """A command reading runs or records (``record``, ``compare``, ...): errors in one line, as the others'."""
    from torchrl_csirl.run.run import run_script

    run_script(partial(_exit_status, _script(name.replace("-", "_")).main, argv))


#: the commands that read finished runs, their records or a saved policy
ANALYSIS = ("off-demos", "outcomes", "summarize", "compare", "curves", "record", "health-table")

_RUNNERS: dict[str, Callable[[list[str]], None]] = {
    "train": _train, "benchmark": _benchmark, "watch": _watch, "expert": _expert, "diagnose": _diagnose,
    **{name: partial(_analysis, name=name) for name in ANALYSIS}}


def main(argv: list[str] | None = None) -> None:
    """Runs ``torchrl-csirl <command> [arguments]``; an unknown command is one line and exit status 2."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if not argv or argv[0] in ("-h", "--help", "help"):
        print(usage())
        return
    command, rest = argv[0], argv[1:]
    if command not in _RUNNERS:
        print(f"error: torchrl-csirl {command}: unknown command; one of {', '.join(COMMANDS)}", file=sys.stderr)
        sys.exit(2)
    _RUNNERS[command](rest)


if __name__ == "__main__":
    main()
