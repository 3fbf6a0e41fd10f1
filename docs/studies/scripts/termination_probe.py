"""Does a trained baseline prefer ending the episode? Its critic on terminating vs continuing transitions.

``python docs/studies/scripts/termination_probe.py <run dir> [key=value ...] [--samples 4096] [--seed 0]``

Reads a run of ``recipes/imitation_highway.py`` or ``recipes/imitation_robotics.py`` (a robotics
or locomotion task: its last checkpoint, with the replay buffer)
and samples its replay (the learner's own transitions) and its demonstrations. For each it
reports the fraction of transitions that end the episode (``terminated``) and the critics'
value ``Q(s, a)`` (the minimum over the ensemble, as SAC's actor reads it) on the terminating
and on the continuing ones: a learner whose ``Q`` is higher where the episode ends has been
taught that ending it pays, whatever the expert did. Per method, the reward it learns:

* ``dac``: the discriminator reward of a step and ``r_a``, the learned reward of the absorbing
  state(s) entered (a termination pays ``gamma r_a / (1 - gamma)`` on top: with ``r_a`` above
  the per-step reward, ending the episode beats going on);
* ``iqlearn``: the implicit reward ``r = Q(s, a) - gamma V(s')`` (``V(s') = 0`` at a termination);
* ``valuedice`` (no critic: in place of ``Q``): the Bellman residual ``nu - B^pi nu``, the
  log-ratio of the expert's to the policy's occupancy that its policy is trained on, on
  terminating / continuing transitions and on the absorbing self-loops.

``key=value`` overrides the run's configuration as ``checkpoint.resume`` would (e.g.
``dac.absorbing_observation=placeholder`` for a run saved before that key existed). Methods: ``sac``,
``sqil``, ``gail``, ``dac``, ``iqlearn`` (a soft-Q critic) and ``valuedice``. The run itself is
not touched (its configuration and checkpoint are read in a temporary copy). The last line is
JSON; it is also written to ``<run dir>/termination_probe.json``. docs/baselines.md, "Ending the
episode", reads it for DAC, IQ-Learn and ValueDICE on merge.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import tempfile

import torch
from tensordict import TensorDictBase

from torchrl_csirl.methods.baselines import IMITATION_RECIPE, make_trainer
from torchrl_csirl.run.builders import resume_run
from torchrl_csirl.run.config import ConfigError
from torchrl_csirl.run.run import run_script
from torchrl_csirl.transforms import absorbing_self_loops

PROBED_METHODS = ("sac", "sqil", "gail", "dac", "iqlearn", "valuedice")


def _mean(values: torch.Tensor, mask: torch.Tensor | None = None) -> float | None:
    values = values if mask is None else values[mask]
    return round(values.mean().item(), 4) if values.numel() else None


def _ends(transitions: TensorDictBase) -> torch.Tensor:
    """``[B]`` bool: the transitions that end the episode."""
    return transitions.get(("next", "terminated")).reshape(-1).bool()


def _split(name: str, values: torch.Tensor, ends: torch.Tensor) -> dict[str, float | None]:
    """``{name}_terminating`` and ``{name}_continuing``: the means of ``values`` on both kinds of transition."""
    return {f"{name}_terminating": _mean(values, ends), f"{name}_continuing": _mean(values, ~ends)}


def critic_on_endings(loss, transitions: TensorDictBase) -> dict[str, float | None]:
    """Fraction of terminating transitions and the critics' min ``Q`` on terminating / continuing ones."""
    ends = _ends(transitions)
    q = loss.qvalues(transitions).min(0).values.reshape(-1)
    return {"terminal_fraction": _mean(ends.float()), **_split("q", q, ends)}


def dac_rewards(discriminator, transitions: TensorDictBase) -> dict[str, float | None]:
    """DAC's per-step reward (the discriminator logit) and ``r_a`` of the absorbing states entered."""
    keys = discriminator.in_keys
    per_step = discriminator(transitions.select(*keys).clone()).get("discriminator_logit").reshape(-1)
    loops = absorbing_self_loops(transitions)
    r_a = discriminator(loops.select(*keys).clone()).get("discriminator_logit").reshape(-1)
    return {"step_reward": _mean(per_step), "absorbing_reward": _mean(r_a)}


def iqlearn_rewards(loss, transitions: TensorDictBase) -> dict[str, float | None]:
    """IQ-Learn's implicit reward on terminating / continuing transitions (mean over the critics)."""
    reward = loss._implicit_reward(transitions)[0].mean(0).reshape(-1)
    return _split("implicit_reward", reward, _ends(transitions))


def valuedice_residuals(loss, transitions: TensorDictBase) -> dict[str, float | None]:
    """ValueDICE's ``nu - B^pi nu`` on terminating / continuing transitions and on the self-loops."""
    ends = _ends(transitions)
    residual = loss._residual(transitions)[0]
    real, loops = residual[:len(ends)], residual[len(ends):]
    return {"terminal_fraction": _mean(ends.float()), **_split("residual", real, ends),
            "absorbing_residual": _mean(loops)}


def probe(run, samples: int) -> dict[str, object]:
    """The probe's figures for the replay (``"agent"``) and the demonstrations (``"expert"``)."""
    method = run.parts.method
    loss = method.states["loss"]
    out: dict[str, object] = {"method": method.name, "scenario": run.spec.name}
    with torch.no_grad():
        for side, buffer in (("agent", run.online_buffer), ("expert", run.parts.expert_buffer)):
            if len(buffer) == 0:
                raise ConfigError(f"termination_probe: the run's {side} buffer is empty "
                                  f"(was it saved? checkpoint.save_buffer)")
            transitions = buffer.sample(samples)
            if method.name == "valuedice":
                out[side] = valuedice_residuals(loss, transitions)
                continue
            figures = critic_on_endings(loss, transitions)
            if method.name == "dac" and "discriminator" in method.states:
                figures.update(dac_rewards(method.states["discriminator"], transitions))
            if method.name == "iqlearn":
                figures.update(iqlearn_rewards(loss, transitions))
            out[side] = figures
    return out


def open_copy(run_dir: str, workdir: str, overrides: list[str] = ()):
    """The run rebuilt from a copy of its configuration and last checkpoint under ``workdir``."""
    checkpoint = os.path.join(run_dir, "checkpoints", "last")
    if not os.path.isfile(os.path.join(checkpoint, "state.pt")):
        raise ConfigError(f"termination_probe: {run_dir} has no checkpoint (looked for {checkpoint}/state.pt)")
    copy = os.path.join(workdir, "run")
    os.makedirs(copy)
    shutil.copy(os.path.join(run_dir, "config.yaml"), copy)
    shutil.copytree(checkpoint, os.path.join(copy, "checkpoints", "last"))
    cfg = IMITATION_RECIPE.load_run_config(copy, [f"checkpoint.resume={copy}", "logger.backend=csv", *overrides])
    if cfg.method not in PROBED_METHODS:
        raise ConfigError(f"termination_probe: method {cfg.method!r} has no critic to probe; "
                          f"probed methods: {', '.join(PROBED_METHODS)}")
    return resume_run(cfg, copy, os.path.join(copy, "checkpoints", "last"), make_trainer)


def main(argv: list[str] | None = None) -> dict[str, object]:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run_dir", help="a run directory of recipes/imitation_highway.py or imitation_robotics.py")
    parser.add_argument("overrides", nargs="*", help="key=value overrides of the run's configuration")
    parser.add_argument("--samples", type=int, default=4096, help="transitions sampled from each buffer")
    parser.add_argument("--seed", type=int, default=0, help="seed of the sampling")
    args = parser.parse_args(argv)
    if args.samples <= 0:
        raise ConfigError(f"--samples must be positive, got {args.samples}")
    with tempfile.TemporaryDirectory() as workdir:
        run = open_copy(os.path.abspath(args.run_dir), workdir, args.overrides)
        try:
            torch.manual_seed(args.seed)  # the samples, whatever the rebuild drew
            out = probe(run, args.samples)
        finally:
            run.close()
    out["run_dir"] = os.path.abspath(args.run_dir)
    with open(os.path.join(args.run_dir, "termination_probe.json"), "w") as f:
        json.dump(out, f, indent=1)
    print(json.dumps(out))
    return out


if __name__ == "__main__":
    run_script(main)
