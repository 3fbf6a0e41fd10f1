"""``torchrl-csirl outcomes``: how a robotics policy's test episodes end (real AntMaze and Relocate envs)."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from tensordict import TensorDict

from torchrl_csirl._compat import gym_env_of
from torchrl_csirl.modules import make_actor, save_policy
from torchrl_csirl.scripts import robotics_outcomes
from torchrl_csirl.tasks import make_env
from torchrl_csirl.tasks.robotics import ROBOTICS_TASKS


def _saved(tmp_path, task: str) -> str:
    spec = ROBOTICS_TASKS[task]
    return str(save_policy(make_actor(spec.obs_dim, spec.action_dim), tmp_path / f"{task}.pt",
                           obs_dim=spec.obs_dim, action_dim=spec.action_dim, scenario=task, frames=0))


def _episode(**flags: list[bool]) -> TensorDict:
    steps = len(next(iter(flags.values())))
    return TensorDict({"next": {k: torch.tensor(v).reshape(steps, 1) for k, v in flags.items()}}, [steps])


def test_antmaze_end_cells_count_along_the_route_and_outcomes_follow_the_flags():
    env = make_env("antmaze-umaze", seed=0)
    try:
        task_env = gym_env_of(env).unwrapped
        cells = task_env.route_cells
        centre = [task_env.maze.cell_rowcol_to_xy(np.array(c)) for c in cells]
        assert robotics_outcomes.route_cell(task_env, centre[0]) == "0"
        assert robotics_outcomes.route_cell(task_env, centre[-1]) == str(len(cells) - 1)
        assert robotics_outcomes.route_cell(task_env, np.array([-2.0, 0.0])) == "off"  # inside the central wall
        env.reset()
        reached = robotics_outcomes.antmaze_record(_episode(success=[False, True], crashed=[False, False]), task_env)
        flipped = robotics_outcomes.antmaze_record(_episode(success=[False] * 3, crashed=[False, True, True]), task_env)
        short = robotics_outcomes.antmaze_record(_episode(success=[False] * 2, crashed=[False] * 2), task_env)
    finally:
        env.close()
    assert (reached["outcome"], flipped["outcome"], short["outcome"]) == ("goal", "flipped", "short")
    assert flipped["flip_step"] == 2 and short["flip_step"] is None
    assert short["end_cell"] == "0"  # just after the reset the ant stands in the start cell


def test_main_reports_each_task_and_refuses_a_driving_policy(tmp_path, capsys):
    ant = robotics_outcomes.main([_saved(tmp_path, "antmaze-umaze"), "--episodes", "1"])
    assert json.loads(capsys.readouterr().out.strip().splitlines()[-1])["end_cells"] == ant["end_cells"]
    assert ant["episodes"] == 1 and sum(ant[o] for o in robotics_outcomes.OUTCOMES["antmaze-umaze"]) == 1
    assert sum(e["episodes"] for e in ant["end_cells"].values()) == 1 - ant["goal"]
    hand = robotics_outcomes.main([_saved(tmp_path, "relocate"), "--episodes", "2"])
    assert sum(hand[o] for o in robotics_outcomes.OUTCOMES["relocate"]) == 2
    assert 0.0 <= hand["accomplish_rate"] <= 1.0 and hand["final_distance"] > 0.0
    driving = save_policy(make_actor(25, 2), tmp_path / "merge.pt", obs_dim=25, action_dim=2, scenario="merge", frames=0)
    with pytest.raises(SystemExit):
        robotics_outcomes.main([str(driving)])
    with pytest.raises(SystemExit):
        robotics_outcomes.main([str(driving), "--episodes", "0"])


def test_warm_start_probe_clones_the_actor_as_a_run_does_and_rolls_its_test_episodes(tmp_path):
    import warm_start_probe

    from torchrl_csirl.modules import load_policy

    stats = warm_start_probe.main(["--updates", "20", "--episodes", "1", "--out", str(tmp_path), "logger.progress_bar=false"])
    assert stats["updates"] == 20 and stats["episodes"] == 1
    assert sum(stats[o] for o in robotics_outcomes.OUTCOMES["antmaze-umaze"]) == 1
    saved = load_policy(stats["policy"])
    spec = ROBOTICS_TASKS["antmaze-umaze"]
    assert sum(p.numel() for p in saved.parameters()) == sum(
        p.numel() for p in make_actor(spec.obs_dim, spec.action_dim).parameters())
    with pytest.raises(SystemExit):
        warm_start_probe.main(["--updates", "0"])


def test_outcomes_reads_a_policy_by_its_tasks_family_and_refuses_another_task(tmp_path, capsys):
    from torchrl_csirl.scripts import outcomes

    hand = outcomes.main([_saved(tmp_path, "relocate"), "--episodes", "1"])
    assert json.loads(capsys.readouterr().out.strip().splitlines()[-1])["task"] == "relocate" and hand["episodes"] == 1
    hopper = save_policy(make_actor(11, 3), tmp_path / "hopper.pt", obs_dim=11, action_dim=3, scenario="hopper", frames=0)
    with pytest.raises(SystemExit):
        outcomes.main([str(hopper)])
    assert "a policy for 'hopper', not one of the driving scenarios and robotics tasks" in capsys.readouterr().err
