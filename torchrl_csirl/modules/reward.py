"""The CSIRL intrinsic reward network r_w: an MLP with a tanh output in (-1, 1), and its
expert-centred form (an option of ours, not in the paper)."""
from __future__ import annotations

from collections.abc import Sequence

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModule, TensorDictModuleBase
from tensordict.utils import NestedKey
from torch import nn
from torchrl.modules import MLP

from torchrl_csirl.modules.actor_critic import _input_size
from torchrl_csirl.modules.precision import mlp_forward

__all__ = [
    "REWARD_ACTIVATIONS",
    "ExpertCenteredReward",
    "RewardMLP",
    "expert_reference_states",
    "make_reward_network",
]

#: Hidden-layer activations of :class:`RewardMLP` by name. ``"relu"`` is the paper's; the smooth ones
#: have a non-zero derivative everywhere, so no unit stops receiving gradient for good (ReLU units
#: of ``r_w`` do die in training: docs/studies/index.md, "The meta-gradient's parts normalised").
REWARD_ACTIVATIONS: dict[str, type[nn.Module]] = {"relu": nn.ReLU, "elu": nn.ELU, "silu": nn.SiLU, "tanh": nn.Tanh}


def _activation_class(activation: str) -> type[nn.Module]:
    if activation not in REWARD_ACTIVATIONS:
        raise ValueError(f"activation must be one of {sorted(REWARD_ACTIVATIONS)}, got {activation!r}.")
    return REWARD_ACTIVATIONS[activation]


class RewardMLP(nn.Module):
    """Concatenates its inputs and maps them through an MLP and ``tanh`` to ``(-1, 1)``.

    Args:
        in_features (int): total input size (sum of the inputs' last dimensions).
        hidden (sequence of int): hidden widths. Defaults to ``(256, 256)``.
        input_features (nn.Module, optional): a parameter-free map of the first input (the
            observation); ``in_features`` then counts its output size.
        activation (str): hidden-layer activation, a key of :data:`REWARD_ACTIVATIONS`.
            Defaults to ``"relu"`` (the paper).

    Examples:
        >>> import torch
        >>> net = RewardMLP(3)
        >>> out = net(torch.randn(5, 2), torch.randn(5, 1))
        >>> out.shape, bool((out.abs() < 1).all())
        (torch.Size([5, 1]), True)
    """

    def __init__(self, in_features: int, hidden: Sequence[int] = (256, 256),
                 input_features: nn.Module | None = None, activation: str = "relu") -> None:
        super().__init__()
        self.input_features = input_features
        self.mlp = MLP(
            in_features=in_features,
            out_features=1,
            num_cells=list(hidden),
            activation_class=_activation_class(activation),
        )

    def forward(self, *inputs: torch.Tensor) -> torch.Tensor:
        if self.input_features is not None:
            inputs = (self.input_features(inputs[0]), *inputs[1:])
        x = inputs[0] if len(inputs) == 1 else torch.cat(inputs, dim=-1)
        return torch.tanh(mlp_forward(self.mlp, x))


def make_reward_network(
    obs_dim: int,
    action_dim: int | None = None,
    hidden: Sequence[int] = (256, 256),
    in_keys: Sequence[NestedKey] | None = None,
    out_key: NestedKey = "intrinsic_reward",
    input_features: nn.Module | None = None,
    activation: str = "relu",
) -> TensorDictModule:
    """Builds the intrinsic reward network ``r_w`` (MLP, ReLU by default, tanh output in ``(-1, 1)``).

    State-only ``r_w(s)`` by default (the published code); state-action ``r_w(s, a)`` (the
    paper) when ``action_dim`` is given.

    Args:
        obs_dim (int): observation size.
        action_dim (int, optional): action size; ``None`` (default) for a state-only reward.
        hidden (sequence of int): hidden widths. Defaults to ``(256, 256)``.
        in_keys (sequence of NestedKey, optional): input keys. Defaults to ``["observation"]``
            (state-only) or ``["observation", "action"]``.
        out_key (NestedKey): output key. Defaults to ``"intrinsic_reward"``.
        input_features (nn.Module, optional): a parameter-free map of the observation (see
            :func:`~torchrl_csirl.modules.make_actor`). Defaults to ``None``.
        activation (str): hidden-layer activation, a key of :data:`REWARD_ACTIVATIONS`
            (``"relu"``, ``"elu"``, ``"silu"``, ``"tanh"``). Defaults to ``"relu"`` (the paper).

    Returns:
        TensorDictModule: writes ``out_key`` with shape ``[*B, 1]``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> net = make_reward_network(4)
        >>> td = net(TensorDict({"observation": torch.randn(8, 4)}, [8]))
        >>> td["intrinsic_reward"].shape
        torch.Size([8, 1])
        >>> sa = make_reward_network(4, action_dim=2)
        >>> sa.in_keys
        ['observation', 'action']
        >>> make_reward_network(4, activation="elu").module.mlp[1]
        ELU(alpha=1.0)
    """
    for name, value in (("obs_dim", obs_dim), ("action_dim", action_dim)):
        if value is None and name == "action_dim":
            continue
        if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
            raise ValueError(f"{name} must be a positive int, got {value!r}.")
    hidden = tuple(hidden)
    if not hidden or any(isinstance(h, bool) or not isinstance(h, int) or h <= 0 for h in hidden):
        raise ValueError(f"hidden must be a non-empty sequence of positive ints, got {hidden!r}.")
    if in_keys is None:
        in_keys = ["observation"] if action_dim is None else ["observation", "action"]
    in_keys = list(in_keys)
    expected = 1 if action_dim is None else 2
    if len(in_keys) != expected:
        raise ValueError(
            f"in_keys must name {expected} input(s) ({'state' if expected == 1 else 'state, action'}), "
            f"got {in_keys}."
        )
    in_features = _input_size(obs_dim, input_features) + (action_dim or 0)
    module = RewardMLP(in_features, hidden, input_features, activation=activation)
    return TensorDictModule(module, in_keys=in_keys, out_keys=[out_key])


class ExpertCenteredReward(TensorDictModuleBase):
    r"""``r'(s) = scale * (r_w(s) - mean_{s_e in E} r_w(s_e))``: the learned reward measured against
    its mean over a fixed set ``E`` of expert states.

    Without it the meta-gradient of ``r_w`` is dominated by a constant shift (a living bonus or
    penalty that saturates ``tanh`` within a few hundred updates, docs/studies/index.md), or, with the
    ``|r_w|`` regulariser, by the regulariser (``r_w`` stays near 0 and inert). Subtracting the mean
    over expert states removes the constant direction exactly: for any ``c``,
    ``r_w + c`` gives the same ``r'``, so the meta-gradient can only move ``r_w`` *between* states
    (above or below how it rates the expert's). ``scale`` puts ``r'`` on the scale of the
    matching reward. Works per state (an env transform) as well as on batches, since ``E`` is fixed.

    Args:
        reward_network (TensorDictModule): a state-only ``r_w`` (one in-key, the observation),
            e.g. :func:`make_reward_network`.
        reference_observations (torch.Tensor): ``[M, obs_dim]`` expert states ``E`` (e.g. a
            fixed sample of the demonstrations' observations).

    Keyword Args:
        scale (float): multiplies the centred reward. Defaults to ``1.0``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> expert_states = torch.randn(16, 4)
        >>> r = ExpertCenteredReward(make_reward_network(4), expert_states, scale=2.0)
        >>> out = r(TensorDict({"observation": expert_states}, [16]))["intrinsic_reward"]
        >>> bool(out.mean().abs() < 1e-5), out.shape
        (True, torch.Size([16, 1]))
    """

    def __init__(self, reward_network: TensorDictModule, reference_observations: torch.Tensor, *,
                 scale: float = 1.0) -> None:
        super().__init__()
        if len(reward_network.in_keys) != 1:
            raise ValueError(
                f"ExpertCenteredReward needs a state-only reward network (one in-key), got in_keys "
                f"{list(reward_network.in_keys)}."
            )
        if reference_observations.ndim != 2 or reference_observations.shape[0] == 0:
            raise ValueError(
                f"reference_observations must be a non-empty [M, obs_dim] tensor, got shape "
                f"{tuple(reference_observations.shape)}."
            )
        if not torch.isfinite(reference_observations).all():
            raise ValueError("reference_observations contain NaN or inf.")
        if not scale > 0:
            raise ValueError(f"scale must be > 0, got {scale}.")
        self.reward_network = reward_network
        self.in_keys = list(reward_network.in_keys)
        self.out_keys = list(reward_network.out_keys)
        self.scale = float(scale)
        self.register_buffer("reference_observations", reference_observations.detach().clone())

    def reference_mean(self) -> torch.Tensor:
        """``mean_{s_e in E} r_w(s_e)`` (graph kept)."""
        return self.reward_network.module(self.reference_observations).mean()

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        key = self.out_keys[0]
        tensordict = self.reward_network(tensordict)
        centred = self.scale * (tensordict.get(key) - self.reference_mean())
        tensordict.set(key, centred)
        return tensordict


def expert_reference_states(observations: torch.Tensor, size: int = 256, seed: int = 0) -> torch.Tensor:
    """A fixed, seeded sample of at most ``size`` expert states for :class:`ExpertCenteredReward`.

    Examples:
        >>> expert_reference_states(torch.arange(10.).reshape(5, 2), size=3).shape
        torch.Size([3, 2])
    """
    if size <= 0:
        raise ValueError(f"size must be > 0, got {size}.")
    if observations.shape[0] <= size:
        return observations.clone()
    generator = torch.Generator().manual_seed(seed)
    return observations[torch.randperm(observations.shape[0], generator=generator)[:size]].clone()
