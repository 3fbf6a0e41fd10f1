"""docs/studies/scripts/power_table.py: the seeds, detectable differences and seeds needed of the comparisons the pages rest on,
recomputed from the records, are the table docs/studies/power.md shows."""
from __future__ import annotations

import importlib.util
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _power_table_module():
    spec = importlib.util.spec_from_file_location("power_table", os.path.join(ROOT, "docs", "studies", "scripts",
                                                                              "power_table.py"))
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def test_the_power_page_holds_the_table_the_records_give():
    with open(os.path.join(ROOT, "docs", "studies", "power.md"), encoding="utf-8") as f:
        assert _power_table_module().power_table() in f.read()


def test_a_comparison_without_records_on_a_side_says_so_and_needs_no_seed_count(tmp_path):
    module = _power_table_module()
    row = module.power_row(module.COMPARISONS[0], root=str(tmp_path))
    assert row["seeds"] == (0, 0) and row["detectable"] is None and row["needed"] is None


def test_more_spread_asks_for_more_seeds():
    from torchrl_csirl.analysis.verdicts import seeds_needed

    assert seeds_needed(0.02, 0.02, 0.05) < seeds_needed(0.04, 0.04, 0.05) < seeds_needed(0.08, 0.08, 0.05)
