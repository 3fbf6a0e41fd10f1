"""Aggregate finished runs of ``recipes/csirl_highway.py``: mean and std over seeds, per scenario.

Reads ``summary.json`` of every run directory given (or found under a folder), groups the runs by
(scenario, method, preset, variant) and prints a Markdown table (to stderr) and, last, one JSON
line with the per-group statistics (and, for CSIRL, where each seed's curriculum ended; for every group the
code its runs ran, from their ``provenance.json``, ``provenance: unknown`` for records made before it). The
*variant* lists the run's configuration values that differ from its preset's defaults (read from
the run's ``config.yaml``; seeds, logging, checkpointing and thread counts do not count), e.g.
``replay_buffer.expert_fraction=0``.

Usage::

    torchrl-csirl summarize runs/                     # every run under runs/
    torchrl-csirl summarize runs/merge-s0 runs/merge-s1 runs/merge-s2

Examples:
    >>> summarize([{"scenario": "merge", "method": "csirl", "preset": "default",
    ...             "accomplish_rate": 0.9, "seed": 0}])["merge/csirl/default"]["accomplish_rate"]["mean"]
    0.9
"""
from __future__ import annotations

import argparse
import functools
import json
import os
import sys
from collections import Counter, defaultdict

from omegaconf import OmegaConf

from torchrl_csirl.analysis.summaries import find_summaries, mean_std
from torchrl_csirl.run.config import ConfigError, flatten_config, format_override
from torchrl_csirl.run.provenance import processes, read_provenance
from torchrl_csirl.run.recipes import load_config_for

__all__ = ["code_of", "main", "markdown_table", "summarize", "variant"]

#: configuration keys that do not change what a run learns (or are shown elsewhere in the key)
NOT_A_VARIANT = ("seed", "device", "preset", "env.scenario", "env.task", "csirl.intrinsic", "collector.main_threads", "logger.",
                 "checkpoint.")

#: a run's code where it has no ``provenance.json``
UNKNOWN = "provenance: unknown"

#: summary fields reported as mean / std over seeds
FIELDS = (
    "accomplish_rate",
    "normalized_accomplish_rate",
    "success_rate",
    "crash_rate",
    "auc",
    "frames",
    "updates",
    "wall_s",
    "total_wall_s",
    "updates_per_s",
    "collect_fps",
)


@functools.lru_cache(maxsize=None)
def _preset_defaults(method: str, preset: str, scenario: str | None = None) -> dict[str, object]:
    """The configuration ``preset`` gives on ``scenario`` (with that scene's own defaults, if any).

    A scenario the method's recipe does not know (a robotics run summarised with a driving recipe's
    loader) falls back on the recipe's default scenario.
    """
    overrides = [f"preset={preset}"]
    try:
        return flatten_config(load_config_for(method)([*overrides, f"env.task={scenario}"] if scenario else overrides))
    except ConfigError:
        if scenario is None:
            raise
        return _preset_defaults(method, preset)


def variant(run_dir: str, preset: str, method: str = "csirl") -> str:
    """``key=value`` of the run's configuration entries that differ from ``preset``'s defaults on
    the run's scenario (those of the recipe that trains ``method``, scene defaults included).

    Empty for a run of the preset as it is, or when the run directory has no ``config.yaml``.
    """
    path = os.path.join(run_dir, "config.yaml")
    if not os.path.isfile(path):
        return ""
    run = flatten_config(OmegaConf.load(path))
    scenario = run.get("env.scenario")
    default = _preset_defaults(method, preset, scenario if isinstance(scenario, str) else None)
    # an option younger than the run is missing from its config: the run had the recipe's own default
    recipe_default = _preset_defaults(method, "default")
    run.update({key: recipe_default[key] for key in default.keys() - run.keys() if key in recipe_default})
    changed = [
        format_override(key, value)
        for key, value in sorted(run.items())
        if not key.startswith(NOT_A_VARIANT) and default.get(key, object()) != value
    ]
    return " ".join(changed)


def summarize(summaries: list[dict]) -> dict[str, dict]:
    """Group run summaries by ``scenario/method/preset[ variant]``; mean/std of :data:`FIELDS` per group.

    Each group also says where each seed's curriculum ended (:func:`curriculum_ends`).
    """
    groups: dict[str, list[dict]] = defaultdict(list)
    for s in summaries:
        key = f"{s['scenario']}/{s['method']}/{s['preset']}"
        groups[f"{key} {s['variant']}" if s.get("variant") else key].append(s)
    out = {}
    for key, runs in sorted(groups.items()):
        stats: dict[str, object] = {"seeds": sorted(int(r["seed"]) for r in runs)}
        for field in FIELDS:
            values = [float(r[field]) for r in runs if r.get(field) is not None]
            if values:
                stats[field] = mean_std(values)
        ends = curriculum_ends(runs)
        if ends:
            stats["final_subgoal"] = ends
        stats["code"] = ", ".join(f"{code} ({n})" for code, n in Counter(r.get("code", UNKNOWN) for r in runs).items())
        out[key] = stats
    return out


def code_of(run_dir: str) -> str:
    """The code a run ran, in short: its commit's first 10 characters (``+dirty <diff hash's first 8>`` for a dirty
    tree, ``a -> b`` where a resume ran other code), ``not a checkout`` without a commit, :data:`UNKNOWN` without
    ``provenance.json`` (records made before runs wrote it).

    Examples:
        >>> import tempfile
        >>> code_of(tempfile.mkdtemp())
        'provenance: unknown'
    """
    prov = read_provenance(run_dir)
    if prov is None:
        return UNKNOWN
    states = []
    for process in processes(prov):
        code = process.get("code") or {}
        state = code["commit"][:10] if code.get("commit") else "not a checkout"
        if code.get("dirty"):
            state += f"+dirty {str(code.get('diff_sha256'))[:8]}"
        states.append(state)
    return " -> ".join(dict.fromkeys(states))


def curriculum_ends(runs: list[dict]) -> str:
    """Where each run's curriculum ended, by seed: ``"44, 42, 44 of 45"`` (empty without a curriculum)."""
    ends = [(int(r["seed"]), r["final_subgoal"], r.get("curriculum_length")) for r in runs
            if r.get("final_subgoal") is not None]
    if not ends:
        return ""
    lengths = {length for *_, length in ends if length is not None}
    text = ", ".join(str(end) for _, end, _ in sorted(ends))
    return f"{text} of {lengths.pop()}" if len(lengths) == 1 else text


def markdown_table(stats: dict[str, dict]) -> str:
    """One row per group: mean ± std of the main figures."""
    head = ("| scenario / method / preset | seeds | accomplish (raw) | expert-normalised | success | crash | AUC | frames "
            "| updates | wall [min] | final subgoal | code (runs) |")
    rows = [head, "|---" * (head.count("|") - 1) + "|"]

    def cell(s: dict, field: str, fmt: str = "{:.3f}", scale: float = 1.0) -> str:
        if field not in s:
            return "n/a"
        return f"{fmt.format(s[field]['mean'] * scale)} ± {fmt.format(s[field]['std'] * scale)}"

    for key, s in stats.items():
        rows.append(
            f"| {key} | {','.join(map(str, s['seeds']))} | {cell(s, 'accomplish_rate')} | "
            f"{cell(s, 'normalized_accomplish_rate')} | {cell(s, 'success_rate', '{:.2f}')} | "
            f"{cell(s, 'crash_rate', '{:.2f}')} | {cell(s, 'auc')} | "
            f"{cell(s, 'frames', '{:.0f}')} | {cell(s, 'updates', '{:.0f}')} | {cell(s, 'total_wall_s', '{:.1f}', 1 / 60)} | "
            f"{s.get('final_subgoal') or 'n/a'} | {s['code']} |"
        )
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> dict[str, dict]:
    """Summarises the runs (``argv``: the command line, ``None`` for ``sys.argv[1:]``); returns the JSON line's object."""
    parser = argparse.ArgumentParser(prog="torchrl-csirl summarize", description=__doc__.split("\n")[0])
    parser.add_argument("paths", nargs="+", help="run directories, or folders holding run directories")
    args = parser.parse_args(argv)
    summaries = []
    for path in find_summaries(args.paths):
        with open(path) as f:
            summary = json.load(f)
        summary["code"] = code_of(os.path.dirname(path))
        summary["variant"] = variant(os.path.dirname(path), summary.get("preset", "default"),
                                     summary.get("method", "csirl"))
        summaries.append(summary)
    stats = summarize(summaries)
    print(markdown_table(stats), file=sys.stderr)
    print(json.dumps(stats))
    return stats


if __name__ == "__main__":
    main()
