"""Exploration of a stochastic policy with fixed Gaussian noise around its deterministic action."""
from __future__ import annotations

from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torchrl.envs.utils import ExplorationType, set_exploration_type
from torchrl.modules import AdditiveGaussianModule

__all__ = ["MeanActionGaussianNoise"]


class MeanActionGaussianNoise(TensorDictModuleBase):
    """Acts with ``policy``'s deterministic action plus ``N(0, sigma^2)`` noise, projected into its action spec.

    ValueDICE's code explores this way (the tanh-Gaussian policy's mean action plus noise of standard
    deviation 0.1, clipped to ``[-1, 1]``): its policy is trained without an entropy term, so the scale it
    would sample with is not a learned exploration. The noise is TorchRL's
    :class:`~torchrl.modules.AdditiveGaussianModule` at a constant ``sigma``; under a deterministic
    exploration type (evaluation) the module returns the policy's deterministic action, noise-free.
    It holds ``policy`` itself (not a copy): the two share their parameters.

    Args:
        policy: a probabilistic actor with an action spec (:func:`~torchrl_csirl.modules.make_actor`).
        sigma: the noise's standard deviation (> 0).
        action_key: Defaults to ``"action"``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.envs.utils import ExplorationType, set_exploration_type
        >>> from torchrl_csirl.modules import make_actor
        >>> actor = make_actor(3, 2, hidden=(8,))
        >>> explorer = MeanActionGaussianNoise(actor, sigma=0.1)
        >>> td = TensorDict({"observation": torch.randn(5, 3)}, [5])
        >>> with set_exploration_type(ExplorationType.RANDOM):
        ...     action = explorer(td.clone())["action"]
        >>> with set_exploration_type(ExplorationType.DETERMINISTIC):
        ...     mean = actor(td.clone())["action"]
        >>> bool((action.abs() <= 1).all()), bool((action - mean).abs().max() > 0)
        (True, True)
    """

    def __init__(self, policy: TensorDictModuleBase, sigma: float, action_key: str = "action") -> None:
        if not sigma > 0:
            raise ValueError(f"sigma must be > 0, got {sigma}.")
        spec = getattr(policy, "spec", None)
        if spec is None or action_key not in spec.keys():
            raise ValueError(f"the policy has no spec for {action_key!r}: the noise is projected into the action bounds.")
        self.in_keys = list(policy.in_keys)
        self.out_keys = list(policy.out_keys)
        super().__init__()
        self.policy = policy
        self.noise = AdditiveGaussianModule(spec[action_key], sigma_init=float(sigma), sigma_end=float(sigma),
                                            annealing_num_steps=1, action_key=action_key)

    @property
    def sigma(self) -> float:
        """The noise's standard deviation."""
        return float(self.noise.sigma)

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        with set_exploration_type(ExplorationType.DETERMINISTIC):
            tensordict = self.policy(tensordict)
        return self.noise(tensordict)  # the caller's exploration type again: noise unless deterministic
