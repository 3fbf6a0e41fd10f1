"""Each of CSIRL's hyperparameters has one default.

The defaults are collected from CSIRL's configuration sections (``csirl``: :class:`CSIRLConfig`,
``optim``: :class:`OptimConfig`, which are the dataclasses of :mod:`torchrl_csirl.hyperparameters`)
and from the keyword defaults (:func:`inspect.signature`) of every public class (its constructor and
public methods) and function of the modules that build CSIRL's learner (:data:`MODULES`). A name
given two different defaults fails the test, naming each default and where it is declared.

Names are compared under the configuration's spelling: :data:`ALIASES` maps a keyword spelled
otherwise to it (``alpha_init`` is ``alpha``, :class:`MetaRewardLoss`'s ``scale`` is ``meta_scale``).
A difference meant to stay goes in :data:`INTENTIONAL` with its reason; it is empty. A keyword that
shares a hyperparameter's name but takes another kind of value (an object built from the setting, or
``None`` for "the object's own") is listed in :data:`OTHER_VALUES` and not compared.

The baselines' learners (:class:`~torchrl_csirl.objectives.SACHyperparameters`: two critics, a
temperature from 1) are other methods with their own published defaults and are not compared here.
"""
from __future__ import annotations

import dataclasses
import importlib
import inspect
from collections import defaultdict
from collections.abc import Callable, Iterator

from torchrl_csirl.hyperparameters import CSIRL_DEFAULTS, CSIRLHyperparameters, CSIRLOptimHyperparameters
from torchrl_csirl.methods.csirl import CSIRLConfig
from torchrl_csirl.run.config import OptimConfig

#: the modules whose public classes and functions take CSIRL's hyperparameters
MODULES = (
    "torchrl_csirl.hyperparameters",
    "torchrl_csirl.objectives.csirl_learner",
    "torchrl_csirl.objectives.ensemble_sac",
    "torchrl_csirl.objectives.meta_reward",
    "torchrl_csirl.trainers.updates",
    "torchrl_csirl.curriculum.subgoal",
    "torchrl_csirl.methods.csirl",
)
#: the configuration sections (and so the library dataclasses they are)
SECTIONS = {"csirl": CSIRLConfig, "optim": OptimConfig}
#: ``name`` or ``(owner, name)`` -> the configuration's name of the same hyperparameter
ALIASES: dict[str | tuple[str, str], str] = {"alpha_init": "alpha", ("MetaRewardLoss", "scale"): "meta_scale"}
#: name -> why two defaults are meant (none)
INTENTIONAL: dict[str, str] = {}
#: ``(owner, name)`` -> what the keyword takes instead of the setting of that name
OTHER_VALUES: dict[tuple[str, str], str] = {
    ("EnsembleSACLoss.qvalue_dispersion", "dispersion"): "a measure for this call; None: the loss's own",
    ("SACUpdate", "precision"): "a LearnerPrecision built from optim.precision; None: float32 throughout (fp32)",
    ("make_csirl_learner", "reward_reference"): "the expert states themselves; None: no reference (none)",
    ("MetaRewardLoss.forward", "expert"): "the expert batch itself; None: read from the one-tensordict batch",
}


def _canonical(owner: str, name: str) -> str:
    return ALIASES.get((owner, name), ALIASES.get(name, name))


def _keyword_defaults(owner: str, where: str, fn: Callable) -> Iterator[tuple[str, str, object]]:
    """``(name, where, default)`` for each parameter of ``fn`` that has a default."""
    try:
        parameters = inspect.signature(fn).parameters.values()
    except (TypeError, ValueError):
        return
    for p in parameters:
        if (owner, p.name) in OTHER_VALUES:
            continue
        if p.default is not inspect.Parameter.empty and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD):
            yield _canonical(owner, p.name), f"{where}({p.name}=)", p.default


def _public_callables(module_name: str) -> Iterator[tuple[str, str, Callable]]:
    """``(owner, where, callable)``: the module's public functions, classes and classes' public methods."""
    module = importlib.import_module(module_name)
    for name, obj in sorted(vars(module).items()):
        if name.startswith("_") or getattr(obj, "__module__", None) != module_name:
            continue
        if inspect.isfunction(obj):
            yield name, f"{module_name}.{name}", obj
        elif inspect.isclass(obj):
            yield name, f"{module_name}.{name}", obj
            for method, fn in sorted(vars(obj).items()):
                if not method.startswith("_") and inspect.isfunction(fn):
                    yield f"{name}.{method}", f"{module_name}.{name}.{method}", fn


def collect_defaults() -> dict[str, dict[str, object]]:
    """``name -> {where: default}`` over :data:`SECTIONS` and :data:`MODULES`."""
    found: dict[str, dict[str, object]] = defaultdict(dict)
    for section, cls in SECTIONS.items():
        for f in dataclasses.fields(cls):
            found[f.name][f"{section}.{f.name} ({cls.__module__}.{cls.__name__})"] = f.default
    for module in MODULES:
        for owner, where, fn in _public_callables(module):
            for name, place, default in _keyword_defaults(owner, where, fn):
                found[name][place] = default
    return found


def disagreements(found: dict[str, dict[str, object]]) -> dict[str, dict[str, object]]:
    """The names given more than one distinct default (``INTENTIONAL`` ones aside).

    Examples:
        >>> disagreements({"tau": {"a": 0.005, "b": 0.005}, "gamma": {"a": 0.99, "b": 0.9}})
        {'gamma': {'a': 0.99, 'b': 0.9}}
    """
    out = {}
    for name, places in found.items():
        values = []
        for value in places.values():
            if value not in values:
                values.append(value)
        if len(values) > 1 and name not in INTENTIONAL:
            out[name] = places
    return out


def test_the_sections_are_the_hyperparameter_dataclasses():
    assert issubclass(CSIRLConfig, CSIRLHyperparameters) and issubclass(OptimConfig, CSIRLOptimHyperparameters)
    for section, base in ((CSIRLConfig, CSIRLHyperparameters), (OptimConfig, CSIRLOptimHyperparameters)):
        declared_here = {name for name in section.__dict__.get("__annotations__", {})}
        assert not declared_here, f"{section.__name__} re-declares {sorted(declared_here)}: declare them in {base.__name__}"
    names = {f.name for f in dataclasses.fields(CSIRLHyperparameters)}
    assert {"meta_every", "updates_per_round", "delta", "sigma"} <= names


def test_the_collection_sees_the_building_blocks():
    found = collect_defaults()
    assert "torchrl_csirl.objectives.ensemble_sac.EnsembleSACLoss(fixed_alpha=)" in found["fixed_alpha"]
    assert "torchrl_csirl.objectives.meta_reward.MetaRewardLoss(scale=)" in found["meta_scale"]
    assert "torchrl_csirl.trainers.updates.MetaRewardUpdate(meta_every=)" in found["meta_every"]
    assert "torchrl_csirl.curriculum.subgoal.SubgoalCurriculum(delta=)" in found["delta"]
    assert "torchrl_csirl.objectives.csirl_learner.CSIRLLearner.optimizers(lr=)" in found["lr"]
    assert found["alpha"]["torchrl_csirl.objectives.ensemble_sac.EnsembleSACLoss(alpha_init=)"] == CSIRL_DEFAULTS.alpha


def test_every_hyperparameter_has_one_default():
    found = disagreements(collect_defaults())
    assert not found, "hyperparameters with more than one default:\n" + "\n".join(
        f"  {name}: " + "; ".join(f"{value!r} in {where}" for where, value in places.items())
        for name, places in sorted(found.items()))
