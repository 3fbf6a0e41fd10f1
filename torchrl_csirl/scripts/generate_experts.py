"""Roll a task's expert and write expert demonstrations (``ExpertDemonstrations`` ``.npz``).

Experts: the privileged expert driver on the driving scenarios, the DAPG policy on ``relocate``,
the waypoint-driven goal-reaching ant on ``antmaze-umaze`` (the shipped ant, or ``--ant-policy``: a
run of ``recipes/train_ant_expert.py``).

Episode ``i`` is reset with seed ``--seed + i``; the expert itself is deterministic, so the same
command writes the same bytes. The script ends with ONE JSON line with the statistics of every
rolled episode (``success_rate``, ``crash_rate``, ``accomplish_rate``, ``return_mean``, ...,
``episodes``, ``kept``, ``rejected``). Recorded episodes (``--out``, ``--shipped``) end at the
ego's arrival (last transition ``truncated`` where the env does not itself terminate there;
``--full-episodes`` keeps recording until the env ends the episode) on tasks whose spec says
``episode_ends_at_goal``; Relocate episodes always run their 200 steps (the ball must stay at the
target). Evaluation without ``--out`` runs full episodes.

Examples:
    python recipes/generate_experts.py --scenario merge --episodes 5 --seed 0 --out /tmp/merge_5.npz
    python recipes/generate_experts.py --scenario roundabout --episodes 25 --seed 1000 \\
        --only-successful --out /tmp/roundabout_25.npz
    python recipes/generate_experts.py --scenario highway-fast --episodes 1 --empty-road --out /tmp/c.npz
    # evaluation only (no file): 100 seeded episodes
    python recipes/generate_experts.py --scenario intersection --episodes 100 --seed 10000
    # the shipped datasets of one scenario (torchrl_csirl/data/experts/<scenario>/)
    python recipes/generate_experts.py --scenario merge --shipped
    # Relocate (DAPG expert): the shipped 25 trajectories, and an evaluation on unseen seeds
    python recipes/generate_experts.py --scenario relocate --episodes 25 --seed 0 --only-successful \
        --out torchrl_csirl/data/experts/relocate/expert_25.npz
    python recipes/generate_experts.py --scenario relocate --episodes 20 --seed 10000
    # AntMaze: the waypoint expert (the shipped ant) on unseen seeds; the shipped 25 trajectories
    python recipes/generate_experts.py --scenario antmaze-umaze --episodes 100 --seed 10000
    python recipes/generate_experts.py --scenario antmaze-umaze --episodes 25 --seed 0 --only-successful \
        --out torchrl_csirl/data/experts/antmaze-umaze/expert_25.npz
    # ... as D4RL recorded AntMaze: N(0, 0.2) noise on the executed (and recorded) actions
    python recipes/generate_experts.py --scenario antmaze-umaze --episodes 25 --seed 0 --only-successful \
        --action-noise 0.2 --out /tmp/antmaze_noisy_25.npz
    # ... or those perturbed states labelled with the expert's own action (DART)
    python recipes/generate_experts.py --scenario antmaze-umaze --episodes 25 --seed 0 --only-successful \
        --action-noise 0.2 --record-expert-action --out /tmp/antmaze_dart_25.npz
    # ... or with another goal-reaching ant
    python recipes/generate_experts.py --scenario antmaze-umaze --ant-policy runs/ant-goal-sac-s0-... \
        --episodes 100 --seed 10000
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from typing import Any

import numpy as np

SHIPPED_SEED = 20230608
"""Base seed of the shipped datasets (trajectory 0 of the empty-road curriculum uses this seed)."""
SHIPPED_TRAJECTORIES = 25
ACTION_UNITS = {
    "driving": "normalised: [acceleration / 15 m/s^2, steering / (pi/2) rad]",
    "robotics": "the gymnasium-robotics action in [-1, 1] (mapped by the env to actuator ranges)",
}
"""What an action means, per task family (recorded in the datasets' metadata)."""


def shipped_scenarios() -> tuple[str, ...]:
    """The scenarios of ``--shipped`` (empty-road and traffic curricula): the driving scenes of the task registry."""
    from torchrl_csirl.tasks.registry import task_names

    return task_names(family="driving")


def expert_options(scenario: str, ant_policy: str | None) -> dict[str, Any]:
    """The keywords of ``make_expert(scenario, ...)``: the ant's policy for AntMaze (``None``: the
    shipped ant), else none."""
    return {"policy": ant_policy} if scenario == "antmaze-umaze" else {}


def expert_metadata(scenario: str, **options: Any) -> dict[str, Any]:
    """The ``generator`` (the expert's class) and ``action_units`` entries of a task's datasets, and
    ``expert_settings`` for an expert that has ``settings`` (the AntMaze controller's)."""
    from torchrl_csirl.tasks import resolve_scenario
    from torchrl_csirl.tasks.experts import make_expert

    expert = make_expert(scenario, **options)
    expert_class = type(expert)
    meta: dict[str, Any] = {
        "generator": f"{expert_class.__module__}.{expert_class.__qualname__}",
        "action_units": ACTION_UNITS[resolve_scenario(scenario).family],
    }
    if hasattr(expert, "settings"):
        meta["expert_settings"] = dict(expert.settings)
    return meta


def _progress(iterable: Any, total: int, desc: str) -> Any:
    try:
        from tqdm import tqdm
    except ImportError:  # pragma: no cover
        return iterable
    return tqdm(iterable, total=total, desc=desc, file=sys.stderr, dynamic_ncols=True)


def roll_episodes(
    scenario: str,
    episodes: int,
    seed: int,
    empty_road: bool = False,
    only_successful: bool = False,
    max_attempts: int | None = None,
    desc: str | None = None,
    end_at_arrival: bool = False,
    expert_kwargs: dict[str, Any] | None = None,
    action_noise: float = 0.0,
    record_expert_action: bool = False,
) -> tuple[list[dict], list[dict]]:
    """Roll expert episodes with seeds ``seed, seed + 1, ...`` (``expert_kwargs``: ``make_expert``'s options;
    ``action_noise``, ``record_expert_action``: Gaussian noise on the executed actions, and which action
    is recorded, see :func:`~torchrl_csirl.tasks.expert_rollout.rollout_expert`).

    With ``end_at_arrival`` (used when recording), each episode ends at the ego's arrival (see
    :func:`~torchrl_csirl.tasks.expert_rollout.rollout_expert`); otherwise it runs until the env ends it.

    With ``only_successful``, rolls until ``episodes`` successful ones are collected (at most
    ``max_attempts`` episodes, default ``4 * episodes``). Returns (kept episodes, all episodes).
    """
    from torchrl_csirl.tasks import make_gym_env, resolve_scenario
    from torchrl_csirl.tasks.expert_rollout import rollout_expert
    from torchrl_csirl.tasks.experts import make_expert

    end_at_arrival = end_at_arrival and resolve_scenario(scenario).episode_ends_at_goal
    env = make_gym_env(scenario)
    expert = make_expert(scenario, **(expert_kwargs or {}))
    attempts = episodes if not only_successful else (max_attempts or 4 * episodes)
    kept: list[dict] = []
    rolled: list[dict] = []
    bar = _progress(range(attempts), attempts, desc or scenario)
    for i in bar:
        episode = rollout_expert(
            env, seed=seed + i, expert=expert, scenario=scenario, empty_road=empty_road,
            end_at_arrival=end_at_arrival, action_noise=action_noise, record_expert_action=record_expert_action,
        )
        rolled.append(episode)
        if episode["success"] or not only_successful:
            kept.append(episode)
        if hasattr(bar, "set_postfix"):
            bar.set_postfix(
                kept=len(kept),
                success=f"{np.mean([e['success'] for e in rolled]):.2f}",
                accomplish=f"{np.mean([e['accomplish_rate'] for e in rolled]):.3f}",
            )
        if only_successful and len(kept) >= episodes:
            break
    env.close()
    return kept, rolled


def summarize(rolled: list[dict], kept: list[dict]) -> dict[str, Any]:
    """Statistics over all rolled episodes (success / crash / accomplish rates)."""
    return {
        "episodes": len(rolled),
        "kept": len(kept),
        "rejected": len(rolled) - len(kept),
        "success_rate": float(np.mean([e["success"] for e in rolled])),
        "crash_rate": float(np.mean([e["crashed"] for e in rolled])),
        "offroad_rate": float(np.mean([e["offroad"] for e in rolled])),
        "accomplish_rate": float(np.mean([e["accomplish_rate"] for e in rolled])),
        "accomplish_rate_min": float(np.min([e["accomplish_rate"] for e in rolled])),
        "mean_length": float(np.mean([e["length"] for e in rolled])),
        "return_mean": float(np.mean([e["return"] for e in rolled])),
        "return_min": float(np.min([e["return"] for e in rolled])),
        "return_max": float(np.max([e["return"] for e in rolled])),
        "success_steps_mean": float(np.mean([e["success_steps"] for e in rolled])),
        "success_steps_min": int(np.min([e["success_steps"] for e in rolled])),
    }


def build_demonstrations(episodes: list[dict], metadata: dict[str, Any]):
    """Pack episodes into an :class:`~torchrl_csirl.data.ExpertDemonstrations`."""
    from torchrl_csirl.data.expert import ExpertDemonstrations

    records = [
        {
            "observation": e["observation"],
            "action": e["action"],
            "next_observation": e["next_observation"],
            "terminated": e["terminated"],
            "truncated": e["truncated"],
            "reward": e["reward"],
        }
        for e in episodes
    ]
    per_episode = [
        {
            "seed": e["seed"],
            "empty_road": e["empty_road"],
            "end_at_arrival": e.get("end_at_arrival", False),
            "success": e["success"],
            "accomplish_rate": round(e["accomplish_rate"], 6),
            "length": e["length"],
        }
        for e in episodes
    ]
    return ExpertDemonstrations.from_episodes(records, metadata={**metadata, "episodes": per_episode})


def generate_shipped(scenario: str, out_dir: str, seed: int = SHIPPED_SEED) -> dict[str, Any]:
    """Write ``empty_25.npz`` and ``traffic_25.npz`` for a scenario.

    * traffic episodes: the first 25 *successful* expert episodes with seeds ``seed + 1, seed + 2, ...``;
    * ``traffic_25``: those 25 (trajectory 0 = the with-traffic curriculum trajectory);
    * ``empty_25``: trajectory 0 replaced by the empty-road curriculum trajectory (seed ``seed``),
      followed by traffic episodes 1..24.

    Smaller dataset sizes (1, 5, 10, 15, 20) are the nested prefixes (``ExpertDemonstrations.subset``).
    """
    empty, empty_rolled = roll_episodes(
        scenario, 1, seed, empty_road=True, only_successful=True, max_attempts=10, desc=f"{scenario} empty",
        end_at_arrival=True,
    )
    if not empty:
        raise RuntimeError(f"the expert failed the empty-road episode of {scenario!r}.")
    traffic, rolled = roll_episodes(
        scenario, SHIPPED_TRAJECTORIES, seed + 1, only_successful=True, max_attempts=8 * SHIPPED_TRAJECTORIES,
        desc=f"{scenario} traffic", end_at_arrival=True,
    )
    if len(traffic) < SHIPPED_TRAJECTORIES:
        raise RuntimeError(f"only {len(traffic)} successful traffic episodes for {scenario!r}.")
    stats = summarize(rolled, traffic)
    base_meta = {
        "scenario": scenario,
        **expert_metadata(scenario),
        "command": f"python recipes/generate_experts.py --scenario {scenario} --shipped --seed {seed}",
        "base_seed": seed,
    }
    os.makedirs(out_dir, exist_ok=True)
    written = {}
    for curriculum, episodes in (("empty", empty + traffic[1:]), ("traffic", traffic)):
        demos = build_demonstrations(
            episodes, {**base_meta, "curriculum": curriculum, "num_trajectories": len(episodes)}
        )
        path = demos.save(os.path.join(out_dir, f"{curriculum}_{SHIPPED_TRAJECTORIES}.npz"))
        written[curriculum] = path
    return {**stats, "scenario": scenario, "files": written, "empty_road_episodes": len(empty_rolled)}


def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    from torchrl_csirl.tasks.experts import expert_tasks

    parser.add_argument("--scenario", required=True, choices=list(expert_tasks()))
    parser.add_argument("--episodes", type=int, default=25, help="episodes to roll (kept ones with --only-successful)")
    parser.add_argument("--seed", type=int, default=None, help="seed of the first episode (then +1 per episode)")
    parser.add_argument("--out", default=None, help="output .npz (omit to only evaluate)")
    parser.add_argument("--empty-road", action="store_true", help="remove all other vehicles (curriculum trajectory)")
    parser.add_argument("--only-successful", action="store_true", help="keep only successful episodes")
    parser.add_argument("--max-attempts", type=int, default=None, help="cap on episodes rolled with --only-successful")
    parser.add_argument(
        "--full-episodes", action="store_true",
        help="with --out: record until the env ends the episode (default: end at the ego's arrival)",
    )
    parser.add_argument("--shipped", action="store_true", help="write the shipped datasets of --scenario")
    parser.add_argument("--shipped-dir", default=None, help="output folder of --shipped (default: the package's)")
    parser.add_argument("--ant-policy", default=None,
                        help="antmaze-umaze: the goal-reaching ant (policy.pt or a run of recipes/train_ant_expert.py; "
                             "default: the shipped one)")
    parser.add_argument("--action-noise", type=float, default=0.0,
                        help="std of Gaussian noise on the expert's actions, executed and recorded (D4RL's AntMaze "
                             "data: 0.2); default 0, the clean expert")
    parser.add_argument("--record-expert-action", action="store_true",
                        help="with --action-noise: record the expert's noise-free action at the perturbed states "
                             "(DART) instead of the executed one")
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error("--episodes must be >= 1")
    if not args.action_noise >= 0:
        parser.error("--action-noise must be >= 0")
    if args.record_expert_action and not args.action_noise:
        parser.error("--record-expert-action needs --action-noise > 0")
    if args.action_noise and args.shipped:
        parser.error("--shipped writes the clean expert's datasets; use --out with --action-noise")
    if args.ant_policy is not None and args.scenario != "antmaze-umaze":
        parser.error("--ant-policy applies to --scenario antmaze-umaze only")
    options = expert_options(args.scenario, args.ant_policy)

    if args.shipped:
        from torchrl_csirl.data.shipped import EXPERTS_DIR

        if args.empty_road or args.scenario not in shipped_scenarios():
            parser.error(
                f"--shipped writes the driving scenarios' curriculum datasets ({', '.join(shipped_scenarios())}); "
                "for relocate use --out (docs/experts.md gives the command)"
            )
        out_dir = args.shipped_dir or os.path.join(EXPERTS_DIR, args.scenario)
        result = generate_shipped(args.scenario, out_dir, SHIPPED_SEED if args.seed is None else args.seed)
    else:
        seed = 0 if args.seed is None else args.seed
        # recording ends at arrival; evaluation (no --out) runs the env's full episodes
        kept, rolled = roll_episodes(
            args.scenario, args.episodes, seed, args.empty_road, args.only_successful, args.max_attempts,
            end_at_arrival=bool(args.out) and not args.full_episodes, expert_kwargs=options,
            action_noise=args.action_noise, record_expert_action=args.record_expert_action,
        )
        result = {"scenario": args.scenario, "seed": seed, "action_noise": args.action_noise,
                  **summarize(rolled, kept)}
        if args.out:
            if not kept:
                raise SystemExit("no episode kept: nothing written")
            meta = {
                "scenario": args.scenario,
                **expert_metadata(args.scenario, **options),
                "base_seed": seed,
                "empty_road": bool(args.empty_road),
                "only_successful": bool(args.only_successful),
                "end_at_arrival": bool(kept[0]["end_at_arrival"]),
                "action_noise": float(args.action_noise),
                "recorded_action": kept[0]["recorded_action"],
                "num_trajectories": len(kept),
            }
            result["out"] = build_demonstrations(kept, meta).save(args.out)
        if args.only_successful:
            print(f"rejected {result['rejected']} of {result['episodes']} episodes", file=sys.stderr)
    print(json.dumps(result, sort_keys=True))
    return result


if __name__ == "__main__":
    main()
