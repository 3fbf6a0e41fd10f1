"""The results tables of docs/benchmark.md and README.md against their records in docs/runs.

Every cell is recomputed with the benchmark's own report code (``torchrl_csirl.scripts.benchmark``:
``read_runs``, ``table_rows``, Welch's t and the verdict rule of ``torchrl_csirl.analysis.verdicts``) and compared
at the precision the page prints, so a figure cannot drift from the records it quotes.
"""
from __future__ import annotations

import os
import re

import pytest

from torchrl_csirl.scripts import benchmark

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

#: the record groups of the benchmark page's tables (its report commands)
DRIVING_GROUPS = ("reference", "bc", "sac", "sqil", "gail", "dac", "iqlearn", "valuedice", "csirl-b", "csirl")
LEARNERS_NOT_BASELINES = ("expert", "random", "csirl", "csirl-b")
NUMBER = re.compile(r"[−-]?\d[\d ]*(?:\.\d+)?")


def numbers(text: str) -> list[tuple[float, float]]:
    """``(value, half a unit of its last printed digit)`` of every number in a table cell ("3 640", "−0.2")."""
    out = []
    for match in NUMBER.finditer(text.replace("**", "")):
        token = match.group().strip().replace(" ", "").replace("−", "-")
        decimals = len(token.partition(".")[2])
        out.append((float(token), 0.5 * 10.0**-decimals + 1e-9))
    return out


def agrees(shown: tuple[float, float], value: float | None) -> bool:
    return value is not None and abs(shown[0] - value) <= shown[1]


def difference_agrees(cell: str, row: dict) -> bool:
    """A difference cell against its row (the verdict rule, ``torchrl_csirl.analysis.verdicts``): ``d (t x)`` in bold
    beyond seed noise, else ``d (t x; detectable m)`` with the minimum detectable difference."""
    shown = numbers(cell)
    if cell.startswith("**") != row["vs_csirl_beyond_noise"] or len(shown) != (2 if row["vs_csirl_beyond_noise"] else 3):
        return False
    values = [row["vs_csirl"], row["vs_csirl_t"], row["vs_csirl_detectable"]]
    return all(agrees(s, v) for s, v in zip(shown, values)) and (len(shown) == 2 or "detectable" in cell)


def caption_counts_the_comparisons(path: str, header: str, rows: dict) -> bool:
    """The caption above the table ``header`` names the Holm correction's number of comparisons, its rows'."""
    with open(os.path.join(ROOT, path)) as f:
        text = f.read()
    caption = text[:text.index(header)].rsplit("\n\n", 2)[-2]
    counts = {r["vs_csirl_comparisons"] for r in rows.values() if r["vs_csirl"] is not None}
    return len(counts) == 1 and f"across the table's {counts.pop()} comparisons" in caption.replace("\n", " ")


def markdown_table(path: str, header: str, occurrence: int = 0) -> dict[str, dict[str, str]]:
    """``row label -> column -> cell`` of the ``occurrence``-th table in ``path`` whose header line starts with ``header``;
    a row's label is its first cell's first word without emphasis (``**csirl** (default preset)`` -> csirl)."""
    with open(os.path.join(ROOT, path)) as f:
        lines = f.read().splitlines()
    start = [i for i, line in enumerate(lines) if line.startswith(header)][occurrence]
    columns = [c.strip() for c in lines[start].strip("|").split("|")]
    rows = {}
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        rows[cells[0].replace("**", "").split()[0]] = dict(zip(columns[1:], cells[1:]))
    assert rows, f"{path}: no rows under {header!r}"
    return rows


def table_cells(*groups: str) -> dict[tuple[str, str], dict]:
    """``(method, scenario) -> table row`` of the records in ``docs/runs/<group>`` for each group, by the report's code."""
    runs = benchmark.read_runs([os.path.join(ROOT, "docs", "runs", g) for g in groups])
    return {(r["method"], r["scenario"]): r for r in benchmark.table_rows(runs)}


@pytest.fixture(scope="module")
def driving() -> dict[tuple[str, str], dict]:
    return table_cells(*DRIVING_GROUPS)


@pytest.fixture(scope="module")
def robotics() -> dict[tuple[str, str], dict]:
    return table_cells("robotics")


def test_table_one_is_its_records_at_one_budget_per_scene(driving):
    table = markdown_table("docs/benchmark.md", "| method | highway-fast |")
    assert set(table) == set(benchmark.METHOD_ORDER)
    for method, columns in table.items():
        for scenario, cell in columns.items():
            row = driving[(method, scenario)]
            assert not benchmark.off_budget(row), (method, scenario, row["frames"])
            ours, _, paper = cell.partition("[")
            shown = numbers(ours)
            expected = [row["normalized_accomplish_rate_mean"], row["normalized_accomplish_rate_std"]]
            assert len(shown) in (1, 2) and all(agrees(s, e) for s, e in zip(shown, expected)), (method, scenario, cell)
            assert len(shown) == 2 or row["runs"] == 1 or row["normalized_accomplish_rate_std"] < 0.005, cell
            if paper:
                assert agrees(numbers(paper)[0], benchmark.PAPER_TABLE[method][scenario]), (method, scenario, cell)
    # bold: the best learner of each column
    for scenario in benchmark.SCENARIO_ORDER:
        learners = [m for m in table if m not in benchmark.REFERENCE_METHODS]
        best = max(learners, key=lambda m: driving[(m, scenario)]["normalized_accomplish_rate_mean"])
        bold = [m for m in learners if table[m][scenario].startswith("**")]
        assert bold == [best], (scenario, bold, best)


def test_outcome_and_difference_tables_are_their_records(driving):
    outcomes = markdown_table("docs/benchmark.md", "| method | highway-fast |", occurrence=1)
    assert set(outcomes) == set(benchmark.METHOD_ORDER) - {"random"}
    for method, columns in outcomes.items():
        for scenario, cell in columns.items():
            row = driving[(method, scenario)]
            success, crash = numbers(cell)
            assert agrees(success, row["success_rate_mean"]) and agrees(crash, row["crash_rate_mean"]), (method, cell)
    differences = markdown_table("docs/benchmark.md", "| − csirl |")
    assert caption_counts_the_comparisons("docs/benchmark.md", "| − csirl |", driving)
    for method, columns in differences.items():
        for scenario, cell in columns.items():
            assert difference_agrees(cell, driving[(method, scenario)]), (method, scenario, cell)


def test_robotics_table_is_its_records(robotics):
    table = markdown_table("docs/benchmark.md", "| method | AntMaze return")
    for method, columns in table.items():
        for column, cell in columns.items():
            scenario = "antmaze-umaze" if column.startswith("AntMaze") else "relocate"
            row = robotics[(method, scenario)]
            if "return" in column:
                shown, expected = numbers(cell), [row["return_mean"], row["return_std"]]
            else:
                shown, expected = numbers(cell), [row["success_rate_mean"], row["accomplish_rate_mean"]]
            assert all(agrees(s, e) for s, e in zip(shown, expected)), (method, column, cell)


def test_locomotion_results_are_their_records():
    rows = table_cells("mujoco")
    table = markdown_table("docs/benchmark.md", "| method | Hopper R / R_expert")
    assert set(table) == {method for method, _ in rows}
    for method, columns in table.items():
        for task, scenario in (("Hopper", "hopper"), ("HalfCheetah", "halfcheetah")):
            row = rows.get((method, scenario))
            best = columns[f"{task} best evaluation"]
            if row is None:  # no finished run yet: an empty cell
                assert columns[f"{task} R / R_expert"] == columns[f"{task} return"] == best == "", (method, columns)
                continue
            normalised, runs_shown = numbers(columns[f"{task} R / R_expert"])
            assert agrees(normalised, row["normalized_return_mean"]) and runs_shown[0] == row["runs"], (method, columns)
            assert agrees(numbers(columns[f"{task} return"])[0], row["return_mean"]), (method, columns)
            if row["normalized_best_eval_return_mean"] is None:  # the reference rows: no evaluations during training
                assert best == "", (method, columns)
            else:
                assert agrees(numbers(best)[0], row["normalized_best_eval_return_mean"]), (method, columns)


def test_locomotion_differences_are_their_records():
    rows = table_cells("mujoco")
    table = markdown_table("docs/benchmark.md", "| − csirl, test return |")
    assert set(table) == {m for m, _ in rows} - {"expert", "random", "csirl"}
    assert caption_counts_the_comparisons("docs/benchmark.md", "| − csirl, test return |", rows)
    for method, columns in table.items():
        for task, scenario in (("Hopper", "hopper"), ("HalfCheetah", "halfcheetah")):
            row, cell = rows.get((method, scenario)), columns[task]
            if row is None or row["vs_csirl"] is None:  # fewer than two seeds on a side
                assert cell == "—", (method, task, cell)
                continue
            assert difference_agrees(cell, row), (method, task, cell)


def test_published_comparison_is_its_data_and_its_records_in_raw_returns():
    """The published table: the papers' raw returns and experts as :data:`benchmark.PUBLISHED_LOCOMOTION` holds
    them, ours the records' raw mean returns (final and best evaluation), each gap divided by the paper's expert."""
    rows = table_cells("mujoco")
    table = markdown_table("docs/benchmark.md", "| method | Hopper: paper")
    assert set(table) == {m for m in benchmark.PUBLISHED_LOCOMOTION if any((m, s) in rows for s in ("hopper", "halfcheetah"))}
    for method, columns in table.items():
        for task, scenario in (("Hopper", "hopper"), ("HalfCheetah", "halfcheetah")):
            published = benchmark.PUBLISHED_LOCOMOTION[method][scenario]
            (header,) = [c for c in columns if c.startswith(f"{task}: paper")]
            assert agrees(numbers(header)[0], published["expert"]), header
            assert agrees(numbers(columns[header])[0], published["return"]), (method, task, columns[header])
            assert published["expert"] == benchmark.PUBLISHED_EXPERTS[scenario]
            for column, field in (("ours, final", "return_mean"), ("ours, best evaluation", "best_eval_return_mean")):
                cell, ours = columns[f"{task}: {column}"], rows[(method, scenario)][field]
                shown, gap = numbers(cell)[:2]
                assert agrees(shown, ours), (method, task, column, cell)
                want = (ours - published["return"]) / published["expert"]
                assert agrees(gap, want), (method, task, column, cell)
                assert ("**" in cell) == (want < -benchmark.PUBLISHED_GAP), (method, task, column, cell)


def test_readme_results_follow_table_one(driving, robotics):
    table = markdown_table("README.md", "| task |")
    for scenario in benchmark.SCENARIO_ORDER:
        cells = table[scenario]
        csirl = driving[("csirl", scenario)]
        mean, std = numbers(cells["CSIRL, ours"])
        assert agrees(mean, csirl["normalized_accomplish_rate_mean"]) and agrees(std, csirl["normalized_accomplish_rate_std"])
        assert agrees(numbers(cells["CSIRL, paper"])[0], benchmark.PAPER_TABLE["csirl"][scenario])
        baselines = [m for m in benchmark.METHOD_ORDER if m not in LEARNERS_NOT_BASELINES]
        best = max(baselines, key=lambda m: driving[(m, scenario)]["normalized_accomplish_rate_mean"])
        named = cells["best baseline, ours"].split()[0].lower()
        assert named == best, (scenario, named, best)
        mean, std = numbers(cells["best baseline, ours"])
        row = driving[(best, scenario)]
        assert agrees(mean, row["normalized_accomplish_rate_mean"]) and agrees(std, row["normalized_accomplish_rate_std"])
    # the robotics rows: success rates (AntMaze's return is its success), CSIRL, CSIRL with cloning, BC
    for label, scenario in (("AntMaze", "antmaze-umaze"), ("Adroit", "relocate")):
        cells = table[label]
        csirl, cloned = numbers(cells["CSIRL, ours"])[0], numbers(cells["CSIRL, ours"])[1:]
        assert agrees(csirl, robotics[("csirl", scenario)]["success_rate_mean"])
        row = robotics[("csirl-bc", scenario)]
        assert all(agrees(s, e) for s, e in zip(cloned, [row["success_rate_mean"], row["success_rate_std"]]))
        assert cells["best baseline, ours"].startswith("BC")
        row = robotics[("bc", scenario)]
        shown = numbers(cells["best baseline, ours"])
        assert all(agrees(s, e) for s, e in zip(shown, [row["success_rate_mean"], row["success_rate_std"]]))


def test_the_sweep_runs_every_cell_at_its_scenes_budget(tmp_path):
    todo, _ = benchmark.plan_cells(["csirl", "sac"], ["roundabout", "relocate"], [0], str(tmp_path), [])
    for cell in todo:
        assert f"collector.total_frames={benchmark.TABLE_BUDGETS[cell.scenario]}" in cell.command, cell.name
    # a user's budget goes after it, so it wins; the report then marks the row as off budget
    (cell,), _ = benchmark.plan_cells(["csirl"], ["roundabout"], [0], str(tmp_path), ["collector.total_frames=110000"])
    assert cell.command.index("collector.total_frames=110000") > cell.command.index("collector.total_frames=60000")
    runs = benchmark.read_runs([os.path.join(ROOT, "docs", "runs", "budget")])
    rows = benchmark.table_rows([r for r in runs if r["scenario"] == "roundabout"])
    assert rows and all(benchmark.off_budget(r) == (r["frames"] == "110000") for r in rows)
    assert "(110000 frames)" in benchmark.markdown_table(rows)


def test_point_maze_table_is_its_records():
    """The point mazes' table (issue 87, part 5): every row's success rate and its difference from CSIRL's."""
    rows = table_cells("pointmaze")
    table = markdown_table("docs/benchmark.md", "| method | U-maze success")
    assert set(table) == {method for method, _ in rows}
    assert caption_counts_the_comparisons("docs/benchmark.md", "| method | U-maze success", rows)
    for method, columns in table.items():
        for maze, scenario in (("U-maze", "PointMaze_UMaze-v3"), ("Medium", "PointMaze_Medium-v3")):
            row = rows.get((method, scenario))
            success, difference = columns[f"{maze} success"], columns[f"− csirl, {maze}"]
            if row is None:  # not run yet: empty cells
                assert success == difference == "", (method, maze, columns)
                continue
            shown, expected = numbers(success), [row["success_rate_mean"], row["success_rate_std"]]
            if row["runs"] == 1:  # one seed: its value, no spread
                expected = expected[:1]
            assert all(agrees(s, e) for s, e in zip(shown, expected)), (method, maze, success)
            if row["vs_csirl"] is None:  # csirl itself, or fewer than two seeds on a side
                assert difference == "—", (method, maze, difference)
                continue
            assert difference_agrees(difference, row), (method, maze, difference)
