"""tools/: the analysis and probe scripts run as scripts from their own folder (their imports of the
run layer (``torchrl_csirl.launch``) resolve from any working directory)."""
from __future__ import annotations

import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TOOLS = os.path.join(ROOT, "tools")
SCRIPTS = sorted(name for name in os.listdir(TOOLS) if name.endswith(".py") and name != "policy_cli.py")


def test_the_analysis_scripts_live_in_tools_and_recipes_holds_what_users_run():
    assert SCRIPTS == ["locomotion_probe.py", "meta_gradient_balance.py", "policy_outcomes.py",
                       "record_runs.py", "robotics_outcomes.py", "summarize_runs.py", "termination_probe.py"]
    assert not set(SCRIPTS) & set(os.listdir(os.path.join(ROOT, "recipes")))


@pytest.mark.parametrize("script", SCRIPTS)
def test_a_tool_runs_from_another_directory(script, tmp_path):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([ROOT, os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run([sys.executable, os.path.join(TOOLS, script), "--help"], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith(f"usage: {script}")
