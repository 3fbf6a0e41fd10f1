"""``torchrl-csirl``'s commands (``torchrl_csirl/scripts/cli.py``): each answers ``--help``, the usage lists them;
the commands that read runs and records (``compare``, ``curves``, ``health-table``) on the recorded runs; and the
study pages' scripts (``docs/studies/scripts``), which run as scripts from any working directory."""
from __future__ import annotations

import os
import subprocess
import sys

import pytest

from torchrl_csirl.scripts import cli

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
STUDY_SCRIPTS = os.path.join(ROOT, "docs", "studies", "scripts")
SCRIPTS = sorted(name for name in os.listdir(STUDY_SCRIPTS) if name.endswith(".py"))


@pytest.mark.parametrize("command", list(cli.COMMANDS))
def test_every_command_answers_help(command, capsys):
    try:
        cli.main([command, "--help"])
    except SystemExit as exit:
        assert exit.code in (0, None)
    out = capsys.readouterr().out
    assert out.strip()
    if command in cli.ANALYSIS or command == "diagnose":
        assert out.startswith(f"usage: torchrl-csirl {command}")


def test_the_usage_lists_every_command_and_an_unknown_one_is_one_line(capsys):
    cli.main([])
    usage = capsys.readouterr().out
    assert all(f"\n  {name} " in usage for name in cli.COMMANDS)
    assert set(cli.COMMANDS) == set(cli._RUNNERS)
    with pytest.raises(SystemExit) as exit:
        cli.main(["no-such-command"])
    assert exit.value.code == 2
    assert capsys.readouterr().err.startswith("error: torchrl-csirl no-such-command: unknown command; one of train")


def test_a_commands_error_is_one_line_and_exit_status_2(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit:
        cli.main(["summarize", str(tmp_path / "missing")])
    assert exit.value.code == 2 and capsys.readouterr().err.count("\n") == 1
    with pytest.raises(SystemExit) as exit:  # a run that cannot be recorded: its line, exit status 1
        cli.main(["record", str(tmp_path), "--into", str(tmp_path / "records")])
    assert exit.value.code == 1 and "has no summary.json" in capsys.readouterr().err


def test_the_study_scripts_are_no_command_of_the_package():
    assert SCRIPTS == ["anchor_records.py", "entropy_bonus_records.py", "locomotion_probe.py", "matching_route_probe.py",
                       "meta_gradient_balance.py", "point_maze_experts.py", "power_table.py", "subgoal_lead_records.py",
                       "termination_probe.py", "warm_start_probe.py"]
    package = os.listdir(os.path.join(ROOT, "torchrl_csirl", "scripts"))
    assert not set(SCRIPTS) & set(package) and not set(SCRIPTS) & set(os.listdir(os.path.join(ROOT, "recipes")))


@pytest.mark.parametrize("script", SCRIPTS)
def test_a_study_script_runs_from_another_directory(script, tmp_path):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([ROOT, os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run([sys.executable, os.path.join(STUDY_SCRIPTS, script), "--help"], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith(f"usage: {script}")


def test_compare_runs_sets_two_seed_sets_side_by_side_with_welchs_test(capsys):
    """The recorded CSIRL and CSIRL-B runs on merge: each side's mean over its 3 seeds, Welch's t of B - A, the
    verdict and, for records made before provenance existed, ``provenance: unknown``."""
    import json

    from torchrl_csirl.analysis.summaries import find_summaries
    from torchrl_csirl.analysis.verdicts import compare_seeds
    from torchrl_csirl.scripts import compare

    runs = os.path.join(ROOT, "docs", "runs")
    first = [os.path.join(runs, "csirl", f"merge-csirl-s{s}") for s in range(3)]
    second = [os.path.join(runs, "csirl-b", f"merge-b-s{s}") for s in range(3)]
    result = compare.main([*first, "--against", *second, "--labels", "csirl", "csirl-b",
                                "--metrics", "normalized_accomplish_rate"])
    last, table = capsys.readouterr()
    row = result["rows"][0]
    values = [[json.load(open(p))["normalized_accomplish_rate"] for p in find_summaries(side)] for side in (first, second)]
    assert row["n"] == [3, 3] and row["methods"] == ["csirl", "csirl-b"]
    assert row["first"]["mean"] == pytest.approx(sum(values[0]) / 3)
    assert row["test"]["t"] == pytest.approx(compare_seeds(values[1], values[0]).t)
    assert row["test"]["verdict"] == compare_seeds(values[1], values[0]).verdict
    assert "| merge" in table and json.loads(last.splitlines()[-1])["labels"] == ["csirl", "csirl-b"]
    assert "provenance: unknown for 6 runs" in table


def test_compare_runs_across_scenarios_sets_a_task_against_its_variant():
    """``--across-scenarios``: the merge runs against the roundabout ones as two groups (a task against its variant)."""
    from torchrl_csirl.scripts import compare

    runs = os.path.join(ROOT, "docs", "runs", "csirl")
    first = [os.path.join(runs, f"merge-csirl-s{s}") for s in range(3)]
    second = [os.path.join(runs, f"roundabout-csirl-s{s}") for s in range(3)]
    assert compare.compare([], [], by_scenario=False) == []
    per_task = compare.main([*first, "--against", *second, "--metrics", "success_rate", "--across-scenarios"])
    (row,) = per_task["rows"]
    assert row["scenario"] == "merge / roundabout" and row["n"] == [3, 3]
    with pytest.raises(SystemExit):  # without it the two sides share no scenario
        compare.main([*first, "--against", *second, "--metrics", "success_rate"])


def test_anchor_records_reads_how_firmly_the_cloning_term_held_per_round(capsys):
    """The anchored AntMaze records: the actor's distance to the demonstrations' actions against ``|L_actor|``."""
    import csv

    import anchor_records

    runs = [os.path.join(ROOT, "docs", "runs", "antmaze-bc-path", f"antmaze-umaze-csirl-s{s}") for s in range(3)]
    result = anchor_records.main([*runs, "--threshold", "20"])
    assert "| Spearman" in capsys.readouterr().err
    for run, row in zip(runs, result["rows"]):
        with open(os.path.join(run, "rounds.csv")) as f:
            rounds = list(csv.DictReader(f))
        weak = [float(r["actor_bc_mse"]) for r in rounds if abs(float(r["loss_actor"])) < 20]
        assert row["rounds"] == len(rounds) and row["rounds_weak"] == len(weak)
        assert row["mse_weak"] == pytest.approx(sum(weak) / len(weak)) and -1 <= row["spearman"] <= 1
    with pytest.raises(SystemExit, match="no rounds.csv"):
        anchor_records.main([os.path.join(ROOT, "docs", "runs", "robotics", "relocate-csirl-bc-s0")])


def test_plot_curves_draws_each_group_at_the_frames_all_its_seeds_evaluated(tmp_path, capsys):
    """The AntMaze study's records: the warm-start seeds differ in carrying a frame-0 evaluation, so their curve
    starts at the first round; each group's last point is its seeds' mean there."""
    import json

    from torchrl_csirl.scripts import curves
    from torchrl_csirl.sweep.results import eval_curve

    runs = os.path.join(ROOT, "docs", "runs")
    groups = {name: [os.path.join(runs, name, f"antmaze-umaze-csirl-s{s}") for s in range(3)]
              for name in ("antmaze-warmstart", "antmaze-bc-path")}
    out = tmp_path / "curves.png"
    args = [arg for name, dirs in groups.items() for arg in ("--group", name, *dirs)]
    result = curves.main([*args, "--reference", "bc, test=0.64", "--output", str(out)])
    assert out.stat().st_size > 10_000 and json.loads(capsys.readouterr().out.splitlines()[-1]) == result
    for name, dirs in groups.items():
        seeds = [eval_curve(d) for d in dirs]
        frames, _ = curves.common_frames(seeds)
        assert frames == sorted(set(seeds[0][0]) & set(seeds[1][0]) & set(seeds[2][0]))
        last = [dict(zip(*c))[frames[-1]] for c in seeds]
        assert result["last"][name] == {"runs": 3, "frames": frames[-1], "mean": pytest.approx(sum(last) / 3)}
    assert 0.0 not in curves.common_frames([eval_curve(d) for d in groups["antmaze-warmstart"]])[0]
    with pytest.raises(SystemExit, match="no 'no_such_key'"):
        curves.main([*args, "--metric", "no_such_key", "--output", str(out)])
    with pytest.raises(SystemExit):  # a reference without its level
        curves.main([*args, "--reference", "bc", "--output", str(out)])


def test_matching_route_probe_scores_the_demonstrations_route_per_rule(capsys):
    """AntMaze's shipped demonstrations at the curriculum's last subgoal: the straight line to the goal (``final``)
    charges the route's first leg and pays it far less in all than the distance along the path."""
    import json

    import matching_route_probe

    rows = matching_route_probe.main(["--task", "antmaze-umaze", "--subgoals", "1.0", "--rules", "final", "path"])
    final, path = rows
    assert (final["rule"], path["rule"]) == ("final", "path") and final["demonstrations"] == 24
    assert final["quarters"][0] < 0 < path["quarters"][0] and final["opening"] < 10 * path["opening"] < 0
    assert 0 < final["return"] < path["return"]
    assert json.loads(capsys.readouterr().out.strip().splitlines()[-1])["rows"] == rows


def test_entropy_bonus_records_rereads_a_recorded_critic_check_with_sacs_entropy_bonus(capsys):
    """The anchored AntMaze seed 1's report (written before the report counted the entropy bonus) flagged critics
    under-valuing the policy's states (-37 against a reward return of 1); alpha 0.057 and entropy -8 at its last
    round make the bonus about -45 over the horizon, and the critics calibrated."""
    import json

    import entropy_bonus_records

    record = os.path.join(ROOT, "docs", "runs", "antmaze-warmstart-bc", "antmaze-umaze-csirl-s1")
    (row,) = entropy_bonus_records.main([record])
    assert row["bonus"] == pytest.approx(row["alpha"] * row["entropy"] * 99.0, rel=1e-3) and row["bonus"] < -40
    policy = row["policy"]
    assert policy["recorded_ok"] is False and policy["reread_ok"] is True
    assert policy["soft_return"] == pytest.approx(policy["return"] + row["bonus"])
    assert json.loads(capsys.readouterr().out.strip().splitlines()[-1])[0]["record"] == record


def test_subgoal_lead_records_reads_where_a_recorded_curriculum_left_its_policy(capsys):
    """AntMaze anchored with the `path` target: each subgoal at the end of the demonstration, each ant stopped within a
    third of the way: the curriculum moved on without the policy; on the U-maze, CSIRL's point mass ends at the goal."""
    import subgoal_lead_records

    records = [os.path.join(ROOT, "docs", "runs", "antmaze-bc-path", f"antmaze-umaze-csirl-s{seed}") for seed in range(3)]
    maze = os.path.join(ROOT, "docs", "runs", "pointmaze", "PointMaze_UMaze-v3-csirl-s0")
    result = subgoal_lead_records.main([*records, maze, ROOT])  # ROOT: no health.json, skipped
    assert result["records"] == 4 and result["moved_on"] == records
    ant = result["rows"][0]
    assert ant["subgoal_share"] > 0.9 and ant["progress_median"] < 0.4 and ant["episodes_flagged"] is True
    assert "| yes |" in capsys.readouterr().err


def test_health_flag_table_counts_flags_on_failed_and_succeeded_records(capsys):
    """The HalfCheetah's CSIRL runs (0.94, 0.87 and 0.27 of the expert's return, the expert's record beside them) and
    PointMaze U-maze with one demonstration (success 0.52): the flipped cheetah and the maze are failures; only they
    flag states_off_the_demonstrations and demonstrations_share_a_goal. With --held-out every one is left out: each
    set a threshold."""
    from torchrl_csirl.scripts import health_table

    cheetahs = [os.path.join(ROOT, "docs", "runs", "mujoco", f"halfcheetah-csirl-s{seed}") for seed in range(3)]
    maze = os.path.join(ROOT, "docs", "runs", "pointmaze-onedemo", "PointMaze_UMaze-v3-csirl-s0")
    result = health_table.main([*cheetahs, maze, ROOT, "--runs"])  # ROOT: no record, skipped
    assert result["records"] == 4 and result["succeeded"] == 2 and result["bar"] == health_table.BAR
    scores = {os.path.basename(r["record"]): (round(r["score"], 2), r["metric"]) for r in result["rows"]}
    assert scores["halfcheetah-csirl-s2"] == (0.27, "return over the expert's")
    assert scores["PointMaze_UMaze-v3-csirl-s0"] == (0.52, "success rate")
    off = result["checks"]["states_off_the_demonstrations"]
    assert (off["failed_flagged"], off["failed"], off["succeeded_flagged"], off["succeeded"]) == (1, 1, 0, 2)
    assert off["unanswered"] == 1  # the maze's report predates the check
    goal = result["checks"]["demonstrations_share_a_goal"]
    assert (goal["failed_flagged"], goal["succeeded_flagged"]) == (1, 0)
    table = capsys.readouterr().err
    assert "| `states_off_the_demonstrations` | 1 of 1 (100%) | 0 of 2 (0%) | 1 |" in table
    held_out = health_table.main([*cheetahs, maze, "--held-out"])
    assert held_out["records"] == 0 and len(held_out["left_out"]) == 4
    assert health_table.main([maze, "--bar", "0.5"])["succeeded"] == 1  # the bar decides


def test_the_own_task_page_holds_the_held_out_table_its_records_give():
    import re

    from torchrl_csirl.scripts import health_table

    with open(os.path.join(ROOT, "docs", "own-task.md"), encoding="utf-8") as f:
        page = f.read()
    marker = re.search(r"<!-- held-out-table: (.*?) -->\n(.*?)\n<!-- /held-out-table -->", page, re.S)
    assert marker, "docs/own-task.md: no held-out table"
    cwd = os.getcwd()
    try:
        os.chdir(ROOT)
        table = health_table.held_out_table(marker.group(1).split())
    finally:
        os.chdir(cwd)
    assert marker.group(2) == table, "regenerate: the records give\n" + table
    assert int(re.search(r"flags failed runs \((\d+)\)", table).group(1)) > 0
