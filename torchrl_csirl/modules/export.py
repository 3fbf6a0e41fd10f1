"""Saving a trained actor and loading it back as a ready-to-roll-out TorchRL module."""
from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

import torch
from torchrl.modules import ProbabilisticActor

from torchrl_csirl.modules.actor_critic import make_actor
from torchrl_csirl.modules.features import feature_map_from_config, input_map

__all__ = ["load_policy", "save_policy"]

POLICY_FORMAT = "torchrl-csirl-policy/1"
POLICY_FILE = "policy.pt"


def save_policy(actor: ProbabilisticActor, path: str | os.PathLike, *, obs_dim: int, action_dim: int,
                **metadata: Any) -> str:
    """Writes the actor's weights and what is needed to rebuild it (``metadata``: e.g. the scenario).

    An input map inside the actor (:class:`~torchrl_csirl.modules.EgoRelativeFeatures`,
    :class:`~torchrl_csirl.modules.LaneFeatures`, :class:`~torchrl_csirl.modules.DropFeatures` or a chain) is saved with it (its
    constructor arguments) and rebuilt by :func:`load_policy`.

    Examples:
        >>> import tempfile, os
        >>> from torchrl_csirl.modules import make_actor
        >>> path = save_policy(make_actor(25, 2), os.path.join(tempfile.mkdtemp(), "policy.pt"),
        ...                    obs_dim=25, action_dim=2, scenario="merge")
        >>> load_policy(path).metadata["scenario"]
        'merge'
    """
    path = os.fspath(path)
    payload = {
        "format": POLICY_FORMAT,
        "obs_dim": int(obs_dim),
        "action_dim": int(action_dim),
        "metadata": dict(metadata),
        "input_features": _input_features_config(actor),
        "state_dict": {k: v.detach().cpu() for k, v in actor.state_dict().items()},
    }
    tmp = path + ".tmp"
    torch.save(payload, tmp)
    os.replace(tmp, path)
    return path


def _input_features_config(actor: ProbabilisticActor) -> dict[str, Any] | None:
    found = input_map(actor)
    return None if found is None else found.config()


def load_policy(path: str | os.PathLike,
                lane_centres: Callable[[str], Any] | None = None) -> ProbabilisticActor:
    """Loads a policy saved by :func:`save_policy` (a file, or a run directory holding ``policy.pt``).

    The returned :class:`~torchrl.modules.ProbabilisticActor` acts deterministically (the mode)
    unless an exploration type says otherwise; its ``metadata`` attribute holds what was saved
    with it and its dimensions (``obs_dim``, ``action_dim``). Two lines roll it out::

        policy = load_policy("runs/merge-csirl-s0-...")
        rollout = make_env(policy.metadata["scenario"]).rollout(60, policy)

    ``lane_centres(scenario)`` supplies the road's lane points to a policy whose
    :class:`~torchrl_csirl.modules.LaneFeatures` were saved by scenario name only (saved before the
    points were stored with them): pass :func:`torchrl_csirl.tasks.sample_lane_centres`.

    Raises:
        FileNotFoundError: no policy file at ``path``.
        ValueError: the file is not a saved policy.
    """
    path = os.fspath(path)
    if os.path.isdir(path):
        path = os.path.join(path, POLICY_FILE)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"No policy file at {path!r}.")
    payload = torch.load(path, map_location="cpu", weights_only=True)
    if not isinstance(payload, dict) or payload.get("format") != POLICY_FORMAT:
        raise ValueError(f"{path!r} is not a torchrl-csirl policy file (format {POLICY_FORMAT}).")
    features = payload.get("input_features")
    actor = make_actor(payload["obs_dim"], payload["action_dim"],
                       input_features=feature_map_from_config(features, lane_centres) if features else None)
    actor.load_state_dict(payload["state_dict"])
    actor.metadata = {"obs_dim": int(payload["obs_dim"]), "action_dim": int(payload["action_dim"]),
                      **payload["metadata"]}
    return actor
