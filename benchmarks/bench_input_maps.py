"""What the input maps cost an update of the README's run: calls per update, with and without the memo, and one call's time.

Builds the README's run (``recipes/csirl_highway.py``, default configuration, one worker process),
collects ``--frames`` transitions, then counts the computations of its input map
(:class:`~torchrl_csirl.modules.EgoRelativeFeatures`) in one plain update and one CSIRL update, called
as the trainer calls them (inside :func:`~torchrl_csirl.modules.map_each_input_once`) and bare (every
call computes). It also times one call of the map on a batch of ``--batch`` merge observations (one
thread, the median of ``--repeats``). ``*_saved_ms`` is the calls saved times that time. With a checkout
that has no memo on ``PYTHONPATH`` (an older commit) only the bare counts and the time are given.

Usage::

    python benchmarks/bench_input_maps.py
    PYTHONPATH=/tmp/base python benchmarks/bench_input_maps.py    # an older checkout's map

Prints one final JSON line.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import statistics
import tempfile
import time
from unittest import mock

import torch
from bench_recipe_update import _fill

from torchrl_csirl.methods import csirl
from torchrl_csirl.modules import EgoRelativeFeatures
from torchrl_csirl.tasks import SCENARIOS

try:
    from torchrl_csirl.modules import map_each_input_once
except ImportError:  # an older checkout
    map_each_input_once = None


def map_call_ms(batch: int, repeats: int) -> float:
    """Median milliseconds of one call of the merge map on ``batch`` observations (one thread)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        feats = EgoRelativeFeatures.from_scenario(SCENARIOS["merge"])
        obs = torch.rand(batch, feats.in_features, generator=torch.Generator().manual_seed(0)) * 2 - 1
        for _ in range(20):
            feats(obs)
        times = []
        for _ in range(repeats):
            start = time.perf_counter()
            feats(obs)
            times.append((time.perf_counter() - start) * 1e3)
        return statistics.median(times)
    finally:
        torch.set_num_threads(threads)


def _count(fn) -> int:
    """Calls that reach the map's computation (its ``forward`` when the checkout has no memo)."""
    target = "_relative_features" if hasattr(EgoRelativeFeatures, "_relative_features") else "forward"
    original = getattr(EgoRelativeFeatures, target)
    with mock.patch.object(EgoRelativeFeatures, target, autospec=True, side_effect=original) as counted:
        fn()
    return counted.call_count


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--frames", type=int, default=3000, help="transitions collected first")
    parser.add_argument("--batch", type=int, default=256)
    parser.add_argument("--repeats", type=int, default=2000)
    args = parser.parse_args()
    out_dir = tempfile.mkdtemp(prefix="bench_input_maps-")
    cfg = csirl.load_config(["collector.num_workers=1", "logger.backend=none", "logger.progress_bar=false",
                             f"logger.output_dir={out_dir}"])
    run = csirl.make_trainer(cfg, out_dir)
    result = {"cpu": torch.cpu.get_capabilities().get("cpu_name"), "batch": args.batch, "memo": map_each_input_once is not None}
    try:
        _fill(run, args.frames)
        trainer = run.trainer

        def update(kind: str, memo: bool) -> None:
            trainer.updates = 1 if kind == "sac" else 0  # updates % meta_every: 0 makes it a CSIRL update
            with map_each_input_once() if memo else contextlib.nullcontext():
                trainer.update_step(trainer)

        for kind in ("sac", "joint"):
            result[f"{kind}_calls_bare"] = _count(lambda: update(kind, False))
            if map_each_input_once is not None:
                result[f"{kind}_calls_memo"] = _count(lambda: update(kind, True))
    finally:
        run.close()
    result["map_call_ms"] = round(map_call_ms(args.batch, args.repeats), 4)
    if map_each_input_once is not None:
        for kind in ("sac", "joint"):
            saved = result[f"{kind}_calls_bare"] - result[f"{kind}_calls_memo"]
            result[f"{kind}_saved_ms"] = round(saved * result["map_call_ms"], 3)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
