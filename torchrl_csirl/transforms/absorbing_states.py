"""DAC's absorbing states: terminal transitions lead to an absorbing state that loops on itself."""
from __future__ import annotations

import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey
from torchrl.envs.transforms import Transform

__all__ = ["AbsorbingStates", "absorbing_value", "absorbing_self_loops"]


def absorbing_value(absorbing_reward: torch.Tensor, gamma: float) -> torch.Tensor:
    """The discounted value ``sum_{k >= 1} gamma^k r_a = gamma r_a / (1 - gamma)`` collected after
    entering the absorbing state, whose self-loop pays ``r_a`` forever.

    Examples:
        >>> import torch
        >>> absorbing_value(torch.tensor(1.0), 0.75)
        tensor(3.)
    """
    if not 0.0 <= gamma < 1.0:
        raise ValueError(f"gamma must be in [0, 1), got {gamma}.")
    return absorbing_reward * (gamma / (1.0 - gamma))


class AbsorbingStates(Transform):
    """Turns terminal transitions into transitions to an absorbing state, with an indicator feature.

    Kostrikov et al. (2019, "Discriminator-Actor-Critic") show that ending the return at
    a terminal state biases adversarial imitation (a positive reward favours long episodes, a
    negative one early termination) and fix it by letting episodes enter an absorbing state
    ``s_a`` that loops on itself with a *learned* reward ``r_a``. On a batch of transitions this
    transform writes the indicator features: ``"absorbing"`` (``False``, the state ``s`` is real)
    and ``("next", "absorbing")`` (``True`` where the transition is terminal), and sets the
    successor observation of terminal transitions to the observation of the absorbing state
    entered:

    * ``absorbing_observation=0.0`` (a number, or an observation-sized tensor): the paper's single
      absorbing state, the same placeholder observation after every termination (a tensor: e.g. the
      raw observation a standardisation maps to zero, ValueDICE's code's placeholder);
    * ``absorbing_observation=None``: one absorbing state per terminal state, observed as the
      terminal observation itself (the successor observation is left as recorded). Use it where
      demonstrations end in a terminal *success* (a goal reached) and the learner can also
      terminate by failing (a crash): with a single absorbing state both endings share one
      learned reward, and the failure inherits the reward of the expert's success
      (docs/baselines.md, "DAC's absorbing states").

    The batch keeps its size (TorchRL's replay buffers need that): the absorbing state's self-loop
    transitions, one per terminal transition as in the paper's replay buffer (or more: ``copies``), are built where
    they are used (:func:`absorbing_self_loops`, by
    :class:`~torchrl_csirl.objectives.DACDiscriminatorLoss`), and since their value is the
    constant ``gamma r_a / (1 - gamma)`` (:func:`absorbing_value`), the critic target of a
    terminal transition adds it in closed form
    (:class:`~torchrl_csirl.transforms.DiscriminatorReward` with ``absorbing_gamma``) instead of
    bootstrapping through a critic evaluated at the absorbing state; ``terminated`` therefore
    stays set. Apply it to the expert and the online replay buffers alike (sampling time).
    Truncated (time-limit) transitions are not terminal and are left alone.

    Keyword Args:
        absorbing_key (NestedKey): the indicator entry. Defaults to ``"absorbing"``.
        observation_key (NestedKey): Defaults to ``"observation"``.
        absorbing_observation (float or tensor, optional): the placeholder observation of the single
            ``s_a`` (a number for every entry, or a vector of the observation's size), or ``None`` for one
            absorbing state per terminal observation. Defaults to ``0.0``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> term = torch.tensor([[False], [True]])
        >>> td = TensorDict({"observation": torch.ones(2, 2), "action": torch.ones(2, 1),
        ...                  "next": {"observation": torch.ones(2, 2), "terminated": term}}, [2])
        >>> out = AbsorbingStates()(td.clone())
        >>> out["absorbing"].squeeze(-1).tolist(), out["next", "absorbing"].squeeze(-1).tolist()
        ([False, False], [False, True])
        >>> out["next", "observation"][1].tolist()
        [0.0, 0.0]
        >>> AbsorbingStates(absorbing_observation=None)(td.clone())["next", "observation"][1].tolist()
        [1.0, 1.0]
    """

    def __init__(self, *, absorbing_key: NestedKey = "absorbing", observation_key: NestedKey = "observation",
                 absorbing_observation: float | torch.Tensor | None = 0.0) -> None:
        super().__init__(in_keys=[observation_key], out_keys=[absorbing_key])
        self.absorbing_key = absorbing_key
        self.observation_key = observation_key
        if isinstance(absorbing_observation, torch.Tensor):
            if absorbing_observation.ndim != 1 or not bool(torch.isfinite(absorbing_observation).all()):
                raise ValueError("absorbing_observation: a tensor placeholder must be a finite observation-sized "
                                 f"vector, got shape {tuple(absorbing_observation.shape)}.")
            absorbing_observation = absorbing_observation.detach().clone()
        elif absorbing_observation is not None:
            absorbing_observation = float(absorbing_observation)
        self.absorbing_observation = absorbing_observation

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        missing = [key for key in (self.observation_key, ("next", self.observation_key), ("next", "terminated"))
                   if key not in tensordict.keys(True, True)]
        if missing:
            raise KeyError(f"AbsorbingStates: the transitions lack the keys {missing}.")
        terminated = tensordict.get(("next", "terminated")).bool()
        tensordict.set(self.absorbing_key, torch.zeros_like(terminated))
        tensordict.set(("next", self.absorbing_key), terminated)
        if self.absorbing_observation is None:  # one absorbing state per terminal observation
            return tensordict
        next_obs = tensordict.get(("next", self.observation_key))
        placeholder = self._placeholder_like(next_obs)
        tensordict.set(("next", self.observation_key), torch.where(terminated, placeholder, next_obs))
        return tensordict

    def _placeholder_like(self, next_obs: torch.Tensor) -> torch.Tensor:
        if not isinstance(self.absorbing_observation, torch.Tensor):
            return torch.full_like(next_obs, self.absorbing_observation)
        if self.absorbing_observation.shape[-1] != next_obs.shape[-1]:
            raise ValueError(f"AbsorbingStates: the placeholder has {self.absorbing_observation.shape[-1]} entries, "
                             f"the observations {next_obs.shape[-1]}.")
        return self.absorbing_observation.to(next_obs).expand_as(next_obs)

    def _call(self, next_tensordict: TensorDictBase) -> TensorDictBase:  # pragma: no cover
        raise RuntimeError("AbsorbingStates works on whole transitions: use it as a replay-buffer transform.")


def check_self_loop_count(count: int, name: str = "copies") -> None:
    """Refuses a self-loop count that is not an integer >= 1, naming the setting ``name``.

    Examples:
        >>> check_self_loop_count(10)
        >>> check_self_loop_count(0, "self_loops_per_termination")
        Traceback (most recent call last):
        ...
        ValueError: self_loops_per_termination must be an integer >= 1, got 0.
    """
    if isinstance(count, bool) or not isinstance(count, int) or count < 1:
        raise ValueError(f"{name} must be an integer >= 1, got {count!r}.")


def absorbing_self_loops(transitions: TensorDictBase, *, absorbing_key: NestedKey = "absorbing",
                         keys: tuple[NestedKey, ...] = ("observation", "action"), copies: int = 1) -> TensorDictBase:
    """``copies`` self-loop samples ``(s_a, 0)`` with indicator ``True`` per transition entering ``s_a``.

    Reads ``("next", absorbing_key)`` and the absorbing state's observation, the successor
    observation ``("next", keys[0])``, both as written by :class:`AbsorbingStates` (the
    placeholder, or the terminal observation); returns the entries ``keys`` (that observation,
    zero for the others, the action) and ``absorbing_key``. ``copies`` sets the absorbing state's
    weight in a batch: one per termination is the DAC paper's replay buffer, whose text adds the
    transition ``(s_a, ., s_a)`` to each terminated episode; the authors' later code (ValueDICE's,
    which also runs DAC) stores up to ten per termination (``absorbing_per_episode``). The copies
    are the same sample (the absorbing state's action is zero here), so they reweight it.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> td = TensorDict({"observation": torch.ones(3, 2), "action": torch.ones(3, 1),
        ...                  "next": {"observation": torch.zeros(3, 2),
        ...                           "absorbing": torch.tensor([[True], [False], [True]])}}, [3])
        >>> loops = absorbing_self_loops(td)
        >>> loops.batch_size, loops["absorbing"].all().item(), loops["observation"].abs().sum().item()
        (torch.Size([2]), True, 0.0)
        >>> absorbing_self_loops(td, copies=10).batch_size
        torch.Size([20])
    """
    check_self_loop_count(copies)
    into = transitions.get(("next", absorbing_key)).reshape(transitions.batch_size).bool()
    entering = transitions.select(*keys, ("next", keys[0]))[into]
    loops = entering.select(*keys)
    loops.set(keys[0], entering.get(("next", keys[0])))
    for key in keys[1:]:
        loops.set(key, torch.zeros_like(loops.get(key)))
    loops.set(absorbing_key, torch.ones(*loops.batch_size, 1, dtype=torch.bool, device=loops.device))
    return loops if copies == 1 else torch.cat([loops] * copies, 0)
