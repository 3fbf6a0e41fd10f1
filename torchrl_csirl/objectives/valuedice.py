"""ValueDICE: imitation learning via off-policy distribution matching (Kostrikov, Nachum and Tompson, ICLR 2020).

ValueDICE minimises the KL divergence between the agent's and the expert's state-action
occupancies through its Donsker-Varadhan dual, written with a value-like function ``nu(s, a)``
and its Bellman residual under the policy, ``(nu - B^pi nu)(s, a) = nu(s, a) - gamma nu(s', a')``
with ``a' ~ pi(s')``:

``J(pi, nu) = log E_{d_E}[exp(nu - B^pi nu)] - (1 - gamma) E_{s_0, a_0 ~ pi}[nu(s_0, a_0)]``,

minimised over ``nu`` and maximised over ``pi`` (the policy gradient flows through the sampled
``a'`` and ``a_0``, re-parameterised). The practical algorithm's regularisers, with the paper's
values (its experimental details; the authors' published code uses the same):

* **replay mixing**, weight ``alpha = 0.1``: the expert distribution is mixed with the
  replay buffer's, ``log E_{(1-a) d_E + a d_RB}[exp(nu - B^pi nu)] - (1 - a)(1 - gamma) E[nu(s_0, a_0)] - a E_{d_RB}[nu - B^pi nu]``,
  so that the objective stays informative where the expert data are absent;
* **orthogonal regularisation** of the actor (Brock et al. 2019), weight 1e-4;
* **gradient penalty** on ``nu`` (Gulrajani et al. 2017), weight 10, at points interpolated
  between expert and replay state-action pairs (and between their successors with the policy's
  actions), one mixing weight per sample.

Initial states ``s_0``: by default every expert state is used as an initial state, as in the
authors' published code (``google-research/value_dice``, where the initial-state batch *is* the
expert batch): the identity behind the linear term holds for any starting distribution whose
trajectories follow the policy, and expert states cover far more of the state space than the few
trajectory starts. ``initial_states="episode_starts"`` uses only the first state of each expert
trajectory (:func:`initial_observations`).

**Absorbing states**, as the paper and its code use them (DAC's, Kostrikov et al. 2019): a
terminal transition leads to an absorbing state ``s_a`` that loops on itself with the zero action,
``nu`` reads the absorbing indicator (:class:`~torchrl_csirl.objectives._imitation.AbsorbingLogit`),
``B^pi nu(s, a) = gamma nu(s_a, 0)`` after a termination, and every transition entering ``s_a``
adds one self-loop sample, whose residual is ``(1 - gamma) nu(s_a, 0)``, to its side. With the
absorbing state of :class:`~torchrl_csirl.objectives._imitation.AbsorbingStateSettings`' default,
one per terminal observation (docs/baselines.md, "DAC's absorbing states"). Without them
(``absorbing_states=False``), ``B^pi nu = 0`` after a termination.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModule
from tensordict.utils import NestedKey
from torchrl.envs.utils import ExplorationType, set_exploration_type
from torchrl.objectives import LossModule

from torchrl_csirl.objectives._imitation import (
    AbsorbingStateSettings,
    gradient_penalty,
    orthogonal_regularization,
    require_keys,
)
from torchrl_csirl.transforms.absorbing_states import check_self_loop_count

__all__ = ["ValueDICEHyperparameters", "ValueDICELoss", "initial_observations", "valuedice_objective"]


@dataclass
class ValueDICEHyperparameters(AbsorbingStateSettings):
    """ValueDICE's settings (Kostrikov et al. 2020, continuous control).

    The absorbing-state fields are :class:`~torchrl_csirl.objectives._imitation.AbsorbingStateSettings`'s
    (on by default: the paper and the authors' code use DAC's absorbing states).

    Attributes:
        actor_lr: Adam learning rate of the policy (1e-5).
        nu_lr: Adam learning rate of ``nu`` (1e-3).
        batch_size: expert and replay samples per update (256, each).
        gamma: discount (0.99).
        replay_regularization: ``alpha`` of the replay mixing (0.1).
        orthogonal_regularization: weight of the actor's orthogonal regulariser (1e-4).
        gp_lambda: weight of ``nu``'s gradient penalty (10).
        initial_states: ``"expert"`` (every expert state, the authors' code) or ``"episode_starts"``
            (the first state of each expert trajectory).
        normalize_states: the networks read states standardised with the demonstrations' mean and
            standard deviation (+ 1e-3), and the gradient penalty is measured in them: the authors'
            code's default (on MuJoCo). Off by default: the driving observations come scaled to
            [-1, 1] by highway-env and are read through maps of the raw rows; the locomotion cells
            turn it on (``TASK_OVERRIDES`` of :mod:`torchrl_csirl.sweep.plan`). Read by the recipes' network
            builder (:func:`~torchrl_csirl.modules.with_standardization`).
        max_grad_norm: gradient-norm clipping (None: none).
        exploration_noise: how the collector acts. None (default): it samples from the policy, as every
            method of the harness; a float ``sigma``: the policy's deterministic action plus ``N(0, sigma^2)``
            noise, clipped to the action bounds (:class:`~torchrl_csirl.modules.MeanActionGaussianNoise`),
            the authors' code's exploration at 0.1 (its policy has no entropy term, so the scale it would
            sample with is not trained to explore).
    """

    actor_lr: float = 1e-5
    nu_lr: float = 1e-3
    batch_size: int = 256
    gamma: float = 0.99
    replay_regularization: float = 0.1
    orthogonal_regularization: float = 1e-4
    gp_lambda: float = 10.0
    initial_states: str = "expert"
    normalize_states: bool = False
    max_grad_norm: float | None = None
    exploration_noise: float | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.initial_states not in INITIAL_STATES:
            raise ValueError(f"initial_states must be one of {INITIAL_STATES}, got {self.initial_states!r}.")
        if self.exploration_noise is not None and not self.exploration_noise > 0:
            raise ValueError(f"exploration_noise must be > 0 or None, got {self.exploration_noise}.")


INITIAL_STATES = ("expert", "episode_starts")


def initial_observations(transitions: TensorDictBase, observation_key: NestedKey = "observation") -> torch.Tensor:
    """The first observation of every trajectory of ``transitions`` (stored trajectory by trajectory).

    A transition starts a trajectory when it is the first one or when the previous one is done.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> done = torch.tensor([[False], [True], [False], [True]])
        >>> td = TensorDict({"observation": torch.arange(4.0).unsqueeze(-1), "next": {"done": done}}, [4])
        >>> initial_observations(td).squeeze(-1).tolist()
        [0.0, 2.0]
    """
    done = transitions.get(("next", "done")).reshape(-1).bool()
    starts = torch.cat([torch.ones(1, dtype=torch.bool, device=done.device), done[:-1]])
    return transitions.get(observation_key)[starts]


def valuedice_objective(expert_residual: torch.Tensor, replay_residual: torch.Tensor, initial_nu: torch.Tensor,
                        gamma: float, alpha: float) -> torch.Tensor:
    """``J(pi, nu)`` with replay mixing: the log-sum-exp term minus the linear terms.

    Args:
        expert_residual: ``nu - B^pi nu`` on expert pairs ``[B_E]``.
        replay_residual: ``nu - B^pi nu`` on replay pairs ``[B_RB]``.
        initial_nu: ``nu(s_0, a_0)``, ``a_0 ~ pi(s_0)``, ``[B_0]``.
        gamma: discount.
        alpha: replay-mixing weight (0: the plain objective).

    Examples:
        >>> import torch
        >>> z = torch.zeros(4)
        >>> float(valuedice_objective(z, z, z, 0.99, 0.1))  # log E[exp 0] = 0
        0.0
    """
    terms = [expert_residual + math.log((1 - alpha) / expert_residual.numel())]
    if alpha > 0:
        terms.append(replay_residual + math.log(alpha / replay_residual.numel()))
    log_expectation = torch.logsumexp(torch.cat(terms), 0)
    linear = (1 - alpha) * (1 - gamma) * initial_nu.mean()
    if alpha > 0:
        linear = linear + alpha * replay_residual.mean()
    return log_expectation - linear


class ValueDICELoss(LossModule):
    """ValueDICE's objective for ``nu`` (minimised) and the policy (maximised), with its regularisers.

    The input holds ``"expert"`` and ``"collector"`` (replay) transitions (observation, action,
    ``("next", "observation")``, ``("next", "terminated")``) and ``"initial"``, a tensordict of
    initial observations. When ``nu_network`` reads the absorbing indicator (built by
    ``logit_network(qvalue, "nu", absorbing_key="absorbing")``), the transitions also carry the
    entries of :class:`~torchrl_csirl.transforms.AbsorbingStates` and a termination leads to the
    absorbing state (module docstring). Outputs:

    * ``loss_nu``: ``J`` (:func:`valuedice_objective`), and ``loss_gradient_penalty``, for ``nu``;
    * ``loss_actor``: ``-J``, and ``loss_orthogonal`` (on the actor's hidden layers, as the
      authors' code regularises the actor's trunk), for the policy;
    * ``policy_scale``: a metric, the mean scale the policy samples with at the replay's next states.

    ``loss_nu`` and ``loss_actor`` share one graph and reach both networks: the update applies
    the gradient of the ``nu`` terms to ``nu`` only and of the actor terms to the actor only
    (:class:`~torchrl_csirl.trainers.imitation_updates.ValueDICEUpdate`).

    Args:
        actor_network: the policy (re-parameterised sampling).
        nu_network: ``nu(s, a)`` writing ``nu_key`` (e.g. built from a critic).

    Keyword Args:
        gamma (float): Defaults to ``0.99``.
        replay_regularization (float): ``alpha``. Defaults to ``0.1``.
        orthogonal_regularization (float): Defaults to ``1e-4``.
        gp_lambda (float): Defaults to ``10``.
        observation_scale (tensor, optional): when the networks read standardised states
            (:class:`~torchrl_csirl.modules.StandardizeFeatures` first in their input map), its scale:
            the gradient penalty is then measured in the standardised states, as in the authors' code,
            whose networks read them directly. Defaults to ``None`` (the raw observation).
        self_loops_per_termination (int): absorbing self-loop samples per replay transition entering the
            absorbing state (the expert's: one, as the authors' code stores them): their weight in the replay
            terms (:func:`~torchrl_csirl.transforms.absorbing_states.absorbing_self_loops`). Defaults to ``1``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl_csirl.modules import make_actor, make_qvalue
        >>> from torchrl_csirl.objectives._imitation import logit_network
        >>> loss = ValueDICELoss(make_actor(3, 1, hidden=(8,)), logit_network(make_qvalue(3, 1, hidden=(8,)), "nu"))
        >>> def t(n):
        ...     return TensorDict({"observation": torch.randn(n, 3), "action": torch.rand(n, 1),
        ...                        "next": {"observation": torch.randn(n, 3),
        ...                                 "terminated": torch.zeros(n, 1, dtype=torch.bool)}}, [n])
        >>> td = TensorDict({"expert": t(4), "collector": t(4),
        ...                  "initial": TensorDict({"observation": torch.randn(4, 3)}, [4])}, [])
        >>> sorted(k for k in loss(td).keys() if k.startswith("loss"))
        ['loss_actor', 'loss_gradient_penalty', 'loss_nu', 'loss_orthogonal']
    """

    @dataclass
    class _AcceptedKeys:
        """Configurable tensordict keys (``set_keys``).

        Attributes:
            expert: expert transitions. Defaults to ``"expert"``.
            collector: replay transitions. Defaults to ``"collector"``.
            initial: initial observations. Defaults to ``"initial"``.
            observation: Defaults to ``"observation"``.
            action: Defaults to ``"action"``.
            terminated: inside ``"next"``. Defaults to ``"terminated"``.
            absorbing: the absorbing-state indicator. Defaults to ``"absorbing"``.
            nu: ``nu``'s output. Defaults to ``"nu"``.
        """

        expert: NestedKey = "expert"
        collector: NestedKey = "collector"
        initial: NestedKey = "initial"
        observation: NestedKey = "observation"
        action: NestedKey = "action"
        terminated: NestedKey = "terminated"
        absorbing: NestedKey = "absorbing"
        nu: NestedKey = "nu"

    tensor_keys: _AcceptedKeys
    default_keys = _AcceptedKeys
    out_keys = ["loss_nu", "loss_gradient_penalty", "loss_actor", "loss_orthogonal"]

    def __init__(self, actor_network: TensorDictModule, nu_network: TensorDictModule, *, gamma: float = 0.99,
                 replay_regularization: float = 0.1, orthogonal_regularization: float = 1e-4,
                 gp_lambda: float = 10.0, observation_scale: torch.Tensor | None = None,
                 self_loops_per_termination: int = 1) -> None:
        super().__init__()
        check_self_loop_count(self_loops_per_termination, "self_loops_per_termination")
        self.self_loops_per_termination = int(self_loops_per_termination)
        if not 0.0 <= replay_regularization < 1.0:
            raise ValueError(f"replay_regularization must be in [0, 1), got {replay_regularization}.")
        if not 0.0 <= gamma < 1.0:
            raise ValueError(f"gamma must be in [0, 1), got {gamma}.")
        self.actor_network = actor_network
        self.nu_network = nu_network
        self.gamma = float(gamma)
        self.replay_regularization = float(replay_regularization)
        self.orthogonal_regularization = float(orthogonal_regularization)
        self.gp_lambda = float(gp_lambda)
        # not saved: it is nu's input map's own scale, rebuilt with the network
        self.register_buffer("observation_scale", None if observation_scale is None
                             else torch.as_tensor(observation_scale, dtype=torch.float32).detach().clone(), persistent=False)

    def _forward_value_estimator_keys(self, **kwargs) -> None:
        pass

    def _policy_sample(self, observation: torch.Tensor) -> TensorDictBase:
        """``a ~ pi(s)``, re-parameterised, beside the distribution's parameters (``"loc"``, ``"scale"``)."""
        td = TensorDict({self.tensor_keys.observation: observation}, observation.shape[:1])
        with set_exploration_type(ExplorationType.RANDOM):
            return td.set(self.tensor_keys.action, self.actor_network.get_dist(td).rsample())

    @property
    def reads_absorbing(self) -> bool:
        """Whether ``nu`` reads the absorbing indicator (absorbing states on)."""
        return self.tensor_keys.absorbing in self.nu_network.in_keys

    def nu(self, observation: torch.Tensor, action: torch.Tensor, absorbing: torch.Tensor | None = None) -> torch.Tensor:
        """``nu(s, a)`` (``nu(s, i, a)`` with the absorbing indicator ``i``, 0 when not given): ``[B]``."""
        keys = self.tensor_keys
        td = TensorDict({keys.observation: observation, keys.action: action}, observation.shape[:1])
        if self.reads_absorbing:
            td.set(keys.absorbing, torch.zeros(*observation.shape[:1], 1, device=observation.device)
                   if absorbing is None else absorbing)
        return self.nu_network(td).get(keys.nu).squeeze(-1)

    def _residual(self, transitions: TensorDictBase, self_loops: int = 1) -> tuple[torch.Tensor, TensorDictBase]:
        """``(nu - B^pi nu)(s, a)`` on the transitions (then on the absorbing self-loops they enter, ``self_loops``
        each), and the successor pairs ``(s', i', a')`` with ``a' ~ pi(s')`` (zero in the absorbing state)."""
        keys = self.tensor_keys
        next_obs = transitions.get(("next", keys.observation))
        successor = self._policy_sample(next_obs)
        if not self.reads_absorbing:
            not_terminated = 1.0 - transitions.get(("next", keys.terminated)).float().reshape(-1)
            residual = (self.nu(transitions.get(keys.observation), transitions.get(keys.action))
                        - self.gamma * not_terminated * self.nu(next_obs, successor.get(keys.action)))
            return residual, successor
        into = transitions.get(("next", keys.absorbing)).reshape(-1, 1)
        successor.set(keys.action, torch.where(into, 0.0, successor.get(keys.action)))
        successor.set(keys.absorbing, into)
        next_nu = self.nu(next_obs, successor.get(keys.action), into)
        residual = (self.nu(transitions.get(keys.observation), transitions.get(keys.action),
                            transitions.get(keys.absorbing)) - self.gamma * next_nu)
        # the self-loops (s_a, 0) -> (s_a, 0): their nu is the successor's where the transition enters s_a
        loops = (1.0 - self.gamma) * next_nu[into.reshape(-1)]
        return torch.cat([residual, loops.repeat(self_loops)]), successor

    def _penalty(self, expert: TensorDictBase, replay: TensorDictBase, expert_successor: TensorDictBase,
                 replay_successor: TensorDictBase) -> torch.Tensor:
        """WGAN-GP on ``nu`` at per-sample interpolations of expert and replay pairs and of their
        successors (the absorbing indicator interpolated as a number)."""
        keys = self.tensor_keys
        n = min(expert.numel(), replay.numel())
        eps = torch.rand(n, 1, device=expert.device)  # one mixing weight per sample
        inputs = [keys.observation, keys.action] + ([keys.absorbing] if self.reads_absorbing else [])

        def mixed(key: NestedKey) -> torch.Tensor:
            pairs = [(expert.get(key), replay.get(key)), (expert_successor.get(key), replay_successor.get(key))]
            return torch.cat([eps * a[:n].detach().float() + (1 - eps) * b[:n].detach().float() for a, b in pairs])

        scales = [self.observation_scale] + [None] * (len(inputs) - 1)
        return self.gp_lambda * gradient_penalty(self.nu, [mixed(key) for key in inputs], scales=scales)

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        keys = self.tensor_keys
        expert, replay = tensordict.get(keys.expert), tensordict.get(keys.collector)
        needed = [keys.observation, keys.action, ("next", keys.observation), ("next", keys.terminated)]
        if self.reads_absorbing:  # written by AbsorbingStates on both buffers
            needed += [keys.absorbing, ("next", keys.absorbing)]
        require_keys(expert, needed, "ValueDICE expert transitions")
        require_keys(replay, needed, "ValueDICE replay transitions")
        initial = tensordict.get(keys.initial)
        require_keys(initial, [keys.observation], "ValueDICE initial states")
        expert_residual, expert_successor = self._residual(expert)
        replay_residual, replay_successor = self._residual(replay, self.self_loops_per_termination)
        initial_obs = initial.get(keys.observation)
        initial_nu = self.nu(initial_obs, self._policy_sample(initial_obs).get(keys.action))
        objective = valuedice_objective(expert_residual, replay_residual, initial_nu, self.gamma,
                                        self.replay_regularization)
        return TensorDict({
            "loss_nu": objective,
            "loss_gradient_penalty": self._penalty(expert, replay, expert_successor, replay_successor),
            "loss_actor": -objective,
            "loss_orthogonal": self.orthogonal_regularization * orthogonal_regularization(self.actor_network,
                                                                                          skip_last=True),
            **self._sampling_scale(replay_successor),
        }, [])

    @staticmethod
    def _sampling_scale(successor: TensorDictBase) -> dict[str, torch.Tensor]:
        """``policy_scale``: the mean scale the policy samples with at the replay's next states (a metric,
        detached; nothing trains it but ``-J``, the policy having no entropy term), when the actor writes one."""
        scale = successor.get("scale", None)
        return {} if scale is None else {"policy_scale": scale.detach().mean()}
