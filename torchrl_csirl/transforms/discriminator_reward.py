"""The reward of an adversarial imitation method, read from its discriminator's logit."""
from __future__ import annotations

import torch
import torch.nn.functional as F
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from tensordict.utils import NestedKey

from torchrl_csirl.transforms._utils import TransitionRewardTransform
from torchrl_csirl.transforms.absorbing_states import absorbing_self_loops, absorbing_value

__all__ = ["DiscriminatorReward", "discriminator_reward"]

_FORMS = ("gail", "logit")


def discriminator_reward(logit: torch.Tensor, form: str) -> torch.Tensor:
    """The reward of a transition whose discriminator outputs ``D = sigmoid(logit)`` (``D``: "is expert").

    * ``"gail"``: ``-log(1 - D) = softplus(logit)``, the generator reward of GAIL in its usual
      non-saturating form (Ho and Ermon 2016 minimise ``E[log D']`` with ``D'`` the "is agent"
      probability, i.e. ``1 - D`` here);
    * ``"logit"``: ``log D - log(1 - D) = logit``, DAC's reward (Kostrikov et al. 2019),
      also AIRL's.

    Examples:
        >>> import torch
        >>> logit = torch.tensor([-2.0, 0.0, 2.0])
        >>> discriminator_reward(logit, "gail")
        tensor([0.1269, 0.6931, 2.1269])
        >>> discriminator_reward(logit, "logit")
        tensor([-2.,  0.,  2.])
    """
    if form == "gail":
        return F.softplus(logit)
    if form == "logit":
        return logit
    raise ValueError(f"form must be one of {_FORMS}, got {form!r}.")


class DiscriminatorReward(TransitionRewardTransform):
    """Writes the discriminator reward of each transition under ``("next", out_key)``.

    The discriminator (held by reference, so every update is seen at the next sample) reads its
    ``in_keys`` (``"observation"``, ``"action"``, DAC's ``"absorbing"``) from the transition and
    writes a logit under ``logit_key``; :func:`discriminator_reward` turns it into a reward. Use
    it as a replay-buffer transform of the online buffer: rewards are recomputed at sampling time.

    Args:
        discriminator (TensorDictModuleBase): writes ``logit_key``.
        form (str): ``"gail"`` (``-log(1 - D)``) or ``"logit"`` (``log D - log(1 - D)``, DAC).

    Keyword Args:
        logit_key (NestedKey): the discriminator's logit entry. Defaults to ``"discriminator_logit"``.
        out_key (NestedKey): the reward entry inside ``"next"``. Defaults to ``"reward"``.
        absorbing_gamma (float, optional): with DAC's absorbing states
            (:class:`~torchrl_csirl.transforms.AbsorbingStates`), the discount: a transition entering
            the absorbing state also gets the value of its self-loop, ``gamma r_a / (1 - gamma)``
            (:func:`~torchrl_csirl.transforms.absorbing_states.absorbing_value`), ``r_a`` being the
            discriminator reward of the absorbing state. Defaults to ``None`` (no absorbing state).
        absorbing_key (NestedKey): the indicator entry. Defaults to ``"absorbing"``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from tensordict.nn import TensorDictModule
        >>> disc = TensorDictModule(torch.nn.Linear(3, 1), in_keys=["observation"], out_keys=["discriminator_logit"])
        >>> td = TensorDict({"observation": torch.zeros(2, 3), "next": {"observation": torch.zeros(2, 3)}}, [2])
        >>> r = DiscriminatorReward(disc, "logit")(td)["next", "reward"]
        >>> r.shape, r.requires_grad
        (torch.Size([2, 1]), False)
    """

    def __init__(self, discriminator: TensorDictModuleBase, form: str, *, logit_key: NestedKey = "discriminator_logit",
                 out_key: NestedKey = "reward", absorbing_gamma: float | None = None,
                 absorbing_key: NestedKey = "absorbing") -> None:
        if form not in _FORMS:
            raise ValueError(f"form must be one of {_FORMS}, got {form!r}.")
        if not isinstance(discriminator, TensorDictModuleBase):
            raise TypeError(f"discriminator must be a TensorDictModule, got {type(discriminator).__name__}.")
        super().__init__(in_keys=list(discriminator.in_keys), out_key=out_key)
        self.discriminator = discriminator
        self.form = form
        self.logit_key = logit_key
        if absorbing_gamma is not None:
            absorbing_value(torch.zeros(()), absorbing_gamma)  # checks gamma
        self.absorbing_gamma = absorbing_gamma
        self.absorbing_key = absorbing_key

    def _reward(self, samples: TensorDictBase) -> torch.Tensor:
        with torch.no_grad():
            logit = self.discriminator(samples.select(*self.discriminator.in_keys)).get(self.logit_key)
        return discriminator_reward(logit, self.form)

    def _transition_reward(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase) -> torch.Tensor:
        missing = [key for key in self.discriminator.in_keys if key not in tensordict.keys(True, True)]
        if missing:
            raise KeyError(f"DiscriminatorReward: the transitions lack the discriminator inputs {missing}.")
        reward = self._reward(tensordict)
        if self.absorbing_gamma is None:
            return reward
        into = tensordict.get(("next", self.absorbing_key), None)
        if into is None:
            raise KeyError(f"DiscriminatorReward: absorbing_gamma is set but the transitions lack "
                           f"('next', {self.absorbing_key!r}) (append AbsorbingStates first).")
        into = into.reshape(reward.shape).bool()
        if not into.any():
            return reward
        loops = absorbing_self_loops(tensordict, absorbing_key=self.absorbing_key,
                                     keys=tuple(k for k in self.discriminator.in_keys if k != self.absorbing_key))
        reward = reward.clone()
        reward[into] += absorbing_value(self._reward(loops).reshape(-1), self.absorbing_gamma)
        return reward
