"""Meta-gradient loss of the CSIRL intrinsic reward (paper Eq. 11-15)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import torch
from tensordict import TensorDict, TensorDictBase, is_tensor_collection
from tensordict.nn import TensorDictModule
from tensordict.utils import NestedKey
from torchrl.data import ReplayBuffer
from torchrl.objectives.common import LossModule
from torchrl.objectives.value import TD0Estimator

from torchrl_csirl._compat import sac_alpha, sac_reduce_loss, sac_reduced_alpha_loss
from torchrl_csirl.hyperparameters import CSIRL_DEFAULTS, GRADIENT_BALANCES, META_GRADIENTS
from torchrl_csirl.objectives.ensemble_sac import EnsembleSACLoss

__all__ = ["MetaRewardLoss", "balanced_meta_gradient"]

def _nested(prefix: NestedKey, key: NestedKey) -> tuple[str, ...]:
    """``key`` under ``prefix`` as one flat nested key."""
    return (prefix if isinstance(prefix, tuple) else (prefix,)) + (key if isinstance(key, tuple) else (key,))


def _check_flat(batch: TensorDictBase, name: str) -> None:
    if batch.batch_dims != 1:
        raise ValueError(f"Expected a flat {name} batch, got batch size {tuple(batch.batch_size)}.")


def _broadcast(batch: TensorDictBase, batch_size: torch.Size, name: str) -> TensorDictBase:
    """``batch`` ``[E]`` as an expanded view ``[*batch_size, E]`` (stored inside a batch of ``batch_size``)."""
    _check_flat(batch, name)
    return batch.expand(*batch_size, *batch.batch_size)


def _leaves_like(params: TensorDictBase) -> TensorDict:
    """Detached copies (sharing storage) of ``params`` that are fresh autograd leaves (a plain TensorDict)."""
    leaves = {key: value.detach().requires_grad_(True) for key, value in params.items(True, True)}
    return TensorDict(leaves, batch_size=params.batch_size)


def sgd_lookahead(
    loss: torch.Tensor, params: TensorDictBase, lr: float, *, create_graph: bool = True
) -> TensorDictBase:
    """One differentiable plain-SGD step ``params - lr * grad(loss, params)`` (Eq. 12 / 13).

    With ``create_graph=True`` the returned parameters keep the graph of the gradient, so
    anything ``loss`` depended on (e.g. the reward parameters ``w``) stays reachable.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> p = TensorDict({"w": torch.ones(2, requires_grad=True)}, [])
        >>> w = torch.tensor(3.0, requires_grad=True)
        >>> new = sgd_lookahead((w * p["w"]).sum(), p, lr=0.1)
        >>> new["w"]  # 1 - 0.1 * w
        tensor([0.7000, 0.7000], grad_fn=<AddBackward0>)
    """
    return _sgd_lookahead_and_grads(loss, params, lr, create_graph=create_graph)[0]


def _grads_or_zeros(
    loss: torch.Tensor,
    params: list[torch.Tensor],
    *,
    grad_outputs: torch.Tensor | None = None,
    create_graph: bool = False,
    retain_graph: bool | None = None,
) -> list[torch.Tensor]:
    """``d loss / d params`` (a vector-Jacobian product with ``grad_outputs``), zeros where ``loss`` does not depend."""
    grads = torch.autograd.grad(
        loss, params, grad_outputs=grad_outputs, create_graph=create_graph, retain_graph=retain_graph, allow_unused=True
    )
    return [torch.zeros_like(p) if g is None else g for p, g in zip(params, grads)]


def _reduction_weights(loss: LossModule, per_sample: torch.Tensor, tensordict: TensorDictBase) -> torch.Tensor:
    """``rho_i = d reduce(l) / d l_i``: the weight of each sample in the SAC loss's reduction (``1 / B`` for a mean).

    The reduction (mean or sum, priority weights, masks) is linear in the per-sample losses, so
    its derivative at zero is the weight of each sample.
    """
    with torch.enable_grad():
        probe = torch.zeros_like(per_sample, requires_grad=True)
        (rho,) = torch.autograd.grad(sac_reduce_loss(loss, probe, tensordict), probe)
    return rho


def _sgd_lookahead_and_grads(
    loss: torch.Tensor, params: TensorDictBase, lr: float, *, create_graph: bool = True
) -> tuple[TensorDictBase, list[torch.Tensor]]:
    keys = list(params.keys(True, True))
    tensors = [params.get(k) for k in keys]
    grads = _grads_or_zeros(loss, tensors, create_graph=create_graph)
    out = params.empty()
    for key, tensor, grad in zip(keys, tensors, grads):
        out.set(key, torch.add(tensor, grad, alpha=-lr))  # one fused pass (and one in backward)
    return out, grads


def _norm(tensors: list[torch.Tensor]) -> torch.Tensor:
    """Global L2 norm of a list of tensors (detached)."""
    return torch.linalg.vector_norm(torch.stack(torch._foreach_norm([t.detach() for t in tensors])))


def balanced_meta_gradient(
    grads_imitation: list[torch.Tensor],
    grads_l1: list[torch.Tensor] | None,
    *,
    l1_weight: float,
    scale: float,
    eps: float = 1e-12,
) -> list[torch.Tensor]:
    """``scale * (g_I / |g_I| + l1_weight * g_R / |g_R|)``: the meta-gradient with its two parts normalised.

    ``g_I`` is the imitation part of the meta-gradient (Eq. 14-15), ``g_R`` the regulariser's
    (``mean |r_w|``), each as a list of per-parameter tensors with one global L2 norm. ``g_I``
    reaches ``w`` through two inner SGD steps and scales with ``lr_inner**2``; ``g_R`` does not,
    so in the plain sum their ratio is set by ``lr_inner`` and by how sharp the critics are, not by
    a choice. Normalised, the direction of the step weighs the two in the ratio ``1 : l1_weight``
    at every update. A part whose norm is zero (or ``grads_l1=None``) contributes nothing.

    Examples:
        >>> import torch
        >>> g = balanced_meta_gradient([torch.tensor([3.0, 4.0])], [torch.tensor([0.0, 200.0])],
        ...                            l1_weight=0.5, scale=10.0)
        >>> g[0]  # 10 * ([0.6, 0.8] + 0.5 * [0, 1])
        tensor([ 6., 13.])
    """
    parts = [(grads_imitation, 1.0)]
    if grads_l1 is not None and l1_weight > 0:
        parts.append((grads_l1, l1_weight))
    out = [torch.zeros_like(g) for g in grads_imitation]
    for grads, weight in parts:
        factor = scale * weight / (_norm(grads) + eps)
        torch._foreach_add_(out, torch._foreach_mul(grads, factor))
    return out


class _WithGradients(torch.autograd.Function):
    """``value`` (detached) whose backward hands ``grads`` (times the incoming scalar) to ``params``."""

    @staticmethod
    def forward(ctx, value: torch.Tensor, grads: tuple[torch.Tensor, ...], *params: torch.Tensor) -> torch.Tensor:
        ctx.grads = grads
        return value.clone()

    @staticmethod
    def backward(ctx, grad_output: torch.Tensor) -> tuple[torch.Tensor | None, ...]:
        return (None, None, *(g * grad_output for g in ctx.grads))


def _linear_surrogate(
    value: torch.Tensor, params: list[torch.Tensor], grads: list[torch.Tensor]
) -> torch.Tensor:
    """A scalar equal to ``value`` whose gradient w.r.t. ``params`` is exactly ``grads``.

    The same value and gradient as ``value + sum_i <p_i, g_i> - sum_i <p_i, g_i>`` (detached), without
    computing the inner products.

    Examples:
        >>> import torch
        >>> p = torch.zeros(2, requires_grad=True)
        >>> s = _linear_surrogate(torch.tensor(5.0), [p], [torch.tensor([1.0, 2.0])])
        >>> s.backward()
        >>> s.item(), p.grad
        (5.0, tensor([1., 2.]))
    """
    return _WithGradients.apply(value.detach(), tuple(g.detach() for g in grads), *params)


@dataclass
class _MetaStep:
    """What one meta-gradient computation gives :meth:`MetaRewardLoss.forward`."""

    td: TensorDictBase  # the online batch with its local reward
    loss: torch.Tensor  # L_meta
    loss_imitation: torch.Tensor
    loss_l1: torch.Tensor
    loss_q: torch.Tensor  # L_Q(phi, w), of the inner critic step
    loss_pi: torch.Tensor  # L_pi(theta, phi'), of the inner actor step
    grads_phi: list[torch.Tensor]  # grad_phi L_Q
    td_error: torch.Tensor  # per sample, detached
    grads: list[torch.Tensor]  # dL_meta/dw
    grads_imitation: list[torch.Tensor]  # its imitation part
    grads_l1: list[torch.Tensor] | None  # its regulariser part (None: no regulariser)


class MetaRewardLoss(LossModule):
    r"""Meta-gradient loss of the CSIRL intrinsic reward network ``r_w`` (paper Eq. 11-15).

    Trains ``r_w`` so that one SAC step on the local reward ``r = r_m + r_w(s)`` brings the actor
    closer to the expert: from the current critics ``phi`` and actor ``theta`` it takes an inner
    critic step ``phi'`` (:meth:`inner_critic_step`) and an inner actor step ``theta'``
    (:meth:`inner_actor_step`), both differentiable in ``w``, and scores ``theta'`` on expert pairs:
    ``L_meta = scale * (mean (a_hat - a_e)^2 + reward_l1_coef * mean |r_w(s)|)``,
    ``a_hat ~ pi_theta'(s_e)`` (:meth:`imitation_loss`).

    ``"loss_meta"`` has the value of ``L_meta`` and backpropagates into the reward network only: the
    actor and the critics are never written to, and ``meta.parameters()`` are the reward network's.
    The online batch's TD errors are written at ``"td_error"`` (the SAC loss's
    ``tensor_keys.priority``) for a prioritised buffer. docs/components/meta-reward.md shows a full
    update; docs/algorithm.md (the meta-gradient of r_w) derives it and discusses the two parts'
    balance and the ``"jvp"`` path.

    Args:
        sac_loss (EnsembleSACLoss): the learner's loss; its current parameters are used.
        reward_network (TensorDictModule): ``r_w``; reads the online batch's root entries
            (``"observation"``) and writes ``intrinsic_reward``.

    Keyword Args:
        lr_inner (float): inner SGD step size (the published code's). Defaults to ``0.01``.
        scale (float): multiplies the meta-objective (the recipes' ``csirl.meta_scale``). Defaults to ``100.0``.
        reward_l1_coef (float): weight of ``mean |r_w(s)|``. ``0`` disables it. Defaults to ``1.0``.
        deterministic_expert_action (bool): use the mean action of ``pi_theta'`` instead of
            a reparameterised sample. Defaults to ``False``.
        use_matching_reward (bool): add ``("next", matching_reward)`` to ``r_w``; ``False``: ``r_w``
            alone. Defaults to ``True``.
        gradient_balance (str): ``"sum"`` (the gradient of ``L_meta``) or ``"normalized"``
            (:func:`balanced_meta_gradient` of the imitation and regulariser parts).
            Defaults to ``"sum"``.
        joint_sac_update (bool): also return the ordinary SAC losses of ``sac_loss`` on the same
            batch and local reward (``"loss_qvalue"``, ``"loss_actor"``, ``"loss_alpha"``,
            ``"alpha"``, ``"entropy"``), sharing the critic pass with the inner critic step, so that
            one backward of ``loss_qvalue + loss_actor + loss_meta`` gives the SAC gradients and the
            meta-gradient. The inner steps then start from the pre-update networks, as in the
            published code. Defaults to ``False``.
        meta_gradient (str): ``"double_backward"`` (differentiate through both inner steps) or
            ``"jvp"`` (the inner critic step differentiated in closed form, the same gradient up
            to rounding; needs the fused critic ensemble, the ``"l2"`` critic loss and a TD(0)
            target). Defaults to ``"double_backward"``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from tensordict.nn import TensorDictModule
        >>> from torchrl_csirl.modules import make_actor, make_qvalue
        >>> sac = EnsembleSACLoss(make_actor(4, 2, hidden=(8,)), make_qvalue(4, 2, hidden=(8,)))
        >>> reward = TensorDictModule(torch.nn.Sequential(torch.nn.Linear(4, 1), torch.nn.Tanh()),
        ...     in_keys=["observation"], out_keys=["intrinsic_reward"])
        >>> meta = MetaRewardLoss(sac, reward)
        >>> online = TensorDict({
        ...     "observation": torch.randn(6, 4), "action": torch.rand(6, 2) * 2 - 1,
        ...     ("next", "observation"): torch.randn(6, 4),
        ...     ("next", "matching_reward"): torch.randn(6, 1),
        ...     ("next", "done"): torch.zeros(6, 1, dtype=torch.bool),
        ...     ("next", "terminated"): torch.zeros(6, 1, dtype=torch.bool)}, [6])
        >>> expert = TensorDict({"observation": torch.randn(3, 4), "action": torch.rand(3, 2)}, [3])
        >>> out = meta(online, expert)
        >>> out["loss_meta"].backward()
        >>> reward.module[0].weight.grad is not None, all(p.grad is None for p in sac.parameters())
        (True, True)
        >>> td = meta.meta_batch(online, expert)  # one TensorDict: the expert batch at "expert"
        >>> td["expert"].batch_size, td.batch_size
        (torch.Size([6, 3]), torch.Size([6]))
        >>> sorted(k for k in meta(td).keys() if k.startswith("loss_"))[:3], td["td_error"].shape
        (['loss_imitation', 'loss_inner_actor', 'loss_inner_qvalue'], torch.Size([6]))
    """

    @dataclass
    class _AcceptedKeys:
        """Configurable tensordict keys (``set_keys``).

        Attributes:
            matching_reward (NestedKey): matching reward, read at
                ``("next", matching_reward)`` of the online batch (unless the loss was
                built with ``use_matching_reward=False``). Defaults to ``"matching_reward"``.
            intrinsic_reward (NestedKey): output key of the reward network.
                Defaults to the network's first out-key (``"intrinsic_reward"``).
            expert_observation (NestedKey): observation key of the expert batch.
                Defaults to ``"observation"``.
            expert_action (NestedKey): action key of the expert batch.
                Defaults to ``"action"``.
            expert (NestedKey): where the one-tensordict call (``loss(td)``) finds the expert
                batch. Defaults to ``"expert"``.
            regularizer (NestedKey): where the one-tensordict call finds the batch of the
                ``mean |r_w(s)|`` regulariser (optional; absent: the online batch).
                Defaults to ``"regularizer"``.
        """

        matching_reward: NestedKey = "matching_reward"
        intrinsic_reward: NestedKey = "intrinsic_reward"
        expert_observation: NestedKey = "observation"
        expert_action: NestedKey = "action"
        expert: NestedKey = "expert"
        regularizer: NestedKey = "regularizer"

    default_keys = _AcceptedKeys
    tensor_keys: _AcceptedKeys
    out_keys: ClassVar[list[str]] = [
        "loss_meta",
        "loss_imitation",
        "loss_reward_l1",
        "loss_inner_qvalue",
        "loss_inner_actor",
        "intrinsic_reward_mean",
        "meta_grad_norm",
        "meta_grad_norm_imitation",
        "meta_grad_norm_l1",
    ]

    def __init__(
        self,
        sac_loss: EnsembleSACLoss,
        reward_network: TensorDictModule,
        *,
        lr_inner: float = CSIRL_DEFAULTS.lr_inner,
        scale: float = CSIRL_DEFAULTS.meta_scale,
        reward_l1_coef: float = CSIRL_DEFAULTS.reward_l1_coef,
        deterministic_expert_action: bool = False,
        use_matching_reward: bool = True,
        gradient_balance: str = CSIRL_DEFAULTS.gradient_balance,
        joint_sac_update: bool = False,
        meta_gradient: str = CSIRL_DEFAULTS.meta_gradient,
    ) -> None:
        if not isinstance(sac_loss, EnsembleSACLoss):
            raise TypeError(f"sac_loss must be an EnsembleSACLoss, got {type(sac_loss).__name__}.")
        if not isinstance(reward_network, torch.nn.Module):
            raise TypeError(
                f"reward_network must be a TensorDictModule, got {type(reward_network).__name__}."
            )
        if lr_inner <= 0 or scale <= 0 or reward_l1_coef < 0:
            raise ValueError(
                "Need lr_inner > 0, scale > 0 and reward_l1_coef >= 0, got "
                f"{lr_inner}, {scale}, {reward_l1_coef}."
            )
        if gradient_balance not in GRADIENT_BALANCES:
            raise ValueError(f"gradient_balance must be one of {GRADIENT_BALANCES}, got {gradient_balance!r}.")
        if meta_gradient not in META_GRADIENTS:
            raise ValueError(f"meta_gradient must be one of {META_GRADIENTS}, got {meta_gradient!r}.")
        if meta_gradient == "jvp" and not (sac_loss.fused_qvalue and sac_loss.loss_function == "l2"):
            raise ValueError(
                "meta_gradient='jvp' needs the fused critic ensemble (critics built by make_qvalue, "
                f"fused_qvalue not False) and loss_function='l2'; got fused_qvalue={sac_loss.fused_qvalue}, "
                f"loss_function={sac_loss.loss_function!r}."
            )
        super().__init__()
        # object.__setattr__, not nn.Module's: the SAC loss is not a submodule, meta_loss.parameters() are the reward's only
        object.__setattr__(self, "sac_loss", sac_loss)
        self.reward_network = reward_network
        self.lr_inner = float(lr_inner)
        self.scale = float(scale)
        self.reward_l1_coef = float(reward_l1_coef)
        self.deterministic_expert_action = bool(deterministic_expert_action)
        self.use_matching_reward = bool(use_matching_reward)
        self.gradient_balance = gradient_balance
        self.joint_sac_update = bool(joint_sac_update)
        self.meta_gradient = meta_gradient
        out_keys = list(getattr(reward_network, "out_keys", []))
        if out_keys and out_keys[0] != self.tensor_keys.intrinsic_reward:
            self.set_keys(intrinsic_reward=out_keys[0])

    def _forward_value_estimator_keys(self, **kwargs) -> None:
        pass

    @property
    def in_keys(self) -> list[NestedKey]:
        """The entries :meth:`forward` reads from a one-tensordict batch (:meth:`meta_batch`'s layout)."""
        keys = list(self.sac_loss.in_keys) + list(self.reward_network.in_keys)
        if self.use_matching_reward:
            keys.append(("next", self.tensor_keys.matching_reward))
        reward = ("next", self.sac_loss.tensor_keys.reward)
        expert = self.tensor_keys.expert
        keys += [_nested(expert, self.tensor_keys.expert_observation), _nested(expert, self.tensor_keys.expert_action)]
        return [k for k in dict.fromkeys(keys) if k != reward]

    # ------------------------------------------------------------------ one-tensordict batches
    def meta_batch(
        self,
        online: TensorDictBase,
        expert: TensorDictBase,
        regularizer: TensorDictBase | None = None,
    ) -> TensorDictBase:
        """The three batches of the meta-loss in one TensorDict, the layout ``loss(td)`` reads.

        The root is (a shallow copy of) the online batch, with its batch size ``[B]``, so that
        ``td_error`` and ``index`` sit where a prioritised buffer's ``update_tensordict_priority``
        looks. The expert batch ``[E]`` (and the regulariser's ``[R]``) are stored at
        ``tensor_keys.expert`` (``tensor_keys.regularizer``) broadcast along the online batch
        (an expanded view ``[B, E]``, no copy); :meth:`split_meta_batch` takes them back.

        Args:
            online (TensorDictBase): online batch ``[B]``.
            expert (TensorDictBase): expert pairs ``[E]``.
            regularizer (TensorDictBase, optional): batch of the ``mean |r_w(s)|`` regulariser.

        Returns:
            a TensorDict of batch size ``[B]``.
        """
        _check_flat(online, "online")
        td = online.copy()
        td.set(self.tensor_keys.expert, _broadcast(expert, online.batch_size, "expert"))
        if regularizer is not None:
            td.set(self.tensor_keys.regularizer, _broadcast(regularizer, online.batch_size, "regularizer"))
        return td

    def sample_meta_batch(
        self, online_rb: ReplayBuffer, expert_rb: ReplayBuffer, regularizer_rb: ReplayBuffer | None = None
    ) -> TensorDictBase:
        """Samples the online, expert and (optionally) regulariser buffers into one :meth:`meta_batch`.

        Args:
            online_rb (ReplayBuffer): the online transitions (with ``("next", matching_reward)``).
            expert_rb (ReplayBuffer): the expert ``(observation, action)`` pairs.
            regularizer_rb (ReplayBuffer, optional): sampled once more for the regulariser (the
                published code and :class:`~torchrl_csirl.trainers.MetaRewardUpdate` use a second
                online batch: pass ``online_rb``). Defaults to ``None``: the online batch.

        Returns:
            a TensorDict of the online batch size, for ``loss(td)``.
        """
        regularizer = None if regularizer_rb is None else regularizer_rb.sample()
        return self.meta_batch(online_rb.sample(), expert_rb.sample(), regularizer)

    def split_meta_batch(
        self, tensordict: TensorDictBase
    ) -> tuple[TensorDictBase, TensorDictBase, TensorDictBase | None]:
        """``(online, expert, regularizer)`` of a one-tensordict batch (:meth:`meta_batch`).

        The nested batches are read at ``tensor_keys.expert`` / ``tensor_keys.regularizer`` and
        un-broadcast along the root's batch dims (index 0); the online batch is the rest of the
        root, a view sharing its tensors. A root of batch size ``[]`` is read as an online batch
        whose batch size is its entries' leading dimension.
        """
        keys = self.tensor_keys
        expert = tensordict.get(keys.expert, None)
        if not is_tensor_collection(expert):
            raise KeyError(
                f"The batch has no expert batch at {keys.expert!r}: build it with meta_batch / sample_meta_batch, "
                "or call the loss with three arguments, loss(online, expert, regularizer)."
            )
        regularizer = tensordict.get(keys.regularizer, None)
        online = tensordict.exclude(keys.expert, keys.regularizer)
        if online.batch_dims == 0:
            online.auto_batch_size_(batch_dims=1)
        index = (0,) * tensordict.batch_dims
        expert = expert[index] if index else expert
        if regularizer is not None and index:
            regularizer = regularizer[index]
        return online, expert, regularizer

    # ------------------------------------------------------------------ pieces of the loss
    def intrinsic_reward(self, tensordict: TensorDictBase) -> torch.Tensor:
        """``r_w`` on the root entries of ``tensordict`` (graph kept)."""
        td_in = tensordict.select(*self.reward_network.in_keys, strict=True)
        return self.reward_network(td_in).get(self.tensor_keys.intrinsic_reward)

    def local_reward(self, tensordict: TensorDictBase, r_w: torch.Tensor) -> torch.Tensor:
        """``r = r_m + r_w`` (``r_m`` read at ``("next", matching_reward)``, no grad)."""
        if not self.use_matching_reward:
            return r_w
        key = self.tensor_keys.matching_reward
        r_m = tensordict.get(("next", key), None)
        if r_m is None:
            raise KeyError(
                f"The online batch has no ('next', {key!r}) entry (matching reward). "
                "Set it, or build the loss with use_matching_reward=False to use r_w only."
            )
        return r_m.detach() + r_w.reshape(r_m.shape)

    def inner_critic_step(self, tensordict: TensorDictBase, actor_params, qvalue_params):
        """Eq. 12: ``phi' = phi - lr_in * grad_phi L_Q(phi, w)``, graph kept.

        Returns ``phi'``, ``L_Q(phi, w)`` and ``grad_phi L_Q``.
        """
        return self._inner_critic_step(tensordict, actor_params, qvalue_params)[:3]

    def _inner_critic_step(self, tensordict: TensorDictBase, actor_params, qvalue_params):
        """:meth:`inner_critic_step`, and the per-sample TD errors of the critic loss (detached)."""
        sac = self.sac_loss
        with sac.using_params(actor_params, qvalue_params), sac.differentiable_reward_mode():
            loss_q, metadata = sac.qvalue_v2_loss(tensordict)
        qvalue_params_new, grads = _sgd_lookahead_and_grads(loss_q, qvalue_params, self.lr_inner)
        return qvalue_params_new, loss_q, grads, metadata["td_error"].detach()

    def inner_actor_step(self, tensordict: TensorDictBase, actor_params, qvalue_params_new):
        """Eq. 13: ``theta' = theta - lr_in * grad_theta L_pi(theta, phi')``, graph kept."""
        sac = self.sac_loss
        with sac.using_params(actor_params, actor_loss_qvalue_params=qvalue_params_new):
            loss_pi, _ = sac.actor_loss(tensordict)
        return sgd_lookahead(loss_pi, actor_params, self.lr_inner), loss_pi

    def imitation_loss(self, expert: TensorDictBase, actor_params) -> torch.Tensor:
        """Eq. 11: ``mean (a_hat - a_e)^2`` with ``a_hat ~ pi_theta'(s_e)``."""
        observation = expert.get(self.tensor_keys.expert_observation)
        a_hat = self.sac_loss.sample_actions(
            observation, actor_params, deterministic=self.deterministic_expert_action
        )
        a_e = expert.get(self.tensor_keys.expert_action)
        if a_hat.shape != a_e.shape:
            raise ValueError(
                f"Expert action shape {tuple(a_e.shape)} does not match the policy's {tuple(a_hat.shape)}."
            )
        return (a_hat - a_e).pow(2).mean()

    def forward(
        self,
        tensordict: TensorDictBase,
        expert: TensorDictBase | None = None,
        regularizer: TensorDictBase | None = None,
    ) -> TensorDictBase:
        """Computes ``L_meta`` and its gradient w.r.t. the reward network.

        Called with one TensorDict (``loss(td)``, TorchRL's convention), ``td`` holds the three
        batches (:meth:`meta_batch`, :meth:`sample_meta_batch`); called with two or three, the
        online, expert and regulariser batches. Both run the same computation.

        The online batch's TD errors (those of the current critics, the inner critic step's,
        detached, one per sample: ``max_k |Q_k(s, a) - y|``) are written at the SAC loss's
        ``tensor_keys.priority`` (``"td_error"``) of ``tensordict``, as :class:`SACLoss` does,
        for a prioritised buffer's ``update_tensordict_priority(tensordict)``.

        Args:
            tensordict (TensorDictBase): online batch (the SAC loss's keys plus
                ``("next", matching_reward)``), or the one-tensordict batch.
            expert (TensorDictBase, optional): expert pairs (``observation``, ``action``), e.g. 32.
                Defaults to ``None``: ``tensordict`` is a one-tensordict batch.
            regularizer (TensorDictBase, optional): batch on which ``mean |r_w(s)|`` is
                taken (the code uses a fresh online batch). Defaults to the online batch.

        Returns:
            a TensorDict with ``"loss_meta"`` (backpropagates into the reward network only)
            and detached diagnostics (and the SAC losses with ``joint_sac_update``).
        """
        online = tensordict
        if expert is None:
            if regularizer is not None:
                raise ValueError("A regularizer batch was given without an expert batch.")
            online, expert, regularizer = self.split_meta_batch(tensordict)
        out, td_error = self._meta_loss(online, expert, regularizer)
        tensordict.set(self.sac_loss.tensor_keys.priority, td_error)
        return out

    def _meta_loss(
        self, tensordict: TensorDictBase, expert: TensorDictBase, regularizer: TensorDictBase | None
    ) -> tuple[TensorDictBase, torch.Tensor]:
        """The losses on the three batches, and the online batch's TD errors."""
        if tensordict.ndim != 1 or expert.ndim != 1:
            raise ValueError(
                f"Expected flat batches, got batch sizes {tensordict.batch_size} and {expert.batch_size}."
            )
        sac = self.sac_loss
        w_params = [p for p in self.reward_network.parameters() if p.requires_grad]
        if not w_params:
            raise ValueError("The reward network has no trainable parameters.")
        # the SAC losses run on detached leaves sharing the networks' storage (swapped in by
        # ``sac.using_params``): the meta-loss never writes gradients into the actor or the critics
        theta = _leaves_like(sac.actor_network_params)
        phi = _leaves_like(sac.qvalue_network_params)
        r_w = self.intrinsic_reward(tensordict)
        meta_gradient = self._jvp_meta_gradient if self.meta_gradient == "jvp" else self._double_backward_meta_gradient
        step = meta_gradient(tensordict, expert, regularizer, r_w, theta, phi, w_params)
        grads = step.grads
        if self.gradient_balance == "normalized":
            grads = balanced_meta_gradient(
                step.grads_imitation, step.grads_l1, l1_weight=self.reward_l1_coef, scale=self.scale
            )
        out = {
            # the gradient is already computed, restricted to w (autograd prunes the second-order paths
            # towards phi and theta): "loss_meta" has the value of L_meta and hands exactly ``grads`` to w
            "loss_meta": _linear_surrogate(step.loss, w_params, grads),
            "loss_imitation": step.loss_imitation.detach(),
            "loss_reward_l1": step.loss_l1.detach(),
            "loss_inner_qvalue": step.loss_q.detach(),
            "loss_inner_actor": step.loss_pi.detach(),
            "intrinsic_reward_mean": r_w.detach().mean(),
            "meta_grad_norm": _norm(grads),
            "meta_grad_norm_imitation": _norm(step.grads_imitation),
            "meta_grad_norm_l1": _norm(step.grads_l1) if step.grads_l1 is not None else r_w.new_zeros(()),
        }
        if self.joint_sac_update:
            out.update(self._sac_losses(step.td, step.loss_q, step.grads_phi))
        return TensorDict(out, batch_size=[]), step.td_error

    def _with_local_reward(self, tensordict: TensorDictBase, r_w: torch.Tensor) -> TensorDictBase:
        """A shallow copy of the online batch whose ``("next", reward)``, the key the critic loss reads, is
        :meth:`local_reward` (the batch's own ``("next", reward)``, if any, is not read)."""
        td = tensordict.copy()
        td.set("next", tensordict.get("next").copy())
        td.set(("next", self.sac_loss.tensor_keys.reward), self.local_reward(tensordict, r_w))
        return td

    def _meta_objective(
        self, loss_imitation: torch.Tensor, r_w: torch.Tensor, regularizer: TensorDictBase | None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """``L_meta`` and the regulariser ``mean |r_w|`` (on ``regularizer``, else on the online batch's ``r_w``)."""
        if self.reward_l1_coef > 0:
            r_reg = r_w if regularizer is None else self.intrinsic_reward(regularizer)
            loss_l1 = r_reg.abs().mean()
            return self.scale * (loss_imitation + self.reward_l1_coef * loss_l1), loss_l1
        return self.scale * loss_imitation, r_w.new_zeros(())

    def _double_backward_meta_gradient(
        self,
        tensordict: TensorDictBase,
        expert: TensorDictBase,
        regularizer: TensorDictBase | None,
        r_w: torch.Tensor,
        theta: TensorDictBase,
        phi: TensorDictBase,
        w_params: list[torch.Tensor],
    ) -> _MetaStep:
        """``meta_gradient="double_backward"``: both inner steps keep their graphs, ``dL_meta/dw`` goes through them."""
        td = self._with_local_reward(tensordict, r_w)
        phi_new, loss_q, grads_phi, td_error = self._inner_critic_step(td, theta, phi)
        theta_new, loss_pi = self.inner_actor_step(td, theta, phi_new)
        loss_imitation = self.imitation_loss(expert, theta_new)
        loss, loss_l1 = self._meta_objective(loss_imitation, r_w, regularizer)
        grads_l1 = None
        if self.reward_l1_coef > 0:  # the regulariser's share (a cheap diagnostic), the imitation part by difference
            grads_l1 = _grads_or_zeros(self.scale * self.reward_l1_coef * loss_l1, w_params, retain_graph=True)
        grads = _grads_or_zeros(loss, w_params)
        grads_imitation = grads if grads_l1 is None else torch._foreach_sub(grads, grads_l1)
        return _MetaStep(td, loss, loss_imitation, loss_l1, loss_q, loss_pi, grads_phi, td_error,
                         grads, grads_imitation, grads_l1)

    def _jvp_meta_gradient(
        self,
        tensordict: TensorDictBase,
        expert: TensorDictBase,
        regularizer: TensorDictBase | None,
        r_w: torch.Tensor,
        theta: TensorDictBase,
        phi: TensorDictBase,
        w_params: list[torch.Tensor],
    ) -> _MetaStep:
        """``meta_gradient="jvp"``: the inner critic step differentiated in closed form (:meth:`_jvp_chain`), the
        imitation part one backward through ``r_w`` alone, then the regulariser's."""
        td = self._with_local_reward(tensordict, r_w.detach())  # the critic step is differentiated by hand: no graph
        loss_q, grads_phi, loss_pi, loss_imitation, cotangent, td_error = self._jvp_chain(td, expert, theta, phi)
        loss, loss_l1 = self._meta_objective(loss_imitation, r_w, regularizer)
        retain = self.reward_l1_coef > 0 and regularizer is None  # the regulariser's backward reuses r_w's graph
        grads_imitation = _grads_or_zeros(r_w, w_params, grad_outputs=cotangent.reshape(r_w.shape), retain_graph=retain)
        grads, grads_l1 = grads_imitation, None
        if self.reward_l1_coef > 0:
            grads_l1 = _grads_or_zeros(self.scale * self.reward_l1_coef * loss_l1, w_params)
            grads = torch._foreach_add(grads_imitation, grads_l1)
        return _MetaStep(td, loss, loss_imitation, loss_l1, loss_q, loss_pi, grads_phi, td_error,
                         grads, grads_imitation, grads_l1)

    def _jvp_chain(
        self, td: TensorDictBase, expert: TensorDictBase, theta: TensorDictBase, phi: TensorDictBase
    ) -> tuple[torch.Tensor, list[torch.Tensor], torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """The two inner steps and the imitation loss, the critic step differentiated in closed form.

        With ``L_Q = reduce_i sum_k (Q_k(s_i, a_i) - y_i)^2`` and ``dy_i / dr_w(s_i) = 1`` (TD(0)),
        ``dL_meta/dw = 2 lr_in sum_i rho_i (sum_k grad_phi_k Q_k(s_i, a_i) . g_k) dr_w(s_i)/dw`` with
        ``g = dL_imitation/dphi'`` and ``rho_i`` the weight of sample ``i`` in the reduction.

        Returns ``L_Q``, ``grad_phi L_Q``, ``L_pi``, the imitation loss, the cotangent
        ``scale * 2 lr_in rho_i sum_k grad_phi_k Q_k(s_i, a_i) . g_k`` of ``r_w`` (shaped like
        ``r_w``'s output), whose backward through the reward network is the imitation part
        of the meta-gradient, and the per-sample TD errors of ``L_Q`` (detached).
        """
        sac = self.sac_loss
        estimator = sac.value_estimator
        if not isinstance(estimator, TD0Estimator) or estimator.average_rewards:
            raise ValueError(
                "meta_gradient='jvp' requires the TD(0) value estimator without reward averaging "
                f"(got {type(estimator).__name__})."
            )
        keys = list(phi.keys(True, True))
        phi_list = [phi.get(k) for k in keys]
        # Eq. 12 without a graph: phi' are fresh leaves, reached by the outer gradient only
        activations = []  # the critics' hidden activations on the batch, for the forward-mode pass
        with sac.using_params(theta, phi):
            loss_q, metadata = sac.qvalue_v2_loss(td, activations=activations)
        grads_phi = _grads_or_zeros(loss_q, phi_list)
        phi_new = phi.empty()
        for key, tensor, grad in zip(keys, phi_list, grads_phi):
            phi_new.set(key, torch.add(tensor.detach(), grad, alpha=-self.lr_inner).requires_grad_(True))
        # Eq. 13 and 11 with their graphs; g = dL_imitation / dphi' (a double backward through the actor step)
        theta_new, loss_pi = self.inner_actor_step(td, theta, phi_new)
        loss_imitation = self.imitation_loss(expert, theta_new)
        g = _grads_or_zeros(loss_imitation, [phi_new.get(k) for k in keys])
        with torch.no_grad():
            fused = sac._fused_qvalue
            tangents = phi.empty()
            for key, tangent in zip(keys, g):
                tangents.set(key, tangent)
            dq = fused.jvp(fused.critic_input(td), phi, tangents, activations or None)  # [N, B, 1]
            per_sample = dq.squeeze(-1).sum(0)  # sum_k grad_phi_k Q_k(s_i, a_i) . g_k
            rho = _reduction_weights(sac, per_sample, td)
            cotangent = (2 * self.lr_inner * self.scale) * rho * per_sample
        return loss_q, grads_phi, loss_pi, loss_imitation, cotangent, metadata["td_error"].detach()

    def _sac_losses(
        self, td: TensorDictBase, loss_q: torch.Tensor, grads_phi: list[torch.Tensor]
    ) -> dict[str, torch.Tensor]:
        """The ordinary SAC losses, reusing ``L_Q(phi, w)`` and its gradient (``loss_qvalue`` is a linear surrogate
        carrying it); the actor loss sees the critics before their update, as in the published code."""
        sac = self.sac_loss
        phi_real = list(sac.qvalue_network_params.values(True, True))
        loss_qvalue = _linear_surrogate(loss_q, phi_real, grads_phi)
        loss_actor, metadata = sac.actor_loss(td)
        log_prob = metadata["log_prob"]
        loss_alpha = sac_reduced_alpha_loss(sac, log_prob, td)
        return {
            "loss_qvalue": loss_qvalue,
            "loss_actor": loss_actor,
            "loss_alpha": loss_alpha,
            "alpha": sac_alpha(sac),
            "entropy": -log_prob.mean(),
        }
