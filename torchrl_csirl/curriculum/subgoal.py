"""Curricular subgoal selection from the critic ensemble's uncertainty (CSIRL, Sec. IV-A).

Once per round, for every state ``s^e_i`` of the curriculum trajectory:

* :func:`critic_uncertainty`: ``U_i = mu(Q_1(s_i, a_i), ..., Q_N(s_i, a_i))`` with
  ``a_i ~ pi(s_i)`` and ``mu`` the (population) variance across critics (paper) or
  ``|variance / mean|`` (``"abs_cv"``, published code);
* :func:`scan_subgoal`: starting from ``U^avg = U_g``, for ``p = g+1 .. L-1`` the first ``p`` with
  ``U_p / U^avg_{p-1} > delta`` becomes the new subgoal; otherwise
  ``U^avg_p = sigma * U^avg_{p-1} + (1 - sigma) * U_p`` and the scan goes on (the ratio is tested
  against the average *before* ``U_p`` enters it, as in the paper's Algorithm 1). No detection:
  the subgoal stays. Subgoals never move backward.
"""
from __future__ import annotations

import dataclasses
from typing import Any, Protocol

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torchrl.envs.utils import ExplorationType, set_exploration_type

from torchrl_csirl._validation import expert_observation_tensor, validate_subgoal
from torchrl_csirl.hyperparameters import CSIRL_DEFAULTS, DISPERSIONS
from torchrl_csirl.objectives.ensemble_sac import qvalue_dispersion

#: The paper's decision uncertainty ``U`` (Eq. 6): the ensemble's dispersion, one implementation.
critic_uncertainty = qvalue_dispersion

__all__ = [
    "SubgoalCurriculum",
    "SubgoalSelection",
    "critic_uncertainty",
    "scan_subgoal",
]



class _HasQValues(Protocol):
    def qvalues(self, tensordict: TensorDictBase) -> torch.Tensor: ...


def scan_subgoal(
    uncertainty: torch.Tensor, subgoal: int, delta: float = CSIRL_DEFAULTS.delta, sigma: float = CSIRL_DEFAULTS.sigma
) -> tuple[int, torch.Tensor]:
    """The soft-average scan selecting the next subgoal.

    ``U^avg = U_g``; for ``p = g+1 .. L-1``: if ``U_p / U^avg > delta`` return ``p``, else
    ``U^avg <- sigma * U^avg + (1 - sigma) * U_p``. A zero average gives ratio ``+inf`` for a
    positive ``U_p`` (and ``0`` for ``U_p = 0``).

    Args:
        uncertainty (torch.Tensor): ``[L]`` profile ``U_0 .. U_{L-1}``.
        subgoal (int): the current subgoal ``g``.
        delta (float): ratio threshold. Defaults to ``5.0``.
        sigma (float): soft-average coefficient in ``[0, 1]``. Defaults to ``0.2``.

    Returns:
        (int, torch.Tensor): the new subgoal (``g`` when nothing passes) and the ``[L]`` ratios
        ``U_p / U^avg_{p-1}`` of the scanned positions (NaN elsewhere).

    Examples:
        >>> import torch
        >>> u = torch.tensor([1.0, 1.0, 1.2, 0.8, 9.0, 50.0])
        >>> g, ratios = scan_subgoal(u, subgoal=1)
        >>> g, [round(r, 3) for r in ratios[2:5].tolist()]
        (4, [1.2, 0.69, 10.321])
    """
    u = uncertainty.detach().to("cpu", torch.float64).reshape(-1)
    length = u.numel()
    if not 0 <= subgoal < length:
        raise ValueError(f"subgoal must be in [0, {length - 1}], got {subgoal}.")
    if not 0.0 <= sigma <= 1.0:
        raise ValueError(f"sigma must be in [0, 1], got {sigma}.")
    if delta <= 0:
        raise ValueError(f"delta must be positive, got {delta}.")
    ratios = torch.full((length,), float("nan"), dtype=torch.float64)
    average = float(u[subgoal])
    for p in range(subgoal + 1, length):
        value = float(u[p])
        if average > 0:
            ratio = value / average
        else:
            ratio = float("inf") if value > 0 else 0.0
        ratios[p] = ratio
        if ratio > delta:
            return p, ratios
        average = sigma * average + (1.0 - sigma) * value
    return subgoal, ratios


@dataclasses.dataclass(frozen=True)
class SubgoalSelection:
    """Result of one curriculum step.

    Attributes:
        subgoal (int): the selected subgoal (``>= previous``).
        previous (int): the subgoal before the step.
        profile (torch.Tensor): ``[L]`` uncertainty ``U_i`` along the curriculum trajectory.
        ratios (torch.Tensor): ``[L]`` scanned ratios ``U_p / U^avg_{p-1}`` (NaN where not scanned).
        changed (bool): whether the subgoal moved.
    """

    subgoal: int
    previous: int
    profile: torch.Tensor
    ratios: torch.Tensor
    changed: bool


class SubgoalCurriculum:
    """Selects CSIRL's curricular subgoals along an expert (curriculum) trajectory.

    Args:
        expert_observations: the curriculum trajectory ``[L, D]`` (a tensor, a trajectory
            TensorDict or :class:`~torchrl_csirl.data.ExpertDemonstrations`, first trajectory).
        loss: any object with ``qvalues(td) -> Tensor[N, L]`` reading ``"observation"`` and
            ``"action"``, e.g. :class:`~torchrl_csirl.objectives.EnsembleSACLoss`.
        policy (TensorDictModuleBase): writes ``"action"`` from ``"observation"``.

    Keyword Args:
        delta (float): uncertainty ratio threshold. Defaults to ``5.0``.
        sigma (float): soft-average coefficient. Defaults to ``0.2``.
        dispersion (str): ``"variance"`` (default) or ``"abs_cv"``.
        initial_subgoal (int, optional): the first subgoal; by default drawn uniformly in
            ``initial_range`` with a generator seeded by ``seed``.
        initial_range (tuple of int): inclusive range for the random first subgoal
            (clipped to ``[0, L-1]``). Defaults to ``(1, 5)``.
        seed (int): seed of the initial draw and of the action sampling (the global RNG is
            untouched: sampling runs under :func:`torch.random.fork_rng`). Defaults to ``0``.
        deterministic_actions (bool): use the policy's mode instead of sampling ``a_i ~ pi``.
            Defaults to ``False``.
        include_final (bool): with a trajectory input, append its last next-observation.

    Examples:
        >>> import torch
        >>> from tensordict.nn import TensorDictModule
        >>> class TwoCritics:
        ...     def qvalues(self, td):
        ...         x = td["observation"][..., 0]
        ...         return torch.stack([x, -x])  # disagreement grows with x**2
        >>> policy = TensorDictModule(lambda obs: obs[..., :1], ["observation"], ["action"])
        >>> expert = torch.tensor([[1.0], [1.0], [1.0], [1.0], [1.0], [1.0], [4.0], [5.0]])
        >>> cur = SubgoalCurriculum(expert, TwoCritics(), policy, initial_subgoal=2)
        >>> sel = cur.step()
        >>> sel.previous, sel.subgoal, sel.changed
        (2, 6, True)
    """

    def __init__(
        self,
        expert_observations: Any,
        loss: _HasQValues,
        policy: TensorDictModuleBase,
        *,
        delta: float = CSIRL_DEFAULTS.delta,
        sigma: float = CSIRL_DEFAULTS.sigma,
        dispersion: str = CSIRL_DEFAULTS.dispersion,
        initial_subgoal: int | None = None,
        initial_range: tuple[int, int] = (1, 5),
        seed: int = 0,
        deterministic_actions: bool = False,
        include_final: bool = False,
    ) -> None:
        expert = expert_observation_tensor(expert_observations, include_final)
        if expert.ndim != 2 or expert.shape[0] < 1:
            raise ValueError(f"expert observations must have shape [L, D], got {tuple(expert.shape)}.")
        if not callable(getattr(loss, "qvalues", None)):
            raise TypeError(f"loss must provide a qvalues(td) method, got {type(loss).__name__}.")
        if dispersion not in DISPERSIONS:
            raise ValueError(f"dispersion must be one of {DISPERSIONS}, got {dispersion!r}.")
        if not 0.0 <= sigma <= 1.0:
            raise ValueError(f"sigma must be in [0, 1], got {sigma}.")
        if delta <= 0:
            raise ValueError(f"delta must be positive, got {delta}.")
        low, high = (int(v) for v in initial_range)
        if low > high:
            raise ValueError(f"initial_range must be (low, high) with low <= high, got {initial_range}.")
        self.expert_observations = expert.detach().float()
        self.loss = loss
        self.policy = policy
        self.delta = float(delta)
        self.sigma = float(sigma)
        self.dispersion = dispersion
        self.seed = int(seed)
        self.deterministic_actions = bool(deterministic_actions)
        self.round = 0
        if initial_subgoal is None:
            generator = torch.Generator().manual_seed(self.seed)
            initial_subgoal = int(torch.randint(low, high + 1, (1,), generator=generator))
            initial_subgoal = min(max(initial_subgoal, 0), self.length - 1)
        self._subgoal = 0
        self.set_subgoal(initial_subgoal)

    @property
    def length(self) -> int:
        """int: the curriculum trajectory length ``L``."""
        return int(self.expert_observations.shape[0])

    @property
    def subgoal(self) -> int:
        """int: the current subgoal."""
        return self._subgoal

    def set_subgoal(self, subgoal: int) -> None:
        """Sets the current subgoal (an int in ``[0, L-1]``)."""
        self._subgoal = validate_subgoal(subgoal, self.length)

    def _policy_device(self) -> torch.device:
        params = getattr(self.policy, "parameters", None)
        if params is not None:
            for p in params():
                return p.device
        return self.expert_observations.device

    @torch.no_grad()
    def uncertainty_profile(self, round_index: int | None = None) -> torch.Tensor:
        """``[L]`` uncertainty ``U_i`` of the curriculum states, actions sampled from the policy.

        Sampling is seeded by ``(seed, round_index)`` (default: the current round) under
        :func:`torch.random.fork_rng`, so the global RNG is left untouched.
        """
        round_index = self.round if round_index is None else int(round_index)
        device = self._policy_device()
        td = TensorDict({"observation": self.expert_observations.to(device)}, [self.length], device=device)
        devices = [device] if device.type == "cuda" else []
        exploration = ExplorationType.DETERMINISTIC if self.deterministic_actions else ExplorationType.RANDOM
        with torch.random.fork_rng(devices=devices):
            torch.manual_seed(self.seed * 1_000_003 + round_index)
            with set_exploration_type(exploration):
                td = self.policy(td)
        qvalues = self.loss.qvalues(td)
        if qvalues.shape[1:] != (self.length,):
            raise ValueError(f"loss.qvalues returned shape {tuple(qvalues.shape)}, expected [N, {self.length}].")
        return critic_uncertainty(qvalues.detach().float(), self.dispersion).cpu()

    def step(self) -> SubgoalSelection:
        """Computes the profile, scans it from the current subgoal and moves the subgoal forward."""
        previous = self._subgoal
        profile = self.uncertainty_profile()
        candidate, ratios = scan_subgoal(profile, previous, self.delta, self.sigma)
        new = max(candidate, previous)
        self._subgoal = new
        self.round += 1
        return SubgoalSelection(
            subgoal=new, previous=previous, profile=profile, ratios=ratios, changed=new != previous
        )

    def state_dict(self) -> dict[str, Any]:
        """The curriculum's state (subgoal, round counter, seed) for checkpoints."""
        return {"subgoal": self._subgoal, "round": self.round, "seed": self.seed}

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        """Restores :meth:`state_dict`."""
        missing = {"subgoal", "round", "seed"} - set(state_dict)
        if missing:
            raise KeyError(f"state_dict lacks {sorted(missing)}.")
        self.set_subgoal(int(state_dict["subgoal"]))
        self.round = int(state_dict["round"])
        self.seed = int(state_dict["seed"])

    def __repr__(self) -> str:
        return (
            f"{type(self).__name__}(length={self.length}, subgoal={self._subgoal}, round={self.round}, "
            f"delta={self.delta}, sigma={self.sigma}, dispersion={self.dispersion!r})"
        )
