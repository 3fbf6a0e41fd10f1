"""SAC with an ensemble of independently initialised critics (the CSIRL learner)."""
from __future__ import annotations

import contextlib
import copy
import inspect
import warnings
from collections.abc import Iterator, Sequence

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModule, dispatch
from torch import nn
from torchrl import torchrl_logger
from torchrl.envs.utils import ExplorationType, set_exploration_type
from torchrl.objectives import SACLoss
from torchrl.objectives.utils import ValueEstimators, distance_loss
from torchrl.objectives.value import TD0Estimator
from torchrl.objectives.value.functional import td0_return_estimate

from torchrl_csirl._compat import (
    check_sac_internals,
    detached_qvalue_params,
    sac_alpha,
    sac_reduce_loss,
    set_qvalue_ensemble_evaluator,
    vmap_qvalue_networks,
)
from torchrl_csirl.hyperparameters import CSIRL_DEFAULTS, DISPERSIONS
from torchrl_csirl.modules.ensemble import FusedCriticEnsemble, fused_critic_ensemble
from torchrl_csirl.modules.fused_actor import FusedTanhNormalActor, fused_tanh_normal_actor

__all__ = ["EnsembleSACLoss", "qvalue_dispersion", "reinitialize_module"]

check_sac_internals()  # the SACLoss internals overridden below


def reinitialize_module(module: nn.Module) -> nn.Module:
    """Re-draws every parameter of ``module`` with its layers' default initialisation (in place).

    Each submodule exposing ``reset_parameters()`` (``nn.Linear``, ...) is reset.

    Examples:
        >>> import torch
        >>> lin = torch.nn.Linear(3, 4)
        >>> w = lin.weight.detach().clone()
        >>> _ = reinitialize_module(lin)
        >>> bool((lin.weight != w).any())
        True
    """
    found = False
    for sub in module.modules():
        reset = getattr(sub, "reset_parameters", None)
        if callable(reset):
            reset()
            found = True
    if not found and any(True for _ in module.parameters()):
        raise ValueError(
            f"Cannot re-initialise {type(module).__name__}: none of its submodules defines "
            "reset_parameters(). Pass a list of independently initialised critics instead."
        )
    return module


def qvalue_dispersion(qvalues: torch.Tensor, dispersion: str = CSIRL_DEFAULTS.dispersion) -> torch.Tensor:
    """Disagreement of an ensemble of Q estimates along dim 0 (CSIRL's uncertainty U).

    Args:
        qvalues (Tensor): ``[N, *batch]`` per-critic values.
        dispersion (str): ``"variance"`` (population variance across critics, the paper's
            choice) or ``"abs_cv"`` (``|variance / mean|``, the published code's choice;
            unstable when the mean Q is close to 0).

    Returns:
        a ``[*batch]`` tensor.

    Examples:
        >>> import torch
        >>> q = torch.tensor([[1.0, 2.0], [3.0, 2.0]])
        >>> qvalue_dispersion(q)
        tensor([1., 0.])
        >>> qvalue_dispersion(q, "abs_cv")
        tensor([0.5000, 0.0000])
    """
    if dispersion not in DISPERSIONS:
        raise ValueError(f"dispersion must be one of {DISPERSIONS}, got {dispersion!r}.")
    if qvalues.ndim < 1 or qvalues.shape[0] < 2:
        raise ValueError(
            f"qvalues must have shape [N, *batch] with N >= 2 critics, got {tuple(qvalues.shape)}."
        )
    var = qvalues.var(dim=0, correction=0)
    if dispersion == "variance":
        return var
    return (var / qvalues.mean(dim=0)).abs()


#: the notices already given in this process (``_log_sacloss_differences_once``, ``_warn_unfused_once``)
_NOTICES_GIVEN: set[str] = set()


def _first_time(notice: str) -> bool:
    """``True`` the first time ``notice`` is asked about in this process."""
    if notice in _NOTICES_GIVEN:
        return False
    _NOTICES_GIVEN.add(notice)
    return True


def _sacloss_default(name: str) -> object:
    return inspect.signature(SACLoss.__init__).parameters[name].default


def _log_sacloss_differences_once(*, reinitialized: bool, **settings: object) -> None:
    """Logs (once per process) the settings in effect that differ from ``SACLoss``'s defaults."""
    differences = [f"{name}={value!r} (SACLoss: {_sacloss_default(name)!r})" for name, value in settings.items()
                   if value != _sacloss_default(name)]
    if reinitialized:
        differences.append("critics re-initialised independently")
    if differences and _first_time("sacloss_differences"):
        torchrl_logger.info(f"EnsembleSACLoss differs from SACLoss: {', '.join(differences)} "
                            "(EnsembleSACLoss's docstring, 'Differences from SACLoss'; logged once).")


def _warn_unfused_once(part: str, reason: str) -> None:
    """Warns (once per process and ``part``) that the losses run SACLoss's unfused path, and why."""
    if _first_time(f"unfused_{part}"):
        warnings.warn(
            f"EnsembleSACLoss runs SACLoss's unfused path: {reason}. The fused path is bit-identical and "
            "faster (fused critics alone: 1.1-1.4x per update, docs/performance.md); build the "
            "networks with torchrl_csirl.modules.make_actor / make_qvalue to get it, or pass "
            "fused=False / fused_qvalue=False to silence this warning.",
            stacklevel=3,
        )


class EnsembleSACLoss(SACLoss):
    """SAC loss with ``N`` independently initialised critics, as used by CSIRL.

    A subclass of :class:`~torchrl.objectives.SACLoss` (version 2, no value network) with
    its interface (keys, ``set_keys``, value estimator, out keys). This class adds:

    * **independent critic initialisation**: :meth:`SACLoss.convert_to_functional` would
      expand a single critic and resample every parameter uniformly between its min and
      max; here each member is a deep copy of ``qvalue_network`` re-drawn with its
      layers' default initialisation (member 0 keeps the given weights). A list of
      ``N`` critics is also accepted and used as is.
    * :meth:`qvalues` / :meth:`qvalue_dispersion`: per-critic ``Q_k(s, a)`` and their
      disagreement (curricular subgoal selection).
    * **a fused critic ensemble**: for critics built by
      :func:`~torchrl_csirl.modules.make_qvalue`, every place SACLoss evaluates the ``N`` critics
      (critic loss, actor loss, target) goes through a
      :class:`~torchrl_csirl.modules.FusedCriticEnsemble` (one batched matmul per layer over the
      same stacked parameters) instead of ``torch.vmap``; values are bit-identical, see
      docs/performance.md for the speed. ``fused_qvalue=False`` keeps the vmap.
    * **a fused path for the losses** (``fused``): for an actor built by
      :func:`~torchrl_csirl.modules.make_actor` and the fused critics, ``forward``,
      :meth:`qvalue_v2_loss`, :meth:`actor_loss` and the critic target compute SACLoss's
      equations on tensors: the actor is evaluated from its parameter TensorDict by a
      :class:`~torchrl_csirl.modules.FusedTanhNormalActor` (no ``to_module`` swap, no
      TensorDict modules, no distribution objects), the TD(0) target is TorchRL's
      ``td0_return_estimate``, losses are reduced by SACLoss's own reduction. Same random draws,
      same operations in the same order: losses and gradients are bit-identical to SACLoss's
      path (``tests/test_fused_sac.py``). Options it does not implement (``skip_done_states``,
      other value estimators, ``reduction="none"`` in ``forward``) run SACLoss's path;
      :meth:`fused_applies` says which one runs. ``fused=False`` always runs SACLoss's.
    * the CSIRL defaults (:data:`~torchrl_csirl.hyperparameters.CSIRL_DEFAULTS`); see
      *Differences from SACLoss* below.
    * a **differentiable-reward mode** (:attr:`differentiable_reward` or the
      :meth:`differentiable_reward_mode` context manager): the critic target
      ``y = r + gamma (1 - terminated) V(s')`` keeps the graph of the reward ``r``
      (the bootstrap ``V(s')`` stays under ``no_grad``), which the meta-gradient of
      :class:`~torchrl_csirl.objectives.MetaRewardLoss` needs. Values are bit-identical
      to ordinary mode (the target is offset by ``r - r.detach()``, an exact zero).
    * :meth:`using_params`: evaluates the SAC losses with swapped-in (possibly
      non-leaf, graph-carrying) actor / critic parameters, including in the actor loss,
      which otherwise evaluates Q with *detached* critic parameters.

    **Differences from SACLoss** (keyword defaults; logged once per process at construction,
    naming those in effect):

    * ``num_qvalue_nets=5`` critics (``SACLoss``: 2);
    * ``alpha_init=0.01`` (``SACLoss``: 1.0); the temperature is learned (``fixed_alpha=False``) as
      in ``SACLoss``, while the paper keeps it fixed (``fixed_alpha=True``, ``preset=paper``);
    * ``loss_function="l2"`` (``SACLoss``: ``"smooth_l1"``), summed over the critics as ``SACLoss`` does;
    * critics re-initialised independently (``SACLoss``: the given critic's parameters
      resampled uniformly between their min and max);
    * the TD(0) value estimator is made at construction with ``gamma=0.99`` (``SACLoss``'s default
      estimator and discount, made on first use).

    With ``fixed_alpha=True``, ``"loss_alpha"`` is still returned (its value
    ``-log(alpha) * (log pi + target_entropy)`` measures the entropy gap) but ``log_alpha`` is a
    buffer: the entry carries no gradient, and adding it to the total loss changes nothing; read it
    as a diagnostic, not as a loss being minimised.

    Truncation is not termination: TorchRL's TD(0) estimator bootstraps with
    ``(1 - ("next", "terminated"))``, and only falls back on ``("next", "done")`` when no
    ``terminated`` entry exists. Batches must therefore carry ``("next", "terminated")``.

    Target critics are updated by the user with :class:`~torchrl.objectives.SoftUpdate`
    (``tau=0.005`` in the published code; the paper states 0.05).

    Args:
        actor_network (ProbabilisticActor): the policy (see
            :func:`~torchrl_csirl.modules.make_actor`).
        qvalue_network (TensorDictModule or list of them): one critic (copied and
            re-initialised ``num_qvalue_nets`` times) or ``num_qvalue_nets`` critics.

    Keyword Args:
        The CSIRL hyperparameters' defaults are :data:`~torchrl_csirl.hyperparameters.CSIRL_DEFAULTS`.

        num_qvalue_nets (int): ensemble size. Defaults to ``5``.
        alpha_init (float): entropy coefficient (its initial value unless ``fixed_alpha``).
            Defaults to ``0.01``.
        fixed_alpha (bool): keep alpha fixed. Defaults to ``False``: SAC's automatic temperature,
            as the recipes (the paper: ``True``, ``preset=paper``).
        gamma (float): discount of the TD(0) target. Defaults to ``0.99``.
        loss_function (str): critic regression loss. Defaults to ``"l2"`` (squared error,
            as in the published code; ``SACLoss`` defaults to ``"smooth_l1"``).
        dispersion (str): default measure of :meth:`qvalue_dispersion`, ``"variance"``
            (paper) or ``"abs_cv"`` (``|var / mean|``, code). Defaults to ``"variance"``.
        reinitialize_qvalue (bool): re-draw each copied member. Defaults to ``True``.
        differentiable_reward (bool): initial value of :attr:`differentiable_reward`.
            Defaults to ``False``.
        fused_qvalue (bool, optional): evaluate the critics with a
            :class:`~torchrl_csirl.modules.FusedCriticEnsemble` (``True``; an error if the critic
            is not supported) or with SACLoss's ``torch.vmap`` (``False``). Defaults to ``None``:
            fused when the critic is supported (else a warning, once per process, says why not).
        fused (bool, optional): compute the losses on the fused path (``True``; an error if the
            actor or the critics are not supported) or on SACLoss's (``False``). Defaults to
            ``None``: fused when supported (the results are bit-identical; else a warning, once per
            process, says why not).
        **kwargs: forwarded to :class:`~torchrl.objectives.SACLoss`.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl_csirl.modules import make_actor, make_qvalue
        >>> loss = EnsembleSACLoss(make_actor(4, 2, hidden=(8,)), make_qvalue(4, 2, hidden=(8,)))
        >>> td = TensorDict({
        ...     "observation": torch.randn(6, 4), "action": torch.rand(6, 2) * 2 - 1,
        ...     ("next", "observation"): torch.randn(6, 4), ("next", "reward"): torch.randn(6, 1),
        ...     ("next", "done"): torch.zeros(6, 1, dtype=torch.bool),
        ...     ("next", "terminated"): torch.zeros(6, 1, dtype=torch.bool)}, [6])
        >>> out = loss(td)
        >>> sorted(k for k in out.keys() if k.startswith("loss"))
        ['loss_actor', 'loss_alpha', 'loss_qvalue']
        >>> loss.qvalues(td).shape, loss.qvalue_dispersion(td).shape
        (torch.Size([5, 6]), torch.Size([6]))
    """

    # plain attributes, none of them module state; the class values hold while SACLoss.__init__ runs
    # (it calls _make_vmap before they are set)
    _fused_qvalue: FusedCriticEnsemble | None = None
    _fused_actor: FusedTanhNormalActor | None = None
    _differentiable_reward: bool = False
    _actor_loss_qvalue_params: TensorDictBase | None = None

    def __init__(
        self,
        actor_network: TensorDictModule,
        qvalue_network: TensorDictModule | Sequence[TensorDictModule],
        *,
        num_qvalue_nets: int = CSIRL_DEFAULTS.num_qvalue_nets,
        alpha_init: float = CSIRL_DEFAULTS.alpha_init,
        fixed_alpha: bool = CSIRL_DEFAULTS.fixed_alpha,
        gamma: float = CSIRL_DEFAULTS.gamma,
        loss_function: str = "l2",
        dispersion: str = CSIRL_DEFAULTS.dispersion,
        reinitialize_qvalue: bool = True,
        differentiable_reward: bool = False,
        fused_qvalue: bool | None = None,
        fused: bool | None = None,
        **kwargs,
    ) -> None:
        if kwargs.get("value_network") is not None:
            raise ValueError("EnsembleSACLoss implements SAC v2 only: value_network must be None.")
        if not isinstance(num_qvalue_nets, int) or num_qvalue_nets < 1:
            raise ValueError(f"num_qvalue_nets must be a positive int, got {num_qvalue_nets!r}.")
        if dispersion not in DISPERSIONS:
            raise ValueError(f"dispersion must be one of {DISPERSIONS}, got {dispersion!r}.")
        members = self._make_members(qvalue_network, num_qvalue_nets, reinitialize_qvalue)
        ensemble = None if fused_qvalue is False else fused_critic_ensemble(members[0])
        if fused_qvalue and ensemble is None:
            raise ValueError(
                "fused_qvalue=True needs critics built by make_qvalue (a TensorDictModule over a "
                f"ConcatMLP of Linear layers and element-wise activations), got {members[0]}."
            )
        super().__init__(
            actor_network,
            members,
            num_qvalue_nets=num_qvalue_nets,
            alpha_init=alpha_init,
            fixed_alpha=fixed_alpha,
            loss_function=loss_function,
            **kwargs,
        )
        self.make_value_estimator(ValueEstimators.TD0, gamma=gamma)
        self.dispersion = dispersion
        self.differentiable_reward = differentiable_reward
        self._fused_qvalue = ensemble
        self._make_vmap()
        self._fused_actor = self._make_fused_actor(actor_network, fused)
        _log_sacloss_differences_once(
            num_qvalue_nets=num_qvalue_nets, alpha_init=alpha_init, loss_function=loss_function,
            reinitialized=reinitialize_qvalue and not isinstance(qvalue_network, (list, tuple)),
        )
        if fused_qvalue is None and not self.fused_qvalue:
            _warn_unfused_once("critic", "the critic is not a make_qvalue ConcatMLP (critics evaluated by torch.vmap)")
        elif fused is None and self.fused_qvalue and not self.fused:
            _warn_unfused_once("actor", "the actor is not a make_actor tanh-Gaussian ProbabilisticActor")

    def _make_fused_actor(self, actor_network: TensorDictModule, fused: bool | None):
        if fused is False:
            return None
        fused_actor = fused_tanh_normal_actor(actor_network)
        if fused and (fused_actor is None or not self.fused_qvalue):
            raise ValueError(
                "fused=True needs the fused critic ensemble (fused_qvalue not False) and an actor "
                f"built by make_actor (a tanh-Gaussian ProbabilisticActor), got {actor_network}."
            )
        return fused_actor if self.fused_qvalue else None

    @property
    def fused(self) -> bool:
        """Whether the SAC losses take the fused path (:meth:`fused_applies` says when it applies)."""
        return self._fused_actor is not None

    def fused_applies(self) -> bool:
        """Whether the next loss evaluation takes the fused path.

        It does when :attr:`fused` is set and the options are those it implements: TD(0) targets
        without reward averaging, ``skip_done_states=False``. Otherwise SACLoss's own path runs.
        """
        if not self.fused or self.skip_done_states:
            return False
        estimator = self.value_estimator
        return isinstance(estimator, TD0Estimator) and not estimator.average_rewards

    @property
    def fused_qvalue(self) -> bool:
        """Whether the critics are evaluated by a fused ensemble (``False``: ``torch.vmap``)."""
        return self._fused_qvalue is not None

    def _make_vmap(self) -> None:
        super()._make_vmap()
        fused = self._fused_qvalue
        if fused is not None:
            set_qvalue_ensemble_evaluator(self, fused)

    @staticmethod
    def _make_members(
        qvalue_network: TensorDictModule | Sequence[TensorDictModule],
        num_qvalue_nets: int,
        reinitialize_qvalue: bool,
    ) -> list[TensorDictModule]:
        if isinstance(qvalue_network, (list, tuple)):
            if len(qvalue_network) != num_qvalue_nets:
                raise ValueError(
                    f"Got {len(qvalue_network)} critics but num_qvalue_nets={num_qvalue_nets}."
                )
            return list(qvalue_network)
        if not isinstance(qvalue_network, nn.Module):
            raise TypeError(
                f"qvalue_network must be a TensorDictModule or a list of them, got {type(qvalue_network)}."
            )
        members = [qvalue_network]
        for _ in range(num_qvalue_nets - 1):
            member = copy.deepcopy(qvalue_network)
            if reinitialize_qvalue:
                reinitialize_module(member)
            members.append(member)
        return members

    # ------------------------------------------------------------------ ensemble queries
    def qvalues(self, tensordict: TensorDictBase, *, target: bool = False) -> torch.Tensor:
        """Per-critic ``Q_k(s, a)`` for the observation/action entries of ``tensordict``.

        Gradients flow to the critic parameters unless called under ``torch.no_grad()``.

        Args:
            tensordict: holds the critic's input keys.

        Keyword Args:
            target (bool): evaluate the target critics (the Polyak-averaged copies that SAC's TD
                target reads) instead of the trained ones. Defaults to ``False``.

        Returns:
            a ``[N, *batch]`` tensor.
        """
        td_in = tensordict.select(*self.qvalue_network.in_keys, strict=True)
        params = self.target_qvalue_network_params if target else self.qvalue_network_params
        td_out = vmap_qvalue_networks(self, td_in, params)
        return td_out.get(self.tensor_keys.state_action_value).squeeze(-1)

    def qvalue_dispersion(
        self,
        tensordict_or_qvalues: TensorDictBase | torch.Tensor,
        dispersion: str | None = None,
    ) -> torch.Tensor:
        """Disagreement of the critics (see :func:`qvalue_dispersion`).

        Args:
            tensordict_or_qvalues: a TensorDict (evaluated with :meth:`qvalues`) or a
                precomputed ``[N, *batch]`` tensor.
            dispersion (str, optional): overrides :attr:`dispersion`.

        Returns:
            a ``[*batch]`` tensor.
        """
        if isinstance(tensordict_or_qvalues, torch.Tensor):
            qvals = tensordict_or_qvalues
        else:
            qvals = self.qvalues(tensordict_or_qvalues)
        return qvalue_dispersion(qvals, dispersion or self.dispersion)

    # ------------------------------------------------------------------ differentiable reward
    @property
    def differentiable_reward(self) -> bool:
        """Whether the critic target carries the graph of the reward."""
        return self._differentiable_reward

    @differentiable_reward.setter
    def differentiable_reward(self, value: bool) -> None:
        self._differentiable_reward = bool(value)

    @contextlib.contextmanager
    def differentiable_reward_mode(self, mode: bool = True) -> Iterator[EnsembleSACLoss]:
        """Context manager setting :attr:`differentiable_reward` temporarily."""
        prev = self.differentiable_reward
        self.differentiable_reward = mode
        try:
            yield self
        finally:
            self.differentiable_reward = prev

    def _compute_target_v2(self, tensordict: TensorDictBase) -> torch.Tensor:
        if self.fused_applies():
            target = self._fused_target(tensordict)
        else:
            target = super()._compute_target_v2(tensordict)
        if not self.differentiable_reward:
            return target
        estimator = self.value_estimator
        if not isinstance(estimator, TD0Estimator) or estimator.average_rewards:
            raise ValueError(
                "differentiable_reward requires the TD(0) value estimator without reward "
                f"averaging (got {type(estimator).__name__})."
            )
        reward = tensordict.get(("next", self.tensor_keys.reward))
        if not reward.requires_grad:
            return target
        # d target / d reward = 1 for TD(0); ``reward - reward.detach()`` is exactly 0.
        return target + (reward - reward.detach()).reshape(target.shape)

    # ------------------------------------------------------------------ fused path
    @dispatch
    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        """SACLoss's forward; on the fused path the same losses without TensorDict modules.

        Returns ``loss_actor``, ``loss_qvalue``, ``loss_alpha``, ``alpha`` and ``entropy``, and
        writes the TD errors at ``tensor_keys.priority`` of ``tensordict``, as SACLoss does.
        """
        if not self.fused_applies() or self.reduction == "none":
            return super().forward(tensordict)
        loss_qvalue, value_metadata = self.qvalue_v2_loss(tensordict)
        loss_actor, actor_metadata = self.actor_loss(tensordict)
        log_prob = actor_metadata["log_prob"]
        loss_alpha = sac_reduce_loss(self, self.alpha_loss(log_prob), tensordict)
        tensordict.set(self.tensor_keys.priority, value_metadata["td_error"])
        if loss_actor.shape != loss_qvalue.shape:
            raise RuntimeError(f"Losses shape mismatch: {loss_actor.shape} and {loss_qvalue.shape}")
        out = {
            "loss_actor": loss_actor,
            "loss_qvalue": loss_qvalue,
            "loss_alpha": loss_alpha,
            "alpha": sac_alpha(self),
            "entropy": (-log_prob).detach().mean(),
        }
        return TensorDict(out, batch_size=[])

    def qvalue_v2_loss(
        self, tensordict: TensorDictBase, *, activations: list | None = None
    ) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        """SACLoss's critic loss (``sum_k`` of the per-critic regression losses, reduced over the batch).

        On the fused path, ``activations`` (a list) receives the critics' hidden activations on the
        batch (:meth:`FusedCriticEnsemble.values <torchrl_csirl.modules.FusedCriticEnsemble.values>`);
        it stays empty otherwise.
        """
        if not self.fused_applies():
            return super().qvalue_v2_loss(tensordict)
        target = self._compute_target_v2(tensordict)
        pred = self._critic_values(tensordict, self.qvalue_network_params, activations=activations).squeeze(-1)
        td_error = abs(pred - target)
        loss = distance_loss(pred, target.expand_as(pred), loss_function=self.loss_function).sum(0)
        return sac_reduce_loss(self, loss, tensordict), {"td_error": td_error.detach().max(0)[0]}

    def actor_loss(self, tensordict: TensorDictBase) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        """SACLoss's actor loss ``alpha log pi(a|s) - min_k Q_k(s, a)``, ``a ~ pi(s)`` reparameterised."""
        if not self.fused_applies():
            return super().actor_loss(tensordict)
        fused_actor = self._fused_actor
        loc, scale = fused_actor.dist_params(tensordict.get(fused_actor.in_key), self.actor_network_params)
        action, log_prob = fused_actor.rsample_and_log_prob(loc, scale)
        qvalue = self._critic_values(tensordict, self._cached_detached_qvalue_params, action)
        min_qvalue = qvalue.min(0)[0].squeeze(-1)
        if log_prob.shape != min_qvalue.shape:
            raise RuntimeError(f"Losses shape mismatch: {log_prob.shape} and {min_qvalue.shape}")
        loss = sac_alpha(self) * log_prob - min_qvalue
        return sac_reduce_loss(self, loss, tensordict), {"log_prob": log_prob.detach()}

    def sample_actions(
        self,
        observation: torch.Tensor,
        actor_params: TensorDictBase | None = None,
        *,
        deterministic: bool = False,
    ) -> torch.Tensor:
        """Actions of the policy for ``observation`` (reparameterised draws, or the mean action).

        Args:
            observation (Tensor): ``[*B, obs]``, read as the actor's input entry.
            actor_params (TensorDictBase, optional): the actor's parameters (graph-carrying tensors
                allowed). Defaults to :attr:`actor_network_params`.

        Keyword Args:
            deterministic (bool): ``tanh(loc)`` instead of a draw. Defaults to ``False``.

        Returns:
            a ``[*B, action]`` tensor, differentiable w.r.t. ``actor_params``.
        """
        params = self.actor_network_params if actor_params is None else actor_params
        fused_actor = self._fused_actor
        if fused_actor is not None:
            loc, scale = fused_actor.dist_params(observation, params)
            return fused_actor.deterministic_sample(loc) if deterministic else fused_actor.rsample(loc, scale)
        exploration = ExplorationType.DETERMINISTIC if deterministic else ExplorationType.RANDOM
        with set_exploration_type(exploration):
            dist = self._stock_actor_dist(observation, params)
        return dist.deterministic_sample if deterministic else dist.rsample()

    def _stock_actor_dist(self, observation: torch.Tensor, params: TensorDictBase) -> torch.distributions.Distribution:
        """The stock actor's action distribution at ``observation`` under ``params`` (its location and scale
        computed, so it can be drawn from once the parameters are put back)."""
        actor = self.actor_network
        td_in = TensorDict({actor.in_keys[0]: observation}, batch_size=observation.shape[:-1])
        with params.to_module(actor, preserve_module_state=False):
            return actor.get_dist(td_in)

    def entropy_bonus(self, observation: torch.Tensor, samples: int = 16) -> torch.Tensor:
        """``-alpha log pi(a|s)`` at each state, averaged over ``samples`` draws ``a ~ pi(s)``.

        The soft TD target adds this term at every next state (``Q'(s', a') - alpha log pi(a'|s')``),
        so a critic's value holds its discounted sum beside the reward's: ``alpha`` times the
        policy's entropy per step, negative where the entropy is (SAC's target entropy is ``-dim(A)``).
        Read under no grad with the stock actor (one draw per sample, scored as drawn).

        Args:
            observation (Tensor): ``[*B, obs]``, read as the actor's input entry.
            samples (int): draws per state. Defaults to 16.

        Returns:
            a ``[*B]`` tensor.

        Examples:
            >>> import torch
            >>> from torchrl_csirl.modules import make_actor, make_qvalue
            >>> loss = EnsembleSACLoss(make_actor(3, 2, hidden=(8,)), make_qvalue(3, 2, hidden=(8,)))
            >>> loss.entropy_bonus(torch.zeros(4, 3)).shape
            torch.Size([4])
        """
        with torch.no_grad():
            dist = self._stock_actor_dist(observation, self.actor_network_params)
            if hasattr(dist, "rsample_and_log_prob"):
                _, log_prob = dist.rsample_and_log_prob((samples,))
            else:
                log_prob = dist.log_prob(dist.sample((samples,)))
            return -sac_alpha(self) * log_prob.reshape(samples, *observation.shape[:-1]).mean(0)

    def _critic_values(
        self,
        tensordict: TensorDictBase,
        params: TensorDictBase,
        action: torch.Tensor | None = None,
        activations: list | None = None,
    ) -> torch.Tensor:
        """``[N, *B, 1]`` values of the critics on ``tensordict``'s entries (``action`` replacing its action)."""
        fused_qvalue = self._fused_qvalue
        action_key = self.tensor_keys.action
        inputs = [
            action if action is not None and key == action_key else tensordict.get(key)
            for key in fused_qvalue.in_keys
        ]
        return fused_qvalue.values(fused_qvalue.concat_inputs(inputs), params, activations)

    def _fused_target(self, tensordict: TensorDictBase) -> torch.Tensor:
        """SACLoss's TD(0) target ``r + gamma (1 - terminated) min_k (Q'_k(s', a') - alpha log pi(a'|s'))``."""
        fused_actor = self._fused_actor
        estimator = self.value_estimator
        keys = estimator.tensor_keys
        next_td = tensordict.get("next")
        with torch.no_grad():
            loc, scale = fused_actor.dist_params(next_td.get(fused_actor.in_key), self.actor_network_params)
            next_action, next_log_prob = fused_actor.rsample_and_log_prob(loc, scale)
            qvalue = self._critic_values(next_td, self.target_qvalue_network_params, next_action)
            if qvalue.shape[-next_log_prob.ndim:] != next_log_prob.shape:
                next_log_prob = next_log_prob.unsqueeze(-1)
            next_value = (qvalue - sac_alpha(self) * next_log_prob).min(0)[0]
            reward = next_td.get(keys.reward)
            if estimator.gamma.device != reward.device:
                estimator.gamma = estimator.gamma.to(reward.device)
            gamma = estimator.gamma
            steps_to_next_obs = tensordict.get(keys.steps_to_next_obs, None)
            if steps_to_next_obs is not None:
                gamma = gamma ** steps_to_next_obs.view_as(reward)
            done = next_td.get(keys.done)
            terminated = next_td.get(keys.terminated, default=done)
            target = td0_return_estimate(
                gamma=gamma, next_state_value=next_value, reward=reward, done=done, terminated=terminated
            )
        return target.squeeze(-1)

    # ------------------------------------------------------------------ parameter swapping
    @property
    def _cached_detached_qvalue_params(self):
        override = self._actor_loss_qvalue_params
        if override is not None:
            return override
        return detached_qvalue_params(self)

    @contextlib.contextmanager
    def using_params(
        self,
        actor_params: TensorDictBase | None = None,
        qvalue_params: TensorDictBase | None = None,
        *,
        actor_loss_qvalue_params: TensorDictBase | None = None,
    ) -> Iterator[EnsembleSACLoss]:
        """Evaluates the losses with swapped-in parameters (graph-carrying tensors allowed).

        Args:
            actor_params (TensorDictBase, optional): replaces :attr:`actor_network_params`.
            qvalue_params (TensorDictBase, optional): replaces :attr:`qvalue_network_params`
                (shape ``[N]``) in the critic loss and in :meth:`qvalues`.

        Keyword Args:
            actor_loss_qvalue_params (TensorDictBase, optional): critic parameters used by
                :meth:`actor_loss` *without* detaching them (SACLoss detaches the critic
                there). Defaults to the detached current critic parameters.
        """
        swapped = {}
        for name, params in (
            ("actor_network_params", actor_params),
            ("qvalue_network_params", qvalue_params),
        ):
            if params is None:
                continue
            current = self._modules[name]
            if params.batch_size != current.batch_size:
                raise ValueError(
                    f"{name}: expected batch size {current.batch_size}, got {params.batch_size}."
                )
            swapped[name] = current
            self._modules[name] = params
        prev_override = self._actor_loss_qvalue_params
        self._set_actor_loss_qvalue_params(actor_loss_qvalue_params)
        try:
            yield self
        finally:
            self._modules.update(swapped)
            self._set_actor_loss_qvalue_params(prev_override)

    def _set_actor_loss_qvalue_params(self, params: TensorDictBase | None) -> None:
        """Sets the critic parameters :meth:`actor_loss` reads without registering them: a ``TensorDictParams``
        (an ``nn.Module``) assigned the usual way would become a submodule, in ``parameters()`` and the state dict."""
        object.__setattr__(self, "_actor_loss_qvalue_params", params)
