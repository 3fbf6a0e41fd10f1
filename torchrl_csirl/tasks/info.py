"""The info entries a CSIRL task writes into its TensorDicts: their keys, their specs and the reader.

Every environment builder reads them (:func:`~torchrl_csirl.tasks.make_env`, the gymnasium tasks'
:func:`~torchrl_csirl.tasks.make_gymnasium_env`): this module depends on no task and no registry.
"""
from __future__ import annotations

import torch
from torchrl.data import Bounded, Categorical, Composite, Unbounded
from torchrl.envs.gym_like import default_info_dict_reader

__all__ = ["FAILURE_KEYS", "INFO_KEYS", "ScenarioInfoReader", "info_spec"]

#: info entries read into the TensorDict (root at reset, under "next" after a step)
INFO_KEYS: tuple[str, ...] = (
    "distance_to_finish",
    "progress",
    "crashed",
    "offroad",
    "arrived",
    "success",
)

#: the info entries that mark a failed termination (a crash, leaving the road)
FAILURE_KEYS: tuple[str, ...] = ("crashed", "offroad")


class ScenarioInfoReader(default_info_dict_reader):
    """Info reader writing the scenario entries with the dtypes of their specs.

    TorchRL's default reader expects numpy values; the scenarios report Python floats/bools.
    """

    def __call__(self, info_dict: dict, tensordict):
        spec = self.info_spec
        for key in self.keys:
            if key in info_dict:
                value = torch.as_tensor(info_dict[key], dtype=spec[key].dtype)
            else:
                value = spec[key].zero()
            tensordict.set(key, value.to(tensordict.device) if tensordict.device else value)
        return tensordict


def info_spec(keys=INFO_KEYS) -> Composite:
    """Specs of the scenario info entries (float32 distance/progress, bool flags).

    Examples:
        >>> info_spec()["distance_to_finish"].dtype
        torch.float32
    """
    specs = {
        "distance_to_finish": Unbounded((), dtype=torch.float32),
        "progress": Bounded(0.0, 1.0, (), dtype=torch.float32),
    }
    for flag in ("crashed", "offroad", "arrived", "success"):
        specs[flag] = Categorical(2, (), dtype=torch.bool)
    unknown = set(keys) - set(specs)
    if unknown:
        raise ValueError(f"Unknown info keys {sorted(unknown)}; expected a subset of {INFO_KEYS}.")
    return Composite({k: specs[k] for k in keys}, shape=())
