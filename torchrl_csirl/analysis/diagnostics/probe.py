"""What a CSIRL learner does, measured on its own networks: the figures the health checks read.

:func:`probe_learner` rolls the deterministic policy for a few seeded episodes, scores them and the
demonstrations with the learner's own reward (the online buffer's transforms: matching reward, ``r_w``,
their sum), and evaluates the critics on both, beside the Monte Carlo return they estimate: that reward's plus SAC's entropy
bonus (``-alpha log pi`` at every next state, negative where the policy's entropy is).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import torch
from tensordict import TensorDictBase
from torchrl.envs import EnvBase, ExplorationType, set_exploration_type

__all__ = ["LearnerProbe", "discounted_returns", "flat_observations", "measurable_states", "probe_learner"]

#: a return is measured where the rest of the episode weighs at least this share of the infinite horizon
_HORIZON_WEIGHT = 0.95


@dataclass
class LearnerProbe:
    """The figures :func:`probe_learner` measures (every tensor on the CPU).

    Attributes:
        policy_values: ``[K, N]`` the critics on the policy's measurable states and actions.
        policy_returns: ``[N]`` the discounted return from those states on that the critics estimate: the
            learner's reward plus SAC's entropy bonus ``-alpha log pi`` at every next state.
        expert_values: ``[K, M]`` the critics on the demonstrations' measurable states and actions.
        expert_returns: ``[M]`` the same return along the demonstrations.
        policy_entropy_returns: ``[N]`` the entropy bonus's part of ``policy_returns`` (zeros without one).
        expert_entropy_returns: ``[M]`` the same part of ``expert_returns``.
        policy_rewards: ``[T]`` the learner's reward on every step of the policy's episodes.
        expert_rewards: ``[U]`` the learner's reward on every demonstrated step.
        matching_to_subgoal: the matching reward on the curriculum trajectory's steps up to the subgoal.
        matching_along_routes: per demonstration after the curriculum's (each walks the route from its own start),
            the matching reward on its every step at the current subgoal.
        final_features: ``[E, F]`` the matching features of each episode's last state.
        demo_final_features: ``[N, F]`` the matching features of each demonstration's last state.
        path_features: ``[L, F]`` the curriculum trajectory's matching features.
        episode_paths: ``[L_e, F]`` per episode, the matching features of the demonstration its goal selects
            (a goal-conditioned matching reward), else empty.
        goal_gaps: per episode (a goal-conditioned matching reward), the distance from its goal to the goal of the
            demonstration it selects, over the curriculum trajectory's length along its matching features (the
            share :func:`~torchrl_csirl.analysis.diagnostics.checks.demonstrations_share_a_goal` reads); else empty.
        actions: ``[T, A]`` the policy's actions.
        goal_conditioned: the matching reward follows the demonstration of each episode's goal
            (:class:`~torchrl_csirl.transforms.GoalConditionedMatchingReward`), not the first one only.
        observations: ``[T_j, D]`` per policy episode, its observations (each step's next one).
        demo_observations: ``[L_i, D]`` per demonstration, its observations.
        matched_features: the observation entries the matching reward's potential reads.
    """

    policy_values: torch.Tensor
    policy_returns: torch.Tensor
    expert_values: torch.Tensor
    expert_returns: torch.Tensor
    policy_rewards: torch.Tensor
    expert_rewards: torch.Tensor
    matching_to_subgoal: torch.Tensor
    final_features: torch.Tensor
    demo_final_features: torch.Tensor
    path_features: torch.Tensor
    actions: torch.Tensor
    goal_conditioned: bool = False
    episode_paths: tuple[torch.Tensor, ...] = ()
    goal_gaps: tuple[float, ...] = ()
    matching_along_routes: tuple[torch.Tensor, ...] = ()
    matching_target: str = "final"
    policy_entropy_returns: torch.Tensor = field(default_factory=lambda: torch.zeros(0))
    expert_entropy_returns: torch.Tensor = field(default_factory=lambda: torch.zeros(0))
    observations: tuple[torch.Tensor, ...] = ()
    demo_observations: tuple[torch.Tensor, ...] = ()
    matched_features: tuple[int, ...] = ()


def discounted_returns(rewards: torch.Tensor, gamma: float) -> torch.Tensor:
    """``G_t = sum_k gamma^k r_{t+k}`` over one episode's ``[T]`` rewards.

    Examples:
        >>> discounted_returns(torch.tensor([1.0, 1.0, 1.0]), 0.5)
        tensor([1.7500, 1.5000, 1.0000])
    """
    out = torch.empty_like(rewards, dtype=torch.float64)
    running = 0.0
    for t in range(rewards.shape[0] - 1, -1, -1):
        running = float(rewards[t]) + gamma * running
        out[t] = running
    return out.to(rewards.dtype)


def measurable_states(length: int, terminated: bool, gamma: float) -> torch.Tensor:
    """Which steps of an episode have a Monte Carlo return comparable to a critic's value: all of an episode that
    terminated; of a truncated one, those with enough steps left that the cut-off tail weighs under 5 %.

    Examples:
        >>> measurable_states(3, True, 0.99).tolist(), measurable_states(6, False, 0.5).tolist()
        ([True, True, True], [True, True, False, False, False, False])
    """
    if terminated:
        return torch.ones(length, dtype=torch.bool)
    horizon = math.ceil(math.log(1 - _HORIZON_WEIGHT) / math.log(gamma)) if 0 < gamma < 1 else length
    remaining = torch.arange(length, 0, -1)
    return remaining >= horizon


def _learner_reward(transforms, transitions: TensorDictBase) -> TensorDictBase:
    """``transitions`` with the learner's reward written by the online buffer's transforms (under no grad)."""
    with torch.no_grad():
        return transforms(transitions.clone())


def _next_terminated(scored: TensorDictBase) -> torch.Tensor:
    """``[T]`` whether each step ended in a terminal state (all False without a ``terminated`` entry)."""
    if ("next", "terminated") in scored.keys(True):
        return scored["next", "terminated"].reshape(-1).bool()
    return torch.zeros(scored["next", "reward"].numel(), dtype=torch.bool, device=scored.device)


def _next_entropy_bonus(loss, scored: TensorDictBase, terminated: torch.Tensor) -> torch.Tensor:
    """``[T]`` the entropy term the soft TD target adds after each step: ``-alpha log pi`` at the next state (zero
    after a terminal one, and for a loss without the term)."""
    if not hasattr(loss, "entropy_bonus"):
        return torch.zeros(terminated.shape, dtype=torch.float, device=terminated.device)
    bonus = loss.entropy_bonus(scored["next", loss.actor_network.in_keys[0]]).reshape(-1).float()
    return bonus * (~terminated).float()


def _episode_figures(episode: TensorDictBase, transforms, loss, gamma: float
                     ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """(critic values ``[K, n]``, soft returns ``[n]``, their entropy part ``[n]``, rewards ``[T]``) of one
    episode's measurable steps."""
    scored = _learner_reward(transforms, episode)
    rewards = scored["next", "reward"].reshape(-1).float()
    terminated = _next_terminated(scored)
    mask = measurable_states(rewards.shape[0], bool(terminated[-1]), gamma)
    with torch.no_grad():
        entropy_returns = discounted_returns(gamma * _next_entropy_bonus(loss, scored, terminated), gamma)[mask]
        values = loss.qvalues(scored[mask]).float()
    returns = discounted_returns(rewards, gamma)[mask] + entropy_returns
    return values.cpu(), returns.cpu(), entropy_returns.cpu(), rewards.cpu()


def probe_learner(*, env: EnvBase, policy, loss, transforms, matching, demos, gamma: float, max_steps: int,
                  episodes: int = 5, seed: int = 0, demonstrations: int = 5, device: torch.device | str = "cpu"
                  ) -> LearnerProbe:
    """Rolls the deterministic policy and reads the learner's reward and critics on its episodes and on the
    demonstrations.

    Args:
        env: an evaluation environment of the task.
        policy: the actor.
        loss: the ensemble SAC loss (``qvalues(td) -> [K, N]``).
        transforms: the online buffer's transforms (matching reward, ``r_w``, their sum into ``("next", "reward")``).
        matching: the :class:`~torchrl_csirl.transforms.SubgoalMatchingReward` (its subgoal and features).
        demos: the :class:`~torchrl_csirl.data.ExpertDemonstrations` (trajectory 0: the curriculum's).
        gamma: the learner's discount.
        max_steps: the episode limit.
        episodes: policy episodes, seeded ``seed + i``.
        seed: the first episode's seed.
        demonstrations: demonstrations scored (the first ones).
        device: the learner's device.
    """
    policy_values, policy_returns, policy_entropy, policy_rewards = [], [], [], []
    finals, actions, paths, observations, goal_gaps = [], [], [], [], []
    position = matching.position_feature_indices.cpu()
    curriculum_path = matching.expert_observations.index_select(-1, matching.position_feature_indices).float().cpu()
    with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
        for i in range(episodes):
            env.set_seed(seed + i)
            episode = env.rollout(max_steps, policy, break_when_any_done=True)
            values, returns, entropy_returns, rewards = _episode_figures(episode.to(device), transforms, loss, gamma)
            policy_values.append(values)
            policy_returns.append(returns)
            policy_entropy.append(entropy_returns)
            policy_rewards.append(rewards)
            finals.append(episode["next", "observation"][-1].index_select(-1, position))
            actions.append(episode["action"].reshape(episode.shape[0], -1))
            observations.append(flat_observations(episode["next"]))
            if hasattr(matching, "demonstration_of"):  # goal-conditioned: the path of the episode's goal
                first = episode["observation"][:1].to(device)
                chosen = int(matching.demonstration_of(first).reshape(-1)[0])
                paths.append(matching.demonstration_positions(chosen).float().cpu())
                goal_gaps.append(_goal_gap(matching.goal_of(first).reshape(-1), matching.demonstration_goals[chosen],
                                           curriculum_path))
    expert_values, expert_returns, expert_entropy, expert_rewards = [], [], [], []
    for i in range(min(demonstrations, demos.num_trajectories)):
        values, returns, entropy_returns, rewards = _episode_figures(demos.trajectory(i).to(device), transforms, loss,
                                                                     gamma)
        expert_values.append(values)
        expert_returns.append(returns)
        expert_entropy.append(entropy_returns)
        expert_rewards.append(rewards)
    demo_finals = torch.stack([demos.trajectory(i)["next", "observation"][-1].index_select(-1, position)
                               for i in range(demos.num_trajectories)]).float()
    curriculum = demos.trajectory(0)[: matching.subgoal].to(device)
    to_subgoal = torch.zeros(0)
    if matching.subgoal:
        with torch.no_grad():
            to_subgoal = matching(curriculum.clone())["next", matching.out_key].reshape(-1).float().cpu()
    with torch.no_grad():
        routes = tuple(matching(demos.trajectory(k).to(device))["next", matching.out_key].reshape(-1).float().cpu()
                       for k in range(1, min(demonstrations + 1, demos.num_trajectories)))
    return LearnerProbe(
        policy_values=torch.cat(policy_values, -1), policy_returns=torch.cat(policy_returns),
        expert_values=torch.cat(expert_values, -1), expert_returns=torch.cat(expert_returns),
        policy_rewards=torch.cat(policy_rewards), expert_rewards=torch.cat(expert_rewards),
        matching_to_subgoal=to_subgoal, final_features=torch.stack(finals).float(), demo_final_features=demo_finals.cpu(),
        path_features=curriculum_path,
        actions=torch.cat(actions).float(), goal_conditioned=hasattr(matching, "demonstration_of"), episode_paths=tuple(paths),
        goal_gaps=tuple(goal_gaps),
        matching_along_routes=routes, matching_target=getattr(matching, "target", "final"),
        policy_entropy_returns=torch.cat(policy_entropy), expert_entropy_returns=torch.cat(expert_entropy),
        observations=tuple(observations), matched_features=tuple(position.tolist()),
        demo_observations=tuple(flat_observations(demos.trajectory(i)) for i in range(demos.num_trajectories)))


def _goal_gap(goal: torch.Tensor, demonstration_goal: torch.Tensor, path: torch.Tensor) -> float:
    """The distance from an episode's ``goal`` to the goal of the demonstration it is matched against, over the length
    along ``path`` (``[L, F]``: the curriculum trajectory's matching features).

    Examples:
        >>> _goal_gap(torch.tensor([1.0, 0.5]), torch.tensor([1.0, 0.0]), torch.tensor([[0.0, 0.0], [1.0, 0.0]]))
        0.5
    """
    length = float((path[1:] - path[:-1]).norm(dim=-1).sum()) if path.shape[0] > 1 else 0.0
    return float((goal.float().cpu() - demonstration_goal.float().cpu()).norm()) / max(length, 1e-8)


def flat_observations(trajectory: TensorDictBase) -> torch.Tensor:
    """``[L, D]`` a trajectory's observations, one row per step (its batch dimensions flattened), on the CPU.

    Examples:
        >>> from tensordict import TensorDict
        >>> flat_observations(TensorDict({"observation": torch.zeros(2, 3, 4)}, [2, 3])).shape
        torch.Size([6, 4])
    """
    observation = trajectory["observation"]
    return observation.reshape(trajectory.numel(), -1).float().cpu()
