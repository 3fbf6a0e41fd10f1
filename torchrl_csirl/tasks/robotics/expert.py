"""The Relocate expert: the DAPG policy (Rajeswaran et al., RSS 2018), shipped with the package.

The weights (``torchrl_csirl/data/experts/relocate/relocate_dapg_policy.npz``, Apache-2.0, see
``LICENSE-DAPG`` and ``README.md`` beside them) are the authors' ``relocate-v0`` policy, the one
that generated D4RL's ``relocate-expert`` data. The policy is an MLP (39 -> 32 -> 32 -> 30, tanh)
on a normalised observation; the expert acts with its mean action, clipped to ``[-1, 1]``::

    x = (o - in_shift) / (in_scale + 1e-8)
    a = clip((w2 @ tanh(w1 @ tanh(w0 @ x + b0) + b1) + b2) * out_scale + out_shift, -1, 1)
"""
from __future__ import annotations

import os
from typing import Any

import numpy as np
import torch
from tensordict.nn import TensorDictModule
from torch import nn

from torchrl_csirl._paths import EXPERTS_DIR

__all__ = ["DAPG_POLICY_PATH", "DAPGRelocateExpert", "DAPGRelocatePolicy", "make_relocate_expert"]

DAPG_POLICY_PATH = os.path.join(EXPERTS_DIR, "relocate", "relocate_dapg_policy.npz")
"""The shipped DAPG weights (float64 arrays ``w0, b0, w1, b1, w2, b2``, ``in_shift``, ``in_scale``,
``out_shift``, ``out_scale``, ``log_std``)."""

_LAYERS = (("w0", "b0"), ("w1", "b1"), ("w2", "b2"))


class DAPGRelocatePolicy(nn.Module):
    """The DAPG Relocate policy's mean action, clipped to ``[-1, 1]`` (float64 inside).

    Args:
        path: the ``.npz`` weights (default: the shipped ones).

    Examples:
        >>> policy = DAPGRelocatePolicy()
        >>> policy(torch.zeros(2, 39)).shape
        torch.Size([2, 30])
    """

    def __init__(self, path: str | os.PathLike = DAPG_POLICY_PATH) -> None:
        super().__init__()
        with np.load(path, allow_pickle=False) as arrays:
            weights = {k: torch.as_tensor(arrays[k], dtype=torch.float64) for k in arrays.files}
        expected = {"w0": (32, 39), "w1": (32, 32), "w2": (30, 32), "in_shift": (39,), "out_shift": (30,)}
        for key, shape in expected.items():
            if key not in weights or tuple(weights[key].shape) != shape:
                raise ValueError(f"{path}: DAPG weights need {key!r} of shape {shape}.")
        for key, value in weights.items():
            self.register_buffer(key, value)

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        x = (observation.to(torch.float64) - self.in_shift) / (self.in_scale + 1e-8)
        for i, (w, b) in enumerate(_LAYERS):
            x = x @ getattr(self, w).T + getattr(self, b)
            if i < len(_LAYERS) - 1:
                x = torch.tanh(x)
        action = x * self.out_scale + self.out_shift
        return action.clamp(-1.0, 1.0).to(observation.dtype)

    def as_tensordict_module(self) -> TensorDictModule:
        """The policy reading ``"observation"`` and writing ``"action"`` (for ``env.rollout``).

        Examples:
            >>> from torchrl_csirl.tasks import make_env
            >>> env = make_env("relocate", seed=0)
            >>> env.rollout(3, DAPGRelocatePolicy().as_tensordict_module())["action"].shape
            torch.Size([3, 30])
        """
        return TensorDictModule(self, in_keys=["observation"], out_keys=["action"])


class DAPGRelocateExpert:
    """The DAPG policy as an expert with the driving expert's interface (``reset(env)``, ``act(env)``).

    ``act`` reads the environment's current flat observation
    (:meth:`~torchrl_csirl.tasks.robotics.RelocateEnv.observation`).

    Examples:
        >>> from torchrl_csirl.tasks import make_gym_env
        >>> env = make_gym_env("relocate")
        >>> _ = env.reset(seed=0)
        >>> expert = DAPGRelocateExpert()
        >>> expert.reset(env)
        >>> expert.act(env).shape
        (30,)
    """

    def __init__(self, path: str | os.PathLike = DAPG_POLICY_PATH) -> None:
        self.policy = DAPGRelocatePolicy(path)

    def reset(self, env: Any) -> None:
        """Nothing to reset: the policy is memoryless."""

    @torch.no_grad()
    def act(self, env: Any) -> np.ndarray:
        obs = torch.as_tensor(np.asarray(env.observation(), dtype=np.float64))
        return self.policy(obs).numpy().astype(np.float32)


def make_relocate_expert(name: str = "relocate") -> DAPGRelocateExpert:
    """The expert of ``"relocate"`` (its :attr:`~torchrl_csirl.tasks.TaskSpec.expert`): the shipped DAPG policy.

    Examples:
        >>> type(make_relocate_expert()).__name__
        'DAPGRelocateExpert'
    """
    return DAPGRelocateExpert()
