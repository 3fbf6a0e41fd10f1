"""The expert driver as a TorchRL policy of one environment (the benchmark's expert row).

:class:`ExpertDriverPolicy` lets :func:`~torchrl_csirl.trainers.evaluate_policy` (and any
``env.rollout``) drive a scenario's TorchRL environment with the privileged
:class:`~torchrl_csirl.tasks.driving.expert_driver.ExpertDriver`, so the expert is scored on exactly the test
episodes (same seeds, same metric) as the learned policies. On a robotics task it drives the
task's expert (:func:`~torchrl_csirl.tasks.experts.make_expert`: the DAPG hand, the waypoint-driven ant).
"""
from __future__ import annotations

from typing import Any

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torchrl.envs import EnvBase

from torchrl_csirl.tasks.driving.expert_driver import ExpertDriver
from torchrl_csirl.tasks.experts import make_expert

__all__ = ["ExpertDriverPolicy"]


class ExpertDriverPolicy(TensorDictModuleBase):
    """Writes the expert driver's action for the current state of ``env`` into ``"action"``.

    The driver reads the simulator, not the observation: the policy belongs to one environment
    (a :func:`~torchrl_csirl.tasks.make_env` environment, batch size ``[]``). A new episode (a new
    ego vehicle after a reset) re-plans the driver's route.

    A robotics task's expert is memoryless and reads the task environment itself (its
    ``observation()``, the ant's ``position()``), so it gets the unwrapped environment.

    Args:
        env: the TorchRL environment the policy drives.
        scenario: the scenario or robotics task name (its expert configuration).
        driver: a driver to use instead of ``make_expert(scenario)``.

    Examples:
        >>> from torchrl_csirl.tasks import make_env
        >>> env = make_env("merge", seed=0)
        >>> rollout = env.rollout(5, ExpertDriverPolicy(env, "merge"))
        >>> rollout["action"].shape, bool(rollout["action"].abs().max() <= 1)
        (torch.Size([5, 2]), True)
    """

    def __init__(self, env: EnvBase, scenario: str, driver: ExpertDriver | None = None) -> None:
        super().__init__()
        if tuple(env.batch_size) != ():
            raise ValueError(f"ExpertDriverPolicy drives one environment (batch size []), got {tuple(env.batch_size)}.")
        gym_env = getattr(env, "_env", None)
        if gym_env is None or not hasattr(gym_env, "unwrapped"):
            raise TypeError(f"ExpertDriverPolicy needs the GymEnv of a driving scenario or a robotics task, got {type(env).__name__}.")
        self.in_keys = ["observation"]
        self.out_keys = ["action"]
        driving = hasattr(gym_env.unwrapped, "road")
        # not a module attribute: the simulator is not state
        self.__dict__["_gym_env"] = gym_env if driving else gym_env.unwrapped
        self.driver = driver or make_expert(scenario)
        self._action_spec = env.full_action_spec[env.action_key]
        self._vehicle: Any = None

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        gym_env = self.__dict__["_gym_env"]
        vehicle = getattr(gym_env.unwrapped, "vehicle", None)  # a robotics task: None, its expert is memoryless
        if vehicle is not self._vehicle:  # a reset made a new ego vehicle: plan its route
            self.driver.reset(gym_env)
            self._vehicle = vehicle
        action = torch.as_tensor(self.driver.act(gym_env), dtype=self._action_spec.dtype)
        tensordict.set("action", action.to(self._action_spec.device))
        return tensordict
