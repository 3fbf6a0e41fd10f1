"""The health checks of a run, each one named function of plain figures (no run, no network).

Each check returns a :class:`HealthCheck`: its figures, whether they are in range (``ok``; None when
the run gives too little to say) and one sentence in plain words. Out of range, the sentence says
what the figures mean for the run and what to look at. The thresholds are module constants, stated
beside each check; they flag a figure worth a look, not a proof.

Examples:
    >>> rows = [{"frames": f, "matching_reward_mean": r, "eval_success_rate": 0.0, "eval_env_return": -5.0}
    ...         for f, r in ((1000, 0.1), (2000, 0.5), (3000, 0.9))]
    >>> check = reward_tracks_the_task(rows)
    >>> check.ok, check.message.split(":")[0]
    (False, 'reward hacking')
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import torch

__all__ = [
    "ACTION_BOUND",
    "ENTROPY_FLOOR_PER_DIM",
    "HACKING_RISE_FLOOR",
    "HACKING_RISE_SHARE",
    "LEARNED_REWARD_SHARE_RANGE",
    "OFF_DEMONSTRATION_SD",
    "OFF_PATH_SHARE",
    "ROUTE_OPENING_SHARE",
    "SATURATION_LIMIT",
    "SHARED_GOAL_DISTANCE",
    "SHARED_GOAL_SHARE",
    "SHORTCUT_RATIO",
    "SHORT_PROGRESS",
    "SOLVED",
    "SUBGOAL_LEAD_LIMIT",
    "TASK_FLAT_SHARE",
    "VALUE_RATIO_LIMIT",
    "WARM_START_KEPT_SHARE",
    "HealthCheck",
    "action_saturation",
    "critic_calibration",
    "curriculum_moved_on",
    "demonstrations_share_a_goal",
    "expert_transitions_reward",
    "learned_reward_share",
    "matching_along_demonstrations",
    "nearest_state_distances",
    "policy_entropy",
    "reward_tracks_the_task",
    "route_opening",
    "states_off_the_demonstrations",
    "subgoal_progress",
    "subgoal_share",
    "warm_start_kept",
    "where_episodes_end",
]

#: the critics' mean value over the Monte Carlo return of the learner's own reward (or the inverse) above which
#: the critics are called over- (under-) valued
VALUE_RATIO_LIMIT = 3.0
#: an action entry beyond this (in ``[-1, 1]``) sits at a bound (a Tanh squashed to its ends)
ACTION_BOUND = 0.99
#: the share of actions at a bound (|a| > :data:`ACTION_BOUND`) above which the policy is called saturated
SATURATION_LIMIT = 0.5
#: entropy per action dimension below which the policy is called collapsed (a Tanh-Normal's entropy goes to -inf)
ENTROPY_FLOOR_PER_DIM = -3.0
#: the share of the demonstrations' route total that the route may cost before it pays (its opening) under the
#: matching reward; beyond it, standing still beats walking the first stretch
ROUTE_OPENING_SHARE = 0.1
#: how far (a share of the demonstration) the curriculum's last subgoal may lie ahead of where the policy's episodes end
#: (median) before :func:`where_episodes_end` says the curriculum moved on without the policy
SUBGOAL_LEAD_LIMIT = 0.5
#: below the first, the learned reward cannot move the policy; above the second, it drowns the matching reward
LEARNED_REWARD_SHARE_RANGE = (0.01, 0.8)


@dataclass
class HealthCheck:
    """One figure of a run's health.

    Attributes:
        name: the check's name (``reward_tracks_the_task``, ...).
        ok: True in range, False out of range (flagged), None when the run gives too little to say.
        message: one sentence in plain words; out of range, what it means and what to look at.
        figures: the numbers behind it.
    """

    name: str
    ok: bool | None
    message: str
    figures: dict[str, Any] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        """A JSON-ready dict."""
        return asdict(self)


def _mean(values: Sequence[float]) -> float:
    values = [v for v in values if v is not None and not math.isnan(v)]
    return sum(values) / len(values) if values else float("nan")


def _thirds(rows: Sequence[dict], key: str) -> tuple[float, float]:
    """The mean of ``key`` over the first and the last third of ``rows`` (those that have it)."""
    values = [r[key] for r in rows if r.get(key) is not None]
    third = max(1, len(values) // 3)
    return _mean(values[:third]), _mean(values[-third:])


def _rounds(rows: Sequence[dict]) -> list[dict]:
    """The per-round rows of ``metrics.jsonl`` (the final test row dropped)."""
    return [r for r in rows if "round" in r]


#: the share of a warm-started actor's score (before any update) under which the last third's evaluations are called
#: a lost warm start
WARM_START_KEPT_SHARE = 0.5

#: a test success (or accomplish rate) from which the task counts as solved: a score flat there is not a failure
SOLVED = 0.9
#: the rise of the matching reward per step, as a share of what the demonstration is paid per step, below which it
#: is too small to call hacking (a relative rise on a near-zero base: a learner that stands still)
HACKING_RISE_FLOOR = 0.01
#: the matching reward's rise, first third to last, as a share of its larger magnitude, from which it counts as risen
HACKING_RISE_SHARE = 0.25
#: the task's success or accomplish rate may gain this much (the environment's return this share of its magnitude)
#: and still count as flat
TASK_FLAT_SHARE = 0.05


#: the cause :func:`reward_tracks_the_task` names where the learner is paid for something the task does not count
_FEATURES_PAY_ELSEWHERE = ("the matching features (env.features, the task's position_feature_indices) reward something "
                           "the task does not")


def _hacking_line(rows: Sequence[dict], matching: tuple[float, float], success: tuple[float, float],
                  env_return: tuple[float, float], demonstration_reward: float | None) -> str:
    """The flagged line of :func:`reward_tracks_the_task`, with its likely cause where the report can tell.

    A learner paid less per step than the demonstration has not outdone the demonstrations on their own reward: a
    run still short of what it needs (a small budget gives this) is as likely as a reward paying for something else,
    and more frames is the cheaper test. A learner paid as much as the demonstration without its success is paid
    for something the task does not count.
    """
    (m0, m1), (s0, s1), (e0, e1) = matching, success, env_return
    frames = rows[-1].get("frames")
    seen = (f"the matching reward per step rose from {m0:.3g} to {m1:.3g} while the evaluations' success went from "
            f"{s0:.2f} to {s1:.2f} and the environment's return from {e0:.3g} to {e1:.3g} (first and last third of the "
            f"run{f', {int(frames)} frames' if frames is not None else ''})")
    if demonstration_reward is not None and m1 < demonstration_reward:
        return (f"the task did not follow the reward: {seen}; the learner is still paid less per step than the "
                f"demonstration ({m1:.3g} against {demonstration_reward:.3g}), so the run may be too short to reach "
                "the task rather than paid for something else: train longer (collector.total_frames) first; if the "
                f"task stays flat once the learner is paid as much as the demonstration, {_FEATURES_PAY_ELSEWHERE}")
    paid = (f"; the learner is paid {m1:.3g} per step, the demonstration {demonstration_reward:.3g}"
            if demonstration_reward is not None else "")
    return f"reward hacking: {seen}{paid}; {_FEATURES_PAY_ELSEWHERE}"


def reward_tracks_the_task(rows: Sequence[dict], test: Mapping[str, Any] | None = None,
                           demonstration_reward: float | None = None) -> HealthCheck:
    """Reward hacking: the matching reward the learner collects rises while the task's success and return stay flat
    (below :data:`SOLVED`, in the last third's evaluations and in the final test).

    Args:
        rows: ``metrics.jsonl``'s rows (``matching_reward_mean``, ``reward_mean``, ``eval_success_rate``,
            ``eval_accomplish_rate``, ``eval_env_return``).
        test: the run's final test (``summary.json``: ``success_rate``, ``accomplish_rate``), where it has one: a
            test at or above :data:`SOLVED` clears the run, whatever its last few 10-episode evaluations said.
        demonstration_reward: the matching reward per step the demonstration is paid on its way to the subgoal
            (the probe's), where known: a rise below :data:`HACKING_RISE_FLOOR` of it is too small to be hacking,
            however large against a near-zero start.

    Examples:
        >>> rows = [{"matching_reward_mean": r, "eval_success_rate": s} for r, s in ((0.1, 1.0), (0.2, 0.9), (0.9, 0.6))]
        >>> reward_tracks_the_task(rows).ok, reward_tracks_the_task(rows, test={"success_rate": 0.96}).ok
        (False, True)
        >>> reward_tracks_the_task(rows, demonstration_reward=100.0).ok  # a rise of 0.8 against 100 per step
        True
    """
    logged = [r for r in rows if r.get("matching_reward_mean") is not None]
    name = "reward_tracks_the_task"
    if rows and not logged:
        return HealthCheck(name, None, "no matching reward was logged (a method without one)")
    rows = logged
    if len(rows) < 3:
        return HealthCheck(name, None, "too few rounds to compare the training reward with the task's score")
    m0, m1 = _thirds(rows, "matching_reward_mean")
    s0, s1 = _thirds(rows, "eval_success_rate")
    a0, a1 = _thirds(rows, "eval_accomplish_rate")
    e0, e1 = _thirds(rows, "eval_env_return")
    spread = max(abs(m0), abs(m1), 1e-8)
    floor = HACKING_RISE_FLOOR * abs(demonstration_reward) if demonstration_reward is not None else 0.0
    rose_relative = (m1 - m0) / spread > HACKING_RISE_SHARE
    reward_rose = rose_relative and m1 - m0 > floor
    task_flat = (math.isnan(s1) or s1 - s0 <= TASK_FLAT_SHARE) and (math.isnan(a1) or a1 - a0 <= TASK_FLAT_SHARE) and (
        math.isnan(e1) or e1 - e0 <= TASK_FLAT_SHARE * max(abs(e0), abs(e1), 1e-8))
    figures = {"matching_reward_first": m0, "matching_reward_last": m1, "success_first": s0, "success_last": s1,
               "accomplish_first": a0, "accomplish_last": a1, "env_return_first": e0, "env_return_last": e1,
               "demonstration_reward": demonstration_reward}
    figures["reward_first"], figures["reward_last"] = _thirds(rows, "reward_mean")
    tested = [float(test[k]) for k in ("success_rate", "accomplish_rate") if (test or {}).get(k) is not None]
    figures["test_success"] = max(tested) if tested else None
    solved = any(not math.isnan(v) and v >= SOLVED for v in (s1, a1, *tested))  # flat at the top is not hacking
    if reward_rose and task_flat and not solved:
        return HealthCheck(name, False, _hacking_line(rows, (m0, m1), (s0, s1), (e0, e1), demonstration_reward), figures)
    if rose_relative and not reward_rose:
        return HealthCheck(name, True, (
            f"the matching reward per step went from {m0:.3g} to {m1:.3g}, a rise below {HACKING_RISE_FLOOR:.0%} of "
            f"the {demonstration_reward:.3g} the demonstration is paid per step: too small to be hacking (the "
            "learner collects almost none of it)"), figures)
    return HealthCheck(name, True, f"the matching reward went from {m0:.3g} to {m1:.3g}, the evaluations' success "
                                   f"from {s0:.2f} to {s1:.2f} and the environment's return from {e0:.3g} to {e1:.3g}",
                       figures)


def warm_start_kept(rows: Sequence[dict]) -> HealthCheck:
    """A warm-started actor (``csirl.actor_pretrain_updates``) against the training that follows: its evaluation
    before any update (the row at frame 0) and the evaluations after, in success, else accomplish rate.

    Args:
        rows: ``metrics.jsonl``'s rows (``frames``, ``eval_success_rate``, ``eval_accomplish_rate``).

    Examples:
        >>> rows = [{"frames": f, "eval_success_rate": s} for f, s in ((0, 0.2), (10, 0.0), (20, 0.0), (30, 0.0))]
        >>> warm_start_kept(rows).ok, warm_start_kept(rows[1:]).ok
        (False, None)
    """
    name = "warm_start_kept"
    evaluated = [r for r in rows if r.get("eval_success_rate") is not None or r.get("eval_accomplish_rate") is not None]
    if not evaluated or evaluated[0].get("frames") != 0:
        return HealthCheck(name, None, "no evaluation before the first update (the actor was not warm-started)")
    start, after = evaluated[0], evaluated[1:]
    if not after:
        return HealthCheck(name, None, "no evaluation after the warm start's")
    key = next((k for k in ("eval_success_rate", "eval_accomplish_rate") if (start.get(k) or 0.0) > 0.0), None)
    if key is None:
        return HealthCheck(name, None, "the warm-started actor scored 0 before any update: nothing to keep")
    what = key.removeprefix("eval_").replace("_", " ")
    first, last = after[0].get(key), _thirds(after, key)[1]
    figures = {"metric": what, "warm_start": start[key], "first_after": first, "last_third": last,
               "first_after_frames": after[0].get("frames")}
    figures["anchored"] = any(r.get("actor_bc_mse") is not None for r in rows)  # csirl.actor_bc_coef > 0
    if last < WARM_START_KEPT_SHARE * start[key]:
        remedy = ("even with cloning in the actor's loss (csirl.actor_bc_coef): SAC's fine-tuning moved the actor off "
                  "the cloned behaviour; where critic_calibration and expert_transitions_reward are in range the reward "
                  "is not the cause (what was tried on AntMaze: docs/studies/outside-driving.md); a larger "
                  "csirl.actor_bc_coef keeps the actor nearer the clone" if figures["anchored"]
                  else "the updates moved the actor off the cloned behaviour (critic_calibration says whether the "
                       "critics had learned; csirl.actor_bc_coef keeps cloning in the actor's loss)")
        return HealthCheck(name, False, (
            f"the training undid the warm start: the cloned actor's {what} was {start[key]:.2f} before any update, "
            f"{first:.2f} at the first evaluation after ({figures['first_after_frames']} frames) and {last:.2f} in the "
            f"last third; {remedy}"), figures)
    return HealthCheck(name, True, f"the warm-started actor's {what}: {start[key]:.2f} before any update, {last:.2f} "
                                   "in the last third", figures)


def critic_calibration(values: torch.Tensor, returns: torch.Tensor, where: str,
                       entropy_returns: torch.Tensor | None = None) -> HealthCheck:
    """The critics' values against Monte Carlo returns of what they estimate on the same states.

    A soft critic estimates the learner's reward plus SAC's entropy bonus (``-alpha log pi`` at every next state);
    ``returns`` holds both, ``entropy_returns`` the bonus's part, stated in the message: with SAC's target entropy
    ``-dim(A)`` it is negative, and ignoring it reads calibrated critics as under-valuing. Over- and under-valuation are
    flagged on either set of states. On the expert's, ``Q(s, a)`` values the policy's continuation, so an
    under-valuation there has two causes, which the message names: critics that under-value, or a policy that does
    not continue the expert's route from the expert's states (``critic_calibration_policy`` in range: the latter).

    Args:
        values: ``[K, N]`` the ensemble's ``Q_k(s, a)`` (or ``[N]``).
        returns: ``[N]`` the discounted return from each ``(s, a)`` on (reward and entropy bonus).
        where: whose states (``"expert"``, ``"policy"``): the check is named ``critic_calibration_<where>``.
        entropy_returns: ``[N]`` the entropy bonus's part of ``returns`` (default: none).

    Examples:
        >>> critic_calibration(torch.full((2, 3), -40.0), torch.full((3,), -45.0), "policy",
        ...                    torch.full((3,), -50.0)).message
        "the critics value the policy's states at -40, their return is -45 (-50 of it SAC's entropy bonus)"
    """
    name = f"critic_calibration_{where}"
    if returns.numel() == 0:
        return HealthCheck(name, None, f"no {where} states whose return could be measured")
    values = values.reshape(-1, returns.numel()) if values.ndim > 1 else values[None]
    q, g = float(values.mean()), float(returns.mean())
    bonus = float(entropy_returns.mean()) if entropy_returns is not None and entropy_returns.numel() else 0.0
    figures = {"value_mean": q, "value_min": float(values.min(0).values.mean()), "return_mean": g,
               "entropy_return_mean": bonus,
               "critic_spread": float(values.std(0).mean()) if values.shape[0] > 1 else 0.0, "states": returns.numel()}
    scale = max(float(returns.abs().mean()), 1e-3)
    figures["bias_over_return"] = (q - g) / scale
    returned = f"{g:.3g}" + (f" ({bonus:.3g} of it SAC's entropy bonus)" if bonus else "")
    over, under = q - g > (VALUE_RATIO_LIMIT - 1) * scale, g - q > (1 - 1 / VALUE_RATIO_LIMIT) * scale
    if over:
        return HealthCheck(name, False, (
            f"the critics over-value the {where}'s states: {q:.3g} on average where they return {returned}; the TD "
            "targets feed on this (try fewer expert transitions in the batch, replay_buffer.expert_fraction; more "
            "critics in the minimum, csirl.num_qvalue_nets; or a smaller csirl.gamma)"), figures)
    if under and where == "expert":
        return HealthCheck(name, False, (
            f"the critics value the expert's states at {q:.3g}, under the demonstration's return {returned}: Q(s, a) "
            "values the policy's continuation, so either the policy does not continue the expert's route from the "
            "expert's states (where critic_calibration_policy is in range: the critics are right, look at where the "
            "policy goes: where_episodes_end, states_off_the_demonstrations, warm_start_kept) or the critics "
            "under-value (a short run, or the minimum over many critics: fewer, csirl.num_qvalue_nets)"), figures)
    if under:
        return HealthCheck(name, False, (
            f"the critics under-value the {where}'s states: {q:.3g} on average where they return {returned} (a short "
            "run, or the minimum over many critics: fewer, csirl.num_qvalue_nets)"), figures)
    return HealthCheck(name, True, f"the critics value the {where}'s states at {q:.3g}, their return is {returned}",
                       figures)


#: the median distance from the episodes' ends to their path, as a share of the path's length, beyond which
#: :func:`where_episodes_end` calls them off the path (and an episode's end this far from every demonstration state
#: off every demonstration)
OFF_PATH_SHARE = 0.2
#: the median progress along the demonstration (its nearest state's share of it) under which the episodes stop short
SHORT_PROGRESS = 0.5
#: an episode that ends on the path with more than :data:`OFF_PATH_SHARE` of the path's length still to walk to the
#: matching target takes a shortcut where the straight line from its end to the target is under this share of the
#: route along the demonstration between them (a wall or a detour lies between)
SHORTCUT_RATIO = 0.5
#: the order in which :func:`where_episodes_end` names an episode's end when as many episodes end each way
_END_KINDS = ("off", "shortcut", "short")


def _arc_lengths(path: torch.Tensor) -> torch.Tensor:
    """``[L]`` the length along ``path`` (``[L, F]``) from its first state to each.

    Examples:
        >>> _arc_lengths(torch.tensor([[0.0, 0.0], [3.0, 4.0], [3.0, 5.0]])).tolist()
        [0.0, 5.0, 6.0]
    """
    steps = (path[1:] - path[:-1]).norm(dim=-1)
    return torch.cat([steps.new_zeros(1), steps.cumsum(0)])


def _episode_end(final: torch.Tensor, path: torch.Tensor, subgoal_share: float | None,
                 demonstrations: Sequence[torch.Tensor]) -> dict[str, Any]:
    """One episode's end against its path (``[L, F]``): its distance to the nearest path state, that state's share of
    the path, the straight line and the route along the path to the matching target (the subgoal's state, else the
    path's end), each as a share of the path's length, and how it ends (``off``, ``shortcut``, ``short``,
    ``reached``)."""
    path = path.float()
    arc = _arc_lengths(path)
    extent = max(float(arc[-1]), 1e-8)
    distance, index = torch.cdist(final[None], path)[0].min(-1)
    last = path.shape[0] - 1
    target = last if subgoal_share is None else min(last, max(0, round(float(subgoal_share) * last)))
    route = max(0.0, float(arc[target] - arc[index])) / extent
    straight = float((final - path[target]).norm()) / extent
    every = [float(torch.cdist(final[None], d.float())[0].min()) for d in demonstrations if d.shape[0]]
    nearest_any = min([float(distance), *every]) / extent
    off = float(distance) / extent > OFF_PATH_SHARE
    if off:
        kind = "off" if nearest_any > OFF_PATH_SHARE else "other"
    elif route > OFF_PATH_SHARE and straight < SHORTCUT_RATIO * route:
        kind = "shortcut"
    else:
        kind = "short" if float(index) / last < SHORT_PROGRESS else "reached"
    return {"distance": float(distance), "progress": float(index) / last, "extent": extent, "route": route,
            "straight": straight, "target_share": target / last, "nearest_demonstration": nearest_any, "kind": kind}


def where_episodes_end(final_features: torch.Tensor, path_features: torch.Tensor,
                       episode_paths: Sequence[torch.Tensor] = (), subgoal_share: float | None = None,
                       demonstrations: Sequence[torch.Tensor] = (), target: str = "final") -> HealthCheck:
    """Where the policy's episodes end compared with the demonstrations' path (the matching features), and, where
    they stop short, why.

    Flagged where the episodes end (median) more than :data:`OFF_PATH_SHARE` of the path's length from it, or under
    :data:`SHORT_PROGRESS` of the way along it. Each episode's end is then read on its own: off every demonstration
    (farther than :data:`OFF_PATH_SHARE` from every demonstration state: somewhere the expert never goes), off its
    path near another demonstration's states, on the path where the straight line to the matching target is under
    :data:`SHORTCUT_RATIO` of the route along the demonstration (a shortcut across a wall or a detour, which a
    straight-line matching target pays), or on the path short of the goal; the message names the most common, its
    likely cause and what to try.

    Args:
        final_features: ``[E, F]`` the matching features of each episode's last state.
        path_features: ``[L, F]`` the curriculum trajectory's matching features.
        episode_paths: ``[L_e, F]`` per episode, the path to compare it with (the demonstration of its goal, with a
            goal-conditioned matching reward); empty: ``path_features`` for every episode.
        subgoal_share: the curriculum's subgoal as a share of its trajectory (None: no curriculum, or one fixed at
            the end): the matching target on each path (else its end). Where the episodes stop short and the
            subgoal is more than :data:`SUBGOAL_LEAD_LIMIT` ahead of them (:func:`curriculum_moved_on`), the message
            says the curriculum moved on without the policy.
        demonstrations: ``[L_i, F]`` every demonstration's matching features (default: the paths alone), to tell
            an episode off every demonstration from one that follows another demonstration.
        target: the matching target rule (``csirl.matching_target``), for the remedy.

    Examples:
        >>> path = torch.stack([torch.arange(11.0), torch.zeros(11)], -1)
        >>> check = where_episodes_end(torch.tensor([[1.0, 0.0]]), path, subgoal_share=0.95)
        >>> check.ok, round(check.figures["subgoal_lead"], 2), "moved on without the policy" in check.message
        (False, 0.85, True)
        >>> where_episodes_end(torch.tensor([[1.0, 9.0]]), path).figures["episode_ends"]  # far from every state
        ['off']
    """
    name = "where_episodes_end"
    paths = list(episode_paths) if episode_paths else [path_features] * final_features.shape[0]
    if final_features.numel() == 0 or min(p.shape[0] for p in paths) < 2:
        return HealthCheck(name, None, "no episode or no path to compare")
    ends = [_episode_end(final, path, subgoal_share, demonstrations) for final, path in zip(final_features.float(), paths)]
    nearest_t, progress_t = torch.tensor([e["distance"] for e in ends]), torch.tensor([e["progress"] for e in ends])
    extent = float(torch.tensor([e["extent"] for e in ends]).median())
    figures = {"progress_median": float(progress_t.median()), "progress": [e["progress"] for e in ends],
               "distance_to_path_median": float(nearest_t.median()), "path_length": extent,
               "distance_over_path_length": float(nearest_t.median()) / extent,
               "episode_ends": [e["kind"] for e in ends], "straight_to_target": [e["straight"] for e in ends],
               "route_to_target": [e["route"] for e in ends],
               "nearest_demonstration_over_path_length": [e["nearest_demonstration"] for e in ends]}
    which = "the demonstration of its goal" if episode_paths else "the demonstration"
    off_path = figures["distance_over_path_length"] > OFF_PATH_SHARE
    if subgoal_share is not None:
        figures["subgoal_share"] = float(subgoal_share)
        figures["subgoal_lead"] = float(subgoal_share) - figures["progress_median"]
    if off_path or figures["progress_median"] < SHORT_PROGRESS:
        where = (f"{figures['distance_over_path_length']:.0%} of the path's length away from it" if off_path
                 else "on the path")
        return HealthCheck(name, False, (
            f"the policy's episodes end {where}, {figures['progress_median']:.0%} of the way along {which} "
            f"(median){_end_cause(ends, which, target, subgoal_share)}" + _subgoal_ahead(figures, bool(episode_paths))),
            figures)
    return HealthCheck(name, True, f"the policy's episodes end {figures['progress_median']:.0%} of the way along "
                                   f"{which} (median), near its path", figures)


def _end_cause(ends: Sequence[dict[str, Any]], which: str, target: str, subgoal_share: float | None) -> str:
    """The clause of :func:`where_episodes_end`'s message naming how most short episodes end, why, and what to try.

    Examples:
        >>> end = {"kind": "off", "nearest_demonstration": 0.7}
        >>> _end_cause([end], "the demonstration", "final", None).split(" (")[0]
        '; 1 of 1 end off every demonstration'
    """
    kinds = [e["kind"] for e in ends]
    counted = [k for k in (*_END_KINDS, "other") if k in kinds]
    if not counted:
        return ": it stops short of the goal or leaves the path"
    kind = max(counted, key=kinds.count)  # the most common; ties to the first of _END_KINDS
    chosen = [e for e in ends if e["kind"] == kind]
    n = f"; {len(chosen)} of {len(ends)}"
    middle = float(torch.tensor([e["nearest_demonstration"] for e in chosen]).median())
    if kind == "off":
        return (f"{n} end off every demonstration ({middle:.0%} of the path's length from the nearest demonstration "
                "state): the policy goes where the expert never does, and the matching reward, read against the "
                "nearest demonstration state, gives it no route back; a warm start on the demonstrations that keeps the "
                "actor near them starts it on the route (csirl.actor_pretrain_updates with csirl.actor_bc_coef)")
    if kind == "other":
        return (f"{n} end off {which}'s path but near another demonstration's states: the policy follows another route "
                "or goal the expert shows than the one it is matched against (demonstrations_share_a_goal; "
                "csirl.goal_conditioned)")
    if kind == "shortcut":
        straight = float(torch.tensor([e["straight"] for e in chosen]).median())
        route = float(torch.tensor([e["route"] for e in chosen]).median())
        at = "the curriculum's subgoal" if subgoal_share is not None else "the demonstration's end"
        clause = (f"{n} stop on the path where the straight line to the matching target ({at}) is {straight:.0%} of "
                  f"the path's length and the route along the demonstration {route:.0%}: a wall or a detour lies "
                  "between them")
        if target == "path":
            return clause + (" though the matching reward already measures progress along the demonstration "
                             "(csirl.matching_target=path): what stops the policy is the learner (critic_calibration_*, "
                             "warm_start_kept), not the target")
        return clause + (f", and the matching reward (csirl.matching_target={target}) pays the straight-line distance, "
                         "a shortcut through it: walking the route's next stretch, away from the target, is paid less "
                         "than standing still; csirl.matching_target=path measures progress along the demonstration "
                         "(route_opening says whether the route pays)")
    return (f"{n} stop on the path short of the goal, on the route the expert takes (the learner: critic_calibration_*, "
            "learned_reward_share; where the curriculum's subgoal stops there too, subgoal_progress)")


def curriculum_moved_on(subgoal_share: float | None, progress: float) -> bool:
    """Whether the curriculum's last subgoal (``subgoal_share`` of its trajectory) lies more than
    :data:`SUBGOAL_LEAD_LIMIT` ahead of ``progress``, where the policy's episodes end (the same share, median).

    Examples:
        >>> curriculum_moved_on(0.98, 0.2), curriculum_moved_on(0.98, 0.9), curriculum_moved_on(None, 0.0)
        (True, False, False)
    """
    return subgoal_share is not None and subgoal_share - progress > SUBGOAL_LEAD_LIMIT


def _subgoal_ahead(figures: dict[str, Any], per_goal: bool) -> str:
    """The clause of :func:`where_episodes_end`'s message for a curriculum that moved on without the policy."""
    share = figures.get("subgoal_share")
    if not curriculum_moved_on(share, figures["progress_median"]):
        return ""
    along = "the same share of each goal's demonstration" if per_goal else "its demonstration"
    clause = (f"; the curriculum's subgoal is already {share:.0%} of the way along {along}: it moved on without the "
              "policy (the subgoal follows the critics' agreement along the demonstration, not how far the policy "
              "gets) and no longer sets a target within its reach")
    if share >= 1.0:
        clause += (", and the run now trains as it would without a curriculum (csirl.fixed_subgoal=true): what holds "
                   "the policy back is the learner or the reward, not the subgoal")
    return clause


#: a demonstration whose end lies within this share of the curriculum trajectory's length of its end (of an episode's
#: goal, with a goal-conditioned matching reward) shares its goal
SHARED_GOAL_DISTANCE = 0.1
#: the share of the demonstrations (of the probe episodes) under which :func:`demonstrations_share_a_goal` says the
#: goal is not shared (not covered)
SHARED_GOAL_SHARE = 0.5


def demonstrations_share_a_goal(final_features: torch.Tensor, path_features: torch.Tensor,
                                goal_conditioned: bool = False, goal_gaps: Sequence[float] | None = None
                                ) -> HealthCheck:
    """Whether the demonstrations end where the curriculum trajectory ends: CSIRL's matching reward leads every
    episode along that one trajectory, so a task whose goal changes per episode cannot be matched. A goal-conditioned
    matching reward matches each transition against the demonstration of its goal instead; the check then reads
    whether that demonstration leads to the episode's goal (the demonstrations cover the goals the episodes draw).

    Args:
        final_features: ``[N, F]`` the matching features of each demonstration's last state.
        path_features: ``[L, F]`` the curriculum trajectory's matching features (its last row: its end).
        goal_conditioned: the matching reward follows the demonstration of each episode's goal.
        goal_gaps: with ``goal_conditioned``, per probe episode, the distance from its goal to the goal of the
            demonstration it is matched against, over the curriculum trajectory's length (the goal in the matching
            features' units, as a goal-conditioned task's ``desired_goal`` and ``achieved_goal`` are); fewer than
            :data:`SHARED_GOAL_SHARE` of them under :data:`SHARED_GOAL_DISTANCE` is flagged.

    Examples:
        >>> path = torch.stack([torch.arange(11.0), torch.zeros(11)], -1)
        >>> demonstrations_share_a_goal(torch.tensor([[10.0, 0.0], [0.0, 5.0]]), path, True, [0.02, 0.4, 0.3]).ok
        False
    """
    name = "demonstrations_share_a_goal"
    if goal_conditioned:
        return _goals_covered(goal_gaps)
    if final_features.shape[0] < 2 or path_features.shape[0] < 2:
        return HealthCheck(name, None, "fewer than two demonstrations")
    extent = max(float((path_features[1:] - path_features[:-1]).norm(dim=-1).sum()), 1e-8)
    distance = (final_features.float() - path_features[-1].float()).norm(dim=-1) / extent
    near = float((distance < SHARED_GOAL_DISTANCE).float().mean())
    figures = {"near_share": near, "end_distance_over_path_length": distance.tolist()}
    if near < SHARED_GOAL_SHARE:
        return HealthCheck(name, False, (
            f"only {near:.0%} of the demonstrations end near the curriculum trajectory's end (within a tenth of its "
            "length): the goal changes from episode to episode, and the matching reward leads every episode to the "
            "first demonstration's goal; give the task one goal, demonstrations that share it, or a matching reward "
            "that follows each episode's goal (csirl.goal_conditioned=true, where the observation has a desired_goal)"),
            figures)
    return HealthCheck(name, True, f"{near:.0%} of the demonstrations end near the curriculum trajectory's end",
                       figures)


def _goals_covered(goal_gaps: Sequence[float] | None) -> HealthCheck:
    """:func:`demonstrations_share_a_goal` with a goal-conditioned matching reward: whether the demonstration each
    probe episode is matched against leads to the episode's own goal."""
    name = "demonstrations_share_a_goal"
    gaps = [float(g) for g in goal_gaps or ()]
    if not gaps:
        return HealthCheck(name, None, "each transition is matched against the demonstration of its goal; no probe "
                                       "episode's goal to compare with it")
    covered = sum(g < SHARED_GOAL_DISTANCE for g in gaps) / len(gaps)
    figures = {"covered_share": covered, "goal_gap_over_path_length": gaps}
    if covered < SHARED_GOAL_SHARE:
        return HealthCheck(name, False, (
            f"each transition is matched against the demonstration of its goal, but for only {covered:.0%} of the "
            "probe episodes does that demonstration's goal lie near the episode's own (within a tenth of the "
            f"curriculum trajectory's length; the median gap {sorted(gaps)[len(gaps) // 2]:.0%} of it): the "
            "demonstrations do "
            "not cover the goals the "
            "episodes draw, and the matching reward leads the others to another demonstration's goal; more "
            "demonstrations (expert.num_trajectories), spread over the goals"), figures)
    return HealthCheck(name, True, (f"each transition is matched against the demonstration of its goal: for {covered:.0%} "
                                    "of the probe episodes its goal lies near the episode's own"), figures)


def subgoal_share(subgoal: int, curriculum_length: int) -> float:
    """``subgoal``'s place on the curriculum trajectory of ``curriculum_length`` states: 0 at its first, 1 at its last.

    Examples:
        >>> subgoal_share(140, 281), subgoal_share(0, 1)
        (0.5, 0.0)
    """
    return subgoal / max(curriculum_length - 1, 1)


def subgoal_progress(subgoals: Sequence[int], curriculum_length: int) -> HealthCheck:
    """The subgoal over rounds: a curriculum that never moves cannot lead anywhere.

    Args:
        subgoals: the subgoal of each round, in order.
        curriculum_length: the curriculum trajectory's length.
    """
    name = "subgoal_progress"
    if len(subgoals) < 3:
        return HealthCheck(name, None, "too few rounds to follow the curriculum")
    last = curriculum_length - 1
    figures = {"subgoals": list(subgoals), "curriculum_length": curriculum_length,
               "final_share": subgoal_share(subgoals[-1], curriculum_length)}
    if max(subgoals) == min(subgoals) and subgoals[-1] < last:
        return HealthCheck(name, False, (
            f"the curriculum never moved: subgoal {subgoals[-1]} of {last} in every round; the critics' dispersion "
            "never crossed csirl.delta"), figures)
    return HealthCheck(name, True, f"the subgoal went from {subgoals[0]} to {subgoals[-1]} of {last}", figures)


def policy_entropy(rows: Sequence[dict], action_dim: int) -> HealthCheck:
    """Alpha and the policy's entropy over training: a collapsed entropy explores nothing more."""
    rows = [r for r in rows if r.get("entropy") is not None]
    name = "policy_entropy"
    if not rows:
        return HealthCheck(name, None, "no entropy was logged")
    last = rows[-1]
    figures = {"alpha": [r.get("alpha") for r in rows], "entropy": [r["entropy"] for r in rows],
               "frames": [r.get("frames") for r in rows], "entropy_floor": ENTROPY_FLOOR_PER_DIM * action_dim}
    if last["entropy"] < ENTROPY_FLOOR_PER_DIM * action_dim:
        return HealthCheck(name, False, (
            f"the policy's entropy collapsed to {last['entropy']:.3g} (alpha {last.get('alpha', float('nan')):.3g}): "
            "it acts almost deterministically and stops exploring"), figures)
    return HealthCheck(name, True, f"entropy {last['entropy']:.3g}, alpha {last.get('alpha', float('nan')):.3g} "
                                   "at the end", figures)


def action_saturation(actions: torch.Tensor) -> HealthCheck:
    """The share of the policy's actions at a bound of ``[-1, 1]`` (a Tanh squashed to its ends)."""
    name = "action_saturation"
    if actions.numel() == 0:
        return HealthCheck(name, None, "no action to look at")
    at_bound = (actions.abs() > ACTION_BOUND).float()
    share = float(at_bound.mean())
    figures = {"saturated_share": share, "per_dimension": at_bound.mean(0).tolist()}
    if share > SATURATION_LIMIT:
        return HealthCheck(name, False, f"{share:.0%} of the policy's actions sit at a bound: it pushes as hard "
                                        "as it can, a sign of a reward that grows without limit", figures)
    return HealthCheck(name, True, f"{share:.0%} of the policy's actions at a bound", figures)


def learned_reward_share(rows: Sequence[dict]) -> HealthCheck:
    """``r_w``'s magnitude and its share of the training reward (matching + learned)."""
    rows = [r for r in rows if r.get("intrinsic_reward_mean") is not None]
    name = "learned_reward_share"
    if not rows:
        return HealthCheck(name, None, "no learned reward (CSIRL-B, or none logged)")
    third = rows[-max(1, len(rows) // 3):]
    learned = _mean([abs(r["intrinsic_reward_mean"]) for r in third])
    matching = _mean([abs(r.get("matching_reward_mean") or 0.0) for r in third])
    share = learned / max(learned + matching, 1e-12)
    figures = {"learned_abs_mean": learned, "matching_abs_mean": matching, "share": share}
    low, high = LEARNED_REWARD_SHARE_RANGE
    if share < low:
        return HealthCheck(name, False, (
            f"the learned reward r_w is {share:.1%} of the training reward: too small to move the policy "
            "(csirl.reward_scale)"), figures)
    if share > high:
        return HealthCheck(name, False, (
            f"the learned reward r_w is {share:.0%} of the training reward: it drowns the matching reward "
            "(csirl.reward_scale, csirl.reward_l1_coef)"), figures)
    return HealthCheck(name, True, f"the learned reward r_w is {share:.0%} of the training reward", figures)


def matching_along_demonstrations(rewards: torch.Tensor) -> HealthCheck:
    """The matching reward on the curriculum trajectory's own steps up to the subgoal: the expert moves toward it,
    so a well-posed matching reward pays it (a negative mean: the reward's sign or features are wrong)."""
    name = "matching_along_demonstrations"
    if rewards.numel() == 0:
        return HealthCheck(name, None, "the subgoal is the curriculum's start: no expert step leads to it")
    mean, positive = float(rewards.mean()), float((rewards > 0).float().mean())
    figures = {"mean": mean, "positive_share": positive, "steps": rewards.numel()}
    if mean <= 0:
        return HealthCheck(name, False, (
            f"the matching reward pays the demonstration {mean:.3g} per step on its way to the subgoal "
            f"({positive:.0%} of the steps positive): moving like the expert is punished, so the reward's sign, "
            "scale or features are wrong"), figures)
    return HealthCheck(name, True, f"the matching reward pays the demonstration {mean:.3g} per step on its way to "
                                   "the subgoal", figures)


def route_opening(routes: Sequence[torch.Tensor], target: str = "final") -> HealthCheck:
    """Whether the matching reward pays the expert's own route from its start: the lowest point of its running sum
    along each demonstration (the *opening*: what the route costs before it pays) against the route's total.

    A straight line to a target behind a wall (``csirl.matching_target`` ``final`` or ``next`` on a maze that
    turns away from its goal) charges the first stretch of the route: a learner that cannot yet finish the detour
    is paid more for standing still.

    Args:
        routes: per demonstration, the matching reward ``[T]`` on its every step at the run's subgoal.
        target: the matching target rule (``csirl.matching_target``), for the remedy.

    Examples:
        >>> route_opening([torch.tensor([-1.0, -1.0, 3.0, 3.0])]).ok, route_opening([torch.ones(4)]).ok
        (False, True)
    """
    name = "route_opening"
    if not routes:
        return HealthCheck(name, None, "one demonstration: no other route to score")
    openings = [min(0.0, float(r.double().cumsum(0).min())) for r in routes]
    totals = [float(r.double().sum()) for r in routes]
    opening, total = sum(openings) / len(routes), sum(totals) / len(routes)
    cost = 0.0 - opening  # what the route costs before it pays (never -0)
    figures = {"opening_mean": opening, "total_mean": total, "demonstrations": len(routes),
               "opening_share": cost / total if total > 0 else None}
    if total > 0 and cost <= ROUTE_OPENING_SHARE * total:
        return HealthCheck(name, True, f"the matching reward pays the demonstrations' route {total:.3g} from its start "
                                       f"(its opening costs {cost:.3g})", figures)
    remedy = ("csirl.matching_target=path measures the distance along the expert's path" if target != "path"
              else "the features the matching reward measures, csirl.matching_features, or the subgoal")
    what = (f"costs {cost:.3g} before it pays ({cost / total:.0%} of its total {total:.3g})" if total > 0
            else f"is paid {total:.3g} in all")
    return HealthCheck(name, False, (
        f"at the run's subgoal the demonstrations' own route {what}: a learner that cannot yet walk the whole route "
        f"is paid more for standing still; the target lies across a detour ({remedy})"), figures)


def expert_transitions_reward(expert: torch.Tensor, policy: torch.Tensor, expert_fraction: float) -> HealthCheck:
    """The learner's reward on expert transitions against its own, and the experts' share of each batch."""
    name = "expert_transitions_reward"
    if expert.numel() == 0 or policy.numel() == 0:
        return HealthCheck(name, None, "no transitions to compare")
    e, p = float(expert.mean()), float(policy.mean())
    figures = {"expert_mean": e, "policy_mean": p, "expert_fraction": expert_fraction}
    if e < p:
        return HealthCheck(name, False, (
            f"the learner's reward pays the policy's own transitions more than the expert's ({p:.3g} against {e:.3g} "
            f"per step; expert transitions are {expert_fraction:.0%} of each batch): imitating the expert does not pay"),
            figures)
    return HealthCheck(name, True, f"the learner's reward pays the expert's transitions {e:.3g} per step, the "
                                   f"policy's {p:.3g}; expert transitions are {expert_fraction:.0%} of each batch",
                       figures)


#: how many of the demonstrations' standard deviations an observation entry the matching reward does not read may lie,
#: on average over one episode's states, from the nearest demonstration state before the episode is called off the
#: demonstrations
OFF_DEMONSTRATION_SD = 5.0
#: at most this many of an episode's states are paired (a fixed random subset, not a stride: a policy that alternates
#: its actions every step would alias with one): the check's cost grows with the episodes, not their length
_MAX_STATES = 4000


def nearest_state_distances(states: torch.Tensor, reference: torch.Tensor, chunk: int = 128
                            ) -> tuple[torch.Tensor, torch.Tensor]:
    """Each of ``states``' (``[N, D]``) Euclidean distance to its nearest row of ``reference`` (``[M, D]``) and that
    row's index, ``chunk`` rows at a time.

    Examples:
        >>> nearest_state_distances(torch.tensor([[0.0, 0.0], [3.0, 4.0]]), torch.tensor([[0.0, 0.0], [3.0, 0.0]]))
        (tensor([0., 4.]), tensor([0, 1]))
    """
    reference = reference.double()
    found = [torch.cdist(part.double(), reference).min(-1) for part in states.split(chunk)]
    return torch.cat([f.values for f in found]).float(), torch.cat([f.indices for f in found])


def _subsampled(states: torch.Tensor, most: int = _MAX_STATES) -> torch.Tensor:
    """At most ``most`` of ``states``' rows, a fixed random subset in their order (all of them when there are fewer).

    Examples:
        >>> _subsampled(torch.arange(10.0).unsqueeze(-1), most=4).shape
        torch.Size([4, 1])
    """
    if states.shape[0] <= most:
        return states
    chosen = torch.randperm(states.shape[0], generator=torch.Generator().manual_seed(0))[:most]
    return states[chosen.sort().values]


def _gaps_to_demonstrations(states: torch.Tensor, pool: torch.Tensor) -> tuple[torch.Tensor, float]:
    """Per entry, the mean absolute gap of ``states`` to their nearest ``pool`` states, and the median distance."""
    states = _subsampled(states)
    distance, nearest = nearest_state_distances(states, pool)
    return (states - pool[nearest]).abs().mean(0), float(distance.median())


def states_off_the_demonstrations(policy_states: torch.Tensor | Sequence[torch.Tensor],
                                  demonstrations: Sequence[torch.Tensor], matched: Sequence[int] = (),
                                  names: Sequence[str] | None = None) -> HealthCheck:
    """Whether the policy's states look like the demonstrations' in what the matching reward does not read.

    The matching reward pays progress in a few features (``h(s)``); a policy can make that progress in a way the
    expert never does (a HalfCheetah that runs on its back moves its torso's x as an upright one does). Each policy
    state is paired with its nearest demonstration state on every other observation entry, each standardised by the
    demonstrations (entries they hold constant are left out); an entry whose gap averages more than
    :data:`OFF_DEMONSTRATION_SD` of the demonstrations' standard deviations over an episode is somewhere the expert
    never goes. Each episode is read on its own and the worst one reported, so that one episode in five on its back
    is not averaged away by four upright ones.

    Args:
        policy_states: the policy's observations, ``[T_j, D]`` per probe episode; one ``[T, D]`` tensor is one
            episode, one ``[E, T, D]`` tensor ``E`` episodes. An empty episode is skipped (its entry in
            ``episode_largest_gaps_sd`` is None).
        demonstrations: ``[L_i, D]`` each demonstration's observations.
        matched: the observation entries the matching reward reads (left out).
        names: a name per observation entry (the task's :meth:`~torchrl_csirl.tasks.ScenarioSpec.feature_name`).

    Examples:
        >>> _ = torch.manual_seed(0)
        >>> demos = [torch.randn(200, 3) for _ in range(4)]
        >>> states_off_the_demonstrations(torch.randn(100, 3), demos).ok
        True
        >>> flipped = torch.randn(100, 3) + torch.tensor([0.0, 0.0, 12.0])
        >>> check = states_off_the_demonstrations([torch.randn(100, 3), flipped], demos, names=["x", "y", "angle"])
        >>> check.ok, check.figures["farthest_features"][0], check.figures["episodes_off"]
        (False, 'angle', 1)
    """
    name = "states_off_the_demonstrations"
    if isinstance(policy_states, torch.Tensor):
        policy_states = policy_states.unbind(0) if policy_states.ndim == 3 else [policy_states]
    episodes = [e.detach().float().cpu().reshape(-1, e.shape[-1]) if e.numel() else torch.zeros(0, 0)
                for e in policy_states]
    demonstrations = [d.detach().float().cpu() for d in demonstrations if d.shape[0] > 0]
    if not any(e.shape[0] for e in episodes) or not demonstrations:
        return HealthCheck(name, None, "no policy state or no demonstration to compare")
    widths = sorted({e.shape[-1] for e in episodes if e.shape[0]})
    if (len(widths) > 1 or any(d.shape[-1] != widths[0] for d in demonstrations)
            or (names is not None and len(names) != widths[0])):
        return HealthCheck(name, None, (
            f"the policy's observations have {widths[0] if len(widths) == 1 else widths} entries, the demonstrations' "
            f"{sorted({d.shape[-1] for d in demonstrations})}" + (f", the names {len(names)}" if names is not None
                                                                  else "") + ": nothing to compare"))
    width = widths[0]
    every_policy_state = torch.cat([e for e in episodes if e.shape[0]])
    if not torch.isfinite(every_policy_state).all():
        bad = sorted({int(i) for i in (~torch.isfinite(every_policy_state)).nonzero()[:, -1]})
        return HealthCheck(name, False, (
            "the policy's observations hold NaN or inf (entries "
            + ", ".join(names[i] if names is not None else f"obs[{i}]" for i in bad[:5])
            + "): the simulation blew up or the policy's actions did"), {"non_finite_entries": bad})
    every = torch.cat(demonstrations)
    if every.shape[0] < 2:
        return HealthCheck(name, None, "one demonstration state: no spread to standardise by")
    mean, std = every.mean(0), every.std(0)
    matched = {int(i) for i in matched}
    unread = [i for i in range(width) if i not in matched]
    keep = [i for i in unread if float(std[i]) > 1e-6]
    if not keep:
        return HealthCheck(name, None, "the matching reward reads every entry" if not unread
                           else "every entry the matching reward does not read is constant in the demonstrations")
    keep_t = torch.tensor(keep)

    def standardised(x: torch.Tensor) -> torch.Tensor:
        return ((x - mean) / std).index_select(-1, keep_t)

    pool = standardised(every)
    read = [_gaps_to_demonstrations(standardised(e), pool) if e.shape[0] else None for e in episodes]
    largest = [None if r is None else float(r[0].max()) for r in read]
    worst = max((i for i, g in enumerate(largest) if g is not None), key=largest.__getitem__)
    gaps = read[worst][0]  # the worst episode's, per entry, in the demonstrations' standard deviations
    order = gaps.argsort(descending=True)[:3].tolist()
    farthest = [names[keep[i]] if names is not None else f"obs[{keep[i]}]" for i in order]
    off = sum(g is not None and g > OFF_DEMONSTRATION_SD for g in largest)
    probed = sum(g is not None for g in largest)
    figures = {"largest_gap_sd": float(gaps[order[0]]), "farthest_features": farthest,
               "farthest_gaps_sd": [float(gaps[i]) for i in order], "distance_median": read[worst][1],
               "episode_largest_gaps_sd": largest, "worst_episode": worst, "episodes_off": off,
               "entries": len(keep)}
    listed = ", ".join(f"{f} {g:.2g}" for f, g in zip(farthest, figures["farthest_gaps_sd"]))
    if off:
        return HealthCheck(name, False, (
            f"the policy goes where the expert never does in {off} of {probed} episode(s): in the worst, its "
            f"states differ from the nearest demonstration state by {listed} of the demonstrations' standard "
            f"deviations on average (the entries that differ most, of the {len(keep)} the matching reward does not "
            "read): a state the expert never shows (e.g. a cheetah or an ant on its back); where such an episode still "
            "progresses, the matching features (env.features, the task's position_feature_indices) pay it as they "
            "pay the expert"), figures)
    return HealthCheck(name, True, (
        f"the policy's states are near the demonstrations' in the {len(keep)} entries the matching reward does not "
        f"read (largest gap to the nearest demonstration state, worst of {probed} episode(s): {listed} "
        "standard deviations)"), figures)

