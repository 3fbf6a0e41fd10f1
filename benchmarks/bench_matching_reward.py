"""Cost of the subgoal matching reward per batch of 256 transitions (replay-buffer use).

Compares, in the same process, :class:`~torchrl_csirl.transforms.SubgoalMatchingReward` on a
sampled batch with a transition-by-transition numpy loop of the same equations (the published
code's cost per transition, for scale, is in docs/performance.md); and, on PointMaze U-maze's 25 shipped
demonstrations, the goal-conditioned matching reward (each transition against the demonstration of its goal)
against the plain one on the first demonstration. Prints one JSON line at the end.

Usage::

    python benchmarks/bench_matching_reward.py [--batch 256] [--length 150] [--obs-dim 25]
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import time

import numpy as np
import torch
from tensordict import TensorDict

from torchrl_csirl.transforms import SubgoalMatchingReward


def numpy_loop_reward(obs, next_obs, expert, g, ego, pos, scale):
    """One transition at a time (what a straightforward per-transition implementation does)."""
    out = np.empty(obs.shape[0])
    length = expert.shape[0]
    for b in range(obs.shape[0]):
        dist = np.linalg.norm(expert[:, ego] - obs[b, ego], axis=-1)
        j = length - 1 - int(np.argmin(dist[::-1]))
        t = g if j < g else min(j + 1, length - 1)
        out[b] = scale * (
            np.linalg.norm(obs[b, pos] - expert[t, pos]) - np.linalg.norm(next_obs[b, pos] - expert[t, pos])
        )
    return out


def _time(fn, repeats: int, inner: int) -> float:
    """Median seconds per call over ``repeats`` blocks of ``inner`` calls."""
    fn()
    samples = []
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(inner):
            fn()
        samples.append((time.perf_counter() - start) / inner)
    return statistics.median(samples)


def goal_conditioned_costs(batch: int, repeats: int) -> dict[str, float]:
    """Seconds per batch of the goal-conditioned and the plain matching reward on PointMaze U-maze's demonstrations
    (the recipe's builder, the subgoal a quarter of the way), on ``batch`` demonstrated transitions."""
    from torchrl_csirl.methods import csirl
    from torchrl_csirl.run.task_schemas import prepare_task
    from torchrl_csirl.tasks import TASKS

    args = prepare_task(["env.gym_id=PointMaze_UMaze-v3"])
    spec = TASKS["PointMaze_UMaze-v3"]
    cfg = csirl.CSIRL_RECIPE.load_config(args)
    demos = csirl.load_experts(cfg.expert, spec)
    first = demos.trajectory_observations(0, include_final=True)
    subgoal = first.shape[0] // 4
    goal = csirl.make_matching(cfg, spec, first, subgoal, demos)
    plain = csirl.make_matching(csirl.CSIRL_RECIPE.load_config([*args, "csirl.goal_conditioned=false"]), spec, first,
                                subgoal, demos)
    td = demos.transitions()[torch.randint(0, len(demos), (batch,), generator=torch.Generator().manual_seed(0))]
    return {"goal": _time(lambda: goal(td), repeats, 50), "plain": _time(lambda: plain(td), repeats, 50),
            "demonstrations": goal.num_demonstrations}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=256)
    parser.add_argument("--length", type=int, default=150, help="curriculum trajectory length L")
    parser.add_argument("--obs-dim", type=int, default=25)
    parser.add_argument("--repeats", type=int, default=15)
    parser.add_argument("--threads", type=int, default=2, help="torch intra-op threads")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    g = torch.Generator().manual_seed(0)
    expert = torch.randn(args.length, args.obs_dim, generator=g).cumsum(0)
    ego, pos = [0, 1, 2, 3, 4], [1]
    transform = SubgoalMatchingReward(
        expert, subgoal=args.length // 3, ego_feature_indices=ego, position_feature_indices=pos, scale=700.0
    )
    obs = expert[torch.randint(0, args.length, (args.batch,), generator=g)] + torch.randn(args.batch, args.obs_dim, generator=g)
    next_obs = obs + 0.1 * torch.randn(args.batch, args.obs_dim, generator=g)
    td = TensorDict({"observation": obs, "next": {"observation": next_obs}}, [args.batch])

    vec_s = _time(lambda: transform(td), args.repeats, 50)
    obs_np, next_np, expert_np = obs.double().numpy(), next_obs.double().numpy(), expert.double().numpy()
    loop_s = _time(
        lambda: numpy_loop_reward(obs_np, next_np, expert_np, transform.subgoal, ego, pos, 700.0), max(3, args.repeats // 3), 2
    )
    # same numbers from both implementations
    ref = numpy_loop_reward(obs_np, next_np, expert_np, transform.subgoal, ego, pos, 700.0)
    max_abs_diff = float(np.abs(transform(td)["next", "matching_reward"].squeeze(-1).double().numpy() - ref).max())
    goal = goal_conditioned_costs(args.batch, args.repeats)
    result = {
        "benchmark": "matching_reward",
        "batch": args.batch,
        "length": args.length,
        "obs_dim": args.obs_dim,
        "torch_threads": torch.get_num_threads(),
        "vectorised_ms_per_batch": round(vec_s * 1e3, 4),
        "vectorised_us_per_transition": round(vec_s * 1e6 / args.batch, 4),
        "numpy_loop_ms_per_batch": round(loop_s * 1e3, 3),
        "speedup_vs_loop": round(loop_s / vec_s, 1),
        "published_code_ms_per_transition": 13.0,
        "max_abs_diff_vs_loop": max_abs_diff,
        "pointmaze_goal_conditioned_ms_per_batch": round(goal["goal"] * 1e3, 3),
        "pointmaze_plain_ms_per_batch": round(goal["plain"] * 1e3, 3),
        "pointmaze_goal_conditioned_over_plain": round(goal["goal"] / goal["plain"], 2),
        # context for absolute numbers on a shared machine
        "load_average_1min": round(os.getloadavg()[0], 2),
    }
    print(json.dumps(result))


if __name__ == "__main__":
    main()
