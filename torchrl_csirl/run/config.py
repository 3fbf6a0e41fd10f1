"""Typed recipe configuration: dataclass schemas read with ``OmegaConf.structured``.

A recipe declares its configuration as nested dataclasses (the sections below are shared by every
recipe; a method adds its own section). Each leaf is declared with :func:`option`, which records
what values are allowed (choices, a lower bound, null or not) and a one-line help. Loading is::

    schema defaults  <-  preset (a config group: config/<recipe>/preset/<name>.yaml)  <-  command line

and resuming a run is ``schema <- the run's saved config.yaml <- command line``. OmegaConf checks
the types (``collector.total_frames=abc`` is rejected), :func:`validate` the values; every problem
is one :class:`ConfigError` line naming the key, the value and what is allowed, raised before any
worker process starts.

Examples:
    >>> from dataclasses import dataclass, field
    >>> @dataclass
    ... class Demo:
    ...     seed: int = option(0, minimum=0, help="random seed")
    ...     env: EnvConfig = field(default_factory=EnvConfig)
    >>> cfg = load_config(Demo, ["seed=3", "env.task=roundabout"])
    >>> cfg.seed, cfg.env.task
    (3, 'roundabout')
    >>> load_config(Demo, ["seed=abc"])
    Traceback (most recent call last):
    ...
    torchrl_csirl.run.config.ConfigError: seed=abc: must be an integer >= 0
"""
from __future__ import annotations

import dataclasses
import difflib
import os
import types
import typing
import warnings
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any, Optional, Union

from omegaconf import DictConfig, OmegaConf, open_dict
from omegaconf.errors import OmegaConfBaseException

from torchrl_csirl._options import option
from torchrl_csirl.hyperparameters import CSIRLOptimHyperparameters

__all__ = [
    "CheckpointConfig",
    "CollectorConfig",
    "CommandLine",
    "ConfigError",
    "EnvConfig",
    "EvalConfig",
    "ExpertConfig",
    "LoggerConfig",
    "ModelConfig",
    "OptimConfig",
    "ReplayBufferConfig",
    "ConfigKey",
    "describe",
    "describe_rows",
    "flatten_config",
    "format_override",
    "load_config",
    "load_run_config",
    "option",
    "parse_command_line",
    "preset_names",
    "validate",
]



def driving_scenes() -> tuple[str, ...]:
    """The driving scenes, read from the task registry when asked (``env.task``'s choices)."""
    from torchrl_csirl.tasks import task_names

    return task_names(family="driving")

PUBLISHED_END_AT = ("recording", "first_done", "termination")  # torchrl_csirl.data.END_AT
DEVICES = ("cpu", "cuda", "auto")


class ConfigError(ValueError):
    """A bad configuration key or value (one line: the key, the value, what is allowed)."""


# ---------------------------------------------------------------------------------------- shared sections
@dataclass
class EnvConfig:
    task: str = option("merge", choices=driving_scenes, help="the driving scene (env.scenario: deprecated spelling)")


@dataclass
class CollectorConfig:
    total_frames: Optional[int] = option(60000, above=0, help="environment frames (null: the preset's budget)")
    frames_per_batch: int = option(500, above=0, help="frames per collected batch")
    num_workers: int = option(2, above=0, help="worker processes, each with its envs and a policy copy")
    envs_per_worker: Optional[int] = option(
        None, above=0, help="envs stepped by each worker (null: up to 4 that still fit a whole episode per batch)")
    main_threads: Optional[int] = option(None, above=0, help="torch threads of the main process (null: all cores)")
    init_random_frames: int = option(1000, minimum=0, help="uniform random actions first")
    cut_episodes: bool = option(
        False, help="true: allow batches whose per-environment share is shorter than the episode limit (every batch "
                    "restarts the environments, so longer episodes are cut; tiny test budgets only)")


@dataclass
class ExpertConfig:
    num_trajectories: int = option(25, above=0, help="demonstrations used (1, 5, 10, 15, 20, 25 shipped)")
    curriculum: str = option("empty", choices=("empty", "traffic"),
                             help="the curriculum trajectory: empty (empty road: trajectory 0 of a file) | traffic "
                                  "(recorded in traffic: the first such trajectory of a file)")
    path: Optional[str] = option(None, help="your own demonstrations (.npz, or a published pickle)")
    end_at: str = option("recording", choices=PUBLISHED_END_AT,
                         help="where a published file's trajectories end: recording (whole recording) | first_done "
                              "| termination (where our scenario ends the episode); docs/experts.md")
    batch_size: int = option(32, above=0, help="expert pairs per meta / cloning step")


@dataclass
class ReplayBufferConfig:
    size: int = option(1_000_000, above=0, help="online buffer capacity")
    batch_size: int = option(256, above=0, help="transitions per update")
    clear_each_round: bool = option(False, help="empty the buffer at each round start (the paper's code)")
    warmup_frames: int = option(1000, minimum=0, help="transitions in the buffer before the first update of a round")
    expert_fraction: float = option(0.25, minimum=0.0, below=1.0,
                                    help="share of expert transitions in every batch (paper: 0)")


@dataclass
class LearnerReplayBufferConfig:
    """The online buffer of a recipe whose learner section sets its own batch size (baselines, the ant expert)."""

    size: int = option(1_000_000, above=0, help="online buffer capacity")
    clear_each_round: bool = option(False, help="empty the buffer at each round start")
    warmup_frames: int = option(1000, minimum=0, help="transitions in the buffer before the first update of a round")


@dataclass
class UpdateRatioConfig:
    """``optim`` of a recipe whose learner section holds its learning rates."""

    utd_ratio: float = option(0.5, above=0.0, help="updates per collected frame (learning rates: the learner's section)")


@dataclass
class ModelConfig:
    ego_relative_features: bool = option(True, help="networks also read the other vehicles' offsets from the ego")
    lane_features: bool = option(False, help="networks also read the ego's offset from the nearest lane centre line "
                                             "(and its heading relative to that lane; docs/recipes.md)")


@dataclass
class OptimConfig(CSIRLOptimHyperparameters):
    """``optim`` of CSIRL's recipes: the learner's optimisation hyperparameters, declared in
    :class:`~torchrl_csirl.hyperparameters.CSIRLOptimHyperparameters` (:func:`~torchrl_csirl.objectives.make_csirl_learner`'s
    and :meth:`~torchrl_csirl.objectives.CSIRLLearner.optimizers`' defaults)."""


@dataclass
class EvalConfig:
    episodes: int = option(10, above=0, help="deterministic episodes per evaluation")
    every_rounds: int = option(1, above=0, help="evaluation cadence in rounds")
    final_episodes: int = option(50, above=0, help="episodes of the reported test accomplish rate")
    seed: int = option(1_000_000, minimum=0, help="test episode i (the final evaluation) uses seed + i")
    validation_seed: Optional[int] = option(
        2_000_000, minimum=0,
        help="the periodic evaluations' (learning curve) episode i uses validation_seed + i, a range apart "
             "from the test episodes; null: the test seeds (runs recorded before this key)")
    health_episodes: int = option(
        5, minimum=0, help="CSIRL: the policy's episodes of the run's health report (health.json, health.png; "
                           "docs/own-task.md#when-a-run-fails); 0: no report")
    video: bool = option(True, help="film the final evaluation's first episode into videos/ (mp4, or gif without "
                                    "imageio-ffmpeg) and log it to W&B; recipes/watch.py films more")


@dataclass
class LoggerConfig:
    backend: str = option("wandb", choices=("wandb", "csv", "none"),
                          help="wandb (offline unless mode=online) | csv / none (metrics.csv and .jsonl only, written "
                               "row by row in every case)")
    mode: str = option("offline", choices=("offline", "online", "disabled"), help="W&B mode")
    project: str = option("torchrl-csirl", help="W&B project")
    output_dir: str = option("runs", help="where run directories go")
    exp_name: Optional[str] = option(None, help="run directory name (null: <scenario>-<method>-s<seed>-<time>)")
    overwrite: bool = option(False, help="replace an existing run directory of the same name")
    progress_bar: bool = option(True, help="a progress bar on a terminal")


@dataclass
class CheckpointConfig:
    every_rounds: int = option(1, minimum=0, help="checkpoint cadence in rounds (0: only at the end)")
    resume: Optional[str] = option(None, help="a run directory to continue")
    save_buffer: bool = option(True, help="save the online buffer with the checkpoint (exact resume)")


# ---------------------------------------------------------------------------------------- loading
def preset_names(config_dir: str) -> tuple[str, ...]:
    """``default`` and the presets of the config group ``<config_dir>/preset/*.yaml``."""
    folder = os.path.join(config_dir, "preset")
    found = sorted(n[:-5] for n in os.listdir(folder) if n.endswith(".yaml")) if os.path.isdir(folder) else []
    return tuple(dict.fromkeys(["default", *found]))


#: the keys a command line may still spell by their deprecated names: ``deprecated -> the setting``
DEPRECATED_KEYS = {"env.scenario": "env.task"}


@dataclass(frozen=True)
class CommandLine:
    """A command line parsed once (:func:`parse_command_line`): what every loader reads instead of the raw strings.

    Attributes:
        values: ``{key: value}``, the values as written (the last one of a key wins), deprecated key names mapped.
        tree: the same as an OmegaConf tree, the values read as YAML (``null``, ``true``, ``3``).
        help: whether ``--help`` / ``-h`` was given.
    """

    values: Mapping[str, str]
    tree: DictConfig
    help: bool = False

    def get(self, key: str) -> str | None:
        """``key``'s value as written, None when absent or ``null``."""
        value = self.values.get(key)
        return None if value in (None, "null") else value

    def strings(self) -> list[str]:
        """The ``key=value`` strings (one per key)."""
        return [f"{k}={v}" for k, v in self.values.items()]

    def with_values(self, values: Mapping[str, str], first: bool = False) -> CommandLine:
        """This command line with ``values`` added (``first``: only where the line does not set the key)."""
        added = {k: v for k, v in values.items() if not (first and k in self.values)}
        if not added:
            return self
        tree = self.tree.copy()
        for key, value in added.items():
            OmegaConf.update(tree, key, _yaml_value(key, value), force_add=True)
        return CommandLine({**self.values, **added}, tree, self.help)

    def without(self, key: str) -> CommandLine:
        """This command line without ``key``."""
        if key not in self.values:
            return self
        values = {k: v for k, v in self.values.items() if k != key}
        return CommandLine(values, _dotlist_tree(values), self.help)


def _dotlist_tree(values: Mapping[str, str]) -> DictConfig:
    try:
        return OmegaConf.from_dotlist([f"{k}={v}" for k, v in values.items()])
    except OmegaConfBaseException as err:
        raise ConfigError(f"bad override: {_first_line(err)}") from None


def _yaml_value(key: str, value: str) -> Any:
    return OmegaConf.select(_dotlist_tree({key: value}), key)


def parse_command_line(argv: Iterable[str] | CommandLine | None) -> CommandLine:
    """``key=value`` strings (and ``--help``) as a :class:`CommandLine`: the one parse of a run's command line.

    A deprecated key name (:data:`DEPRECATED_KEYS`: ``env.scenario``) is mapped onto its setting (``env.task``) with a
    ``FutureWarning``. A :class:`CommandLine` is returned as it is.

    Raises:
        ConfigError: an item not of the form ``key=value``, or a deprecated name and its setting naming different values.

    Examples:
        >>> parse_command_line(["env.gym_id=Pendulum-v1", "checkpoint.resume=runs/a=b"]).values
        {'env.gym_id': 'Pendulum-v1', 'checkpoint.resume': 'runs/a=b'}
    """
    if isinstance(argv, CommandLine):
        return argv
    items = list(argv or [])
    flags = [a for a in items if a in ("--help", "-h")]
    values: dict[str, str] = {}
    deprecated: dict[str, tuple[str, str]] = {}  # the setting -> (its deprecated name, the value given under it)
    current: dict[str, str] = {}  # the settings given under their own name -> the value
    for item in items:
        if item in flags:
            continue
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise ConfigError(f"{item}: not of the form key=value (e.g. env.task=merge)")
        if key in DEPRECATED_KEYS:
            warnings.warn(f"{key}= is deprecated: use {DEPRECATED_KEYS[key]}={value}", FutureWarning, stacklevel=2)
            deprecated[DEPRECATED_KEYS[key]] = (key, value)
            key = DEPRECATED_KEYS[key]
        else:
            current[key] = value
        values.pop(key, None)
        values[key] = value
    for key, (name, value) in deprecated.items():
        if current.get(key, value) != value:
            raise ConfigError(f"{key}={current[key]} and {name}={value}: the same setting, give one of them")
    return CommandLine(values, _dotlist_tree(values), bool(flags))


def current_names(saved: DictConfig) -> DictConfig:
    """A saved configuration with its deprecated key names (:data:`DEPRECATED_KEYS`) read as their settings: a run saved
    with ``env.scenario`` only resumes as ``env.task``; the mirror a loaded configuration carries is dropped.

    Examples:
        >>> current_names(OmegaConf.create({"env": {"scenario": "merge"}})).env
        {'task': 'merge'}
    """
    for name, key in DEPRECATED_KEYS.items():
        section, _, leaf = name.rpartition(".")
        parent = OmegaConf.select(saved, section)
        if parent is None or leaf not in parent:
            continue
        value = parent[leaf]
        if OmegaConf.select(saved, key) is None:
            OmegaConf.update(saved, key, value, force_add=True)
        del parent[leaf]
    return saved


def with_deprecated_names(cfg: DictConfig) -> DictConfig:
    """``cfg`` with each deprecated key name (``env.scenario``) holding its setting's value: read-only mirrors for the
    code and the saved runs that read the deprecated name (the command line and the schema know one name)."""
    for name, key in DEPRECATED_KEYS.items():
        section, _, leaf = name.rpartition(".")
        parent = OmegaConf.select(cfg, section)
        if parent is not None and key.rpartition(".")[2] in parent:
            with open_dict(parent):
                parent[leaf] = OmegaConf.select(cfg, key)
    return cfg


def scene_defaults_path(config_dir: str, scenario: str) -> str:
    """``<config_dir>/scene/<scenario>.yaml``: a scenario's own defaults (the file may not exist)."""
    return os.path.join(config_dir, "scene", f"{scenario}.yaml")


def scene_defaults(config_dir: str) -> dict[str, dict[str, object]]:
    """Every scenario that has its own defaults under ``config_dir``, as ``{scenario: {key: value}}``."""
    folder = os.path.join(config_dir, "scene")
    names = sorted(n[:-5] for n in os.listdir(folder) if n.endswith(".yaml")) if os.path.isdir(folder) else []
    return {name: flatten_config(OmegaConf.load(scene_defaults_path(config_dir, name))) for name in names}


def load_config(schema: type, overrides: list[str] | CommandLine | None = None, config_dir: str | None = None) -> DictConfig:
    """Schema defaults, the task's defaults, the ``preset``, then ``overrides``.

    The task's defaults (``<config_dir>/scene/<env.task>.yaml``, where the task has such a file) are the default
    preset of that task; a named preset (``preset=paper``) goes over them.

    Args:
        schema: the recipe's top-level dataclass.
        overrides: the command line (:func:`parse_command_line`'s, or its ``key=value`` strings).
        config_dir: folder holding ``preset/<name>.yaml`` and ``scene/<task>.yaml`` (None: no
            presets besides ``default``, no scene defaults).

    Raises:
        ConfigError: one line naming the bad key or value.
    """
    cli = parse_command_line(overrides).tree
    check_known_keys(schema, cli)
    base = OmegaConf.structured(schema)
    layers = []
    scenario = OmegaConf.select(cli, "env.task", default=None)
    if scenario is None:
        scenario = OmegaConf.select(base, "env.task", default=None)
    scene_file = scene_defaults_path(config_dir, scenario) if config_dir and isinstance(scenario, str) else None
    if scene_file and os.path.isfile(scene_file):
        layers.append(OmegaConf.load(scene_file))
    preset = cli.get("preset", base.get("preset", "default")) if "preset" in base else None
    if preset is not None:
        allowed = preset_names(config_dir) if config_dir else ("default",)
        if preset not in allowed:
            raise ConfigError(f"preset={preset}: must be one of {', '.join(allowed)}")
        if preset != "default":
            layers.append(OmegaConf.load(os.path.join(config_dir, "preset", f"{preset}.yaml")))
    return _merge_and_validate(schema, base, [*layers, cli])


#: keys a resumed run keeps: ``preset`` (the saved values already hold it) and the settings that decide what the
#: checkpoint's networks and losses are (a standardisation's statistics, an objective's form)
RESUME_FIXED_KEYS = ("preset", "valuedice.normalize_states", "iqlearn.value_loss")


#: the value a saved configuration that lacks the key is read with, where that differs from the schema's default:
#: a resumed (or diagnosed) run keeps the value it ran with
VALUES_OF_MISSING_KEYS: dict[str, object] = {
    # the schema's null turns goal-conditioned matching on where the observation has a desired_goal; a saved
    # configuration without the key matched without the goal
    "csirl.goal_conditioned": False,
}


def pin_missing_settings(saved: DictConfig) -> DictConfig:
    """``saved`` with each key of :data:`VALUES_OF_MISSING_KEYS` it lacks (where it has the key's section) set to
    that value, the one the run ran with, instead of the schema's default.

    Examples:
        >>> from omegaconf import OmegaConf
        >>> pin_missing_settings(OmegaConf.create({"csirl": {"delta": 5.0}})).csirl.goal_conditioned
        False
    """
    for key, value in VALUES_OF_MISSING_KEYS.items():
        section, _, leaf = key.rpartition(".")
        parent = OmegaConf.select(saved, section)
        if parent is not None and leaf not in parent:
            OmegaConf.update(saved, key, value)
    return saved


def load_run_config(schema: type, run_dir: str, overrides: list[str] | CommandLine | None = None) -> DictConfig:
    """A run's saved ``config.yaml`` over the schema, updated by ``overrides`` (resume).

    ``checkpoint.resume`` of the saved file is dropped, the :data:`RESUME_FIXED_KEYS` cannot change, and a key the
    saved file lacks keeps the value the run had (:func:`pin_missing_settings`).
    """
    path = os.path.join(run_dir, "config.yaml")
    if not os.path.isfile(path):
        raise ConfigError(f"checkpoint.resume={run_dir}: no config.yaml there")
    saved = pin_missing_settings(current_names(OmegaConf.load(path)))
    if "checkpoint" in saved and "resume" in saved.checkpoint:
        saved.checkpoint.resume = None
    cli = parse_command_line(overrides).tree
    check_known_keys(schema, cli)
    for key in RESUME_FIXED_KEYS:
        new, old = OmegaConf.select(cli, key), OmegaConf.select(saved, key)
        if new is not None and old is not None and new != old:
            what = "its preset" if key == "preset" else "this setting"
            raise ConfigError(f"{key}={new}: a resumed run keeps {what} ({old})")
    return _merge_and_validate(schema, OmegaConf.structured(schema), [saved, cli], source=path)


def check_known_keys(schema: type, overrides: DictConfig) -> None:
    """Raises :class:`ConfigError` naming the first override key the schema does not have."""
    for key in flatten_config(overrides):
        if _leaf_field(schema, key) is None:
            raise ConfigError(_unknown_key(schema, key, None))


def _unknown_key(schema: type, key: str, source: str | None) -> str:
    known = list(flatten_config(OmegaConf.structured(schema)))
    close = difflib.get_close_matches(key, known, n=1)
    hint = f"; did you mean {close[0]}?" if close else ""
    where = f" (in {source})" if source else ""
    return f"{key}: unknown configuration key{where}{hint}"


def _merge_and_validate(schema: type, base: DictConfig, layers: list[DictConfig], source: str | None = None) -> DictConfig:
    cfg = base
    OmegaConf.set_struct(cfg, True)
    for layer in layers:
        try:
            cfg = OmegaConf.merge(cfg, layer)
        except OmegaConfBaseException as err:
            raise ConfigError(_explain(schema, err, source)) from None
    validate(cfg, schema)
    return with_deprecated_names(cfg)


def _explain(schema: type, err: OmegaConfBaseException, source: str | None) -> str:
    """One line for an OmegaConf merge error: unknown key, or a value of the wrong type."""
    key = getattr(err, "full_key", None) or ""
    where = f" (in {source})" if source else ""
    leaf = _leaf_field(schema, key)
    if leaf is None:
        return _unknown_key(schema, key or _first_line(err), source)
    value = getattr(err, "value", None)
    shown = _value_text(value) if value is not None else "?"
    return f"{key}={shown}: must be {describe_allowed(*leaf)}{where}"


def _first_line(err: Exception) -> str:
    return str(err).strip().splitlines()[0]


def _value_text(value: Any) -> str:
    return "null" if value is None else str(value).lower() if isinstance(value, bool) else str(value)


def _hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def _optional_inner(tp: Any) -> tuple[Any, bool]:
    """(the type, whether null is allowed) of an annotation."""
    if typing.get_origin(tp) in (Union, types.UnionType):  # Optional[X], X | None
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        return args[0], len(args) < len(typing.get_args(tp))
    return tp, False


def _leaf_field(schema: type, dotted: str) -> tuple[Any, dict] | None:
    """(annotation, metadata) of the schema leaf at ``dotted``, or None if there is none."""
    cls = schema
    parts = dotted.split(".") if dotted else []
    for i, part in enumerate(parts):
        if not dataclasses.is_dataclass(cls):
            return None
        fields = {f.name: f for f in dataclasses.fields(cls)}
        if part not in fields:
            return None
        tp = _hints(cls)[part]
        if i == len(parts) - 1:
            return (None, {}) if dataclasses.is_dataclass(tp) else (tp, dict(fields[part].metadata))
        cls = tp
    return None


_TYPE_WORDS = {int: "an integer", float: "a number", bool: "true or false", str: "a string"}


def describe_allowed(annotation: Any, metadata: dict) -> str:
    """What a leaf accepts, in words: ``an integer > 0 or null``, ``one of a, b``.

    Examples:
        >>> describe_allowed(Optional[int], {"above": 0})
        'an integer > 0 or null'
        >>> describe_allowed(str, {"choices": ("ego", "position")})
        'one of ego, position'
    """
    tp, nullable = _optional_inner(annotation)
    choices = _choices(metadata)
    if choices:
        text = "one of " + ", ".join(map(str, choices))
    else:
        text = _TYPE_WORDS.get(tp, getattr(tp, "__name__", str(tp)))
        bounds = [f">= {metadata['minimum']}" if metadata.get("minimum") is not None else None,
                  f"> {metadata['above']}" if metadata.get("above") is not None else None,
                  f"< {metadata['below']}" if metadata.get("below") is not None else None]
        bounds = [b for b in bounds if b]
        if bounds:
            text += " " + " and ".join(bounds)
    return text + (" or null" if nullable else "")


def validate(cfg: DictConfig, schema: type, prefix: str = "") -> None:
    """Checks every leaf of ``cfg`` against its :func:`option` constraints.

    Raises:
        ConfigError: ``key=value: must be ...`` for the first value out of bounds.
    """
    hints = _hints(schema)
    for f in dataclasses.fields(schema):
        tp, value, key = hints[f.name], cfg.get(f.name), f"{prefix}{f.name}"
        if dataclasses.is_dataclass(tp):
            validate(value, tp, prefix=f"{key}.")
        elif not _allowed(value, tp, f.metadata):
            raise ConfigError(f"{key}={_value_text(value)}: must be {describe_allowed(tp, f.metadata)}")


def _choices(metadata: Any) -> tuple | None:
    """A leaf's allowed values: a tuple, or a callable giving them now (e.g. the registered tasks)."""
    choices = metadata.get("choices")
    return tuple(choices()) if callable(choices) else choices


def _allowed(value: Any, annotation: Any, metadata: Any) -> bool:
    tp, nullable = _optional_inner(annotation)
    if value is None:
        return nullable
    choices = _choices(metadata)
    if choices and value not in choices:
        return False
    if metadata.get("minimum") is not None and value < metadata["minimum"]:
        return False
    if metadata.get("above") is not None and not value > metadata["above"]:
        return False
    if metadata.get("below") is not None and not value < metadata["below"]:
        return False
    return True


# ---------------------------------------------------------------------------------------- views
def flatten_config(cfg: DictConfig) -> dict[str, Any]:
    """``{"dotted.key": value}`` for every leaf of ``cfg``.

    Examples:
        >>> flatten_config(OmegaConf.create({"env": {"task": "merge"}, "seed": 0}))
        {'env.task': 'merge', 'seed': 0}
    """
    out: dict[str, Any] = {}

    def visit(node: dict, prefix: str) -> None:
        for key, value in node.items():
            if isinstance(value, dict):
                visit(value, f"{prefix}{key}.")
            else:
                out[f"{prefix}{key}"] = value

    visit(OmegaConf.to_container(cfg), "")
    return out


def format_override(key: str, value: Any) -> str:
    """``key=value`` as the command line writes it (``null``, lower-case booleans).

    Examples:
        >>> format_override("expert.path", None), format_override("csirl.intrinsic", False)
        ('expert.path=null', 'csirl.intrinsic=false')
    """
    return f"{key}={_value_text(value)}"


def attribute_docs(cls: type) -> dict[str, str]:
    """``name -> description`` from the ``Attributes:`` sections of ``cls``'s and its bases' docstrings.

    The help of a leaf declared without :func:`option` (e.g. a library's hyperparameter dataclass
    used as a section).

    Examples:
        >>> @dataclass
        ... class Hp:
        ...     \"\"\"Settings.
        ...
        ...     Attributes:
        ...         lr: Adam learning rate.
        ...         gamma: discount
        ...             factor.
        ...     \"\"\"
        ...     lr: float = 0.1
        ...     gamma: float = 0.9
        >>> attribute_docs(Hp)
        {'lr': 'Adam learning rate', 'gamma': 'discount factor'}
    """
    docs: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        lines = (klass.__doc__ or "").splitlines()
        starts = [i for i, line in enumerate(lines) if line.strip() == "Attributes:"]
        if not starts:
            continue
        indent, name = None, None
        for line in lines[starts[0] + 1:]:
            if not line.strip():
                if name is not None:
                    break
                continue
            depth = len(line) - len(line.lstrip())
            indent = depth if indent is None else indent
            if depth < indent:
                break
            head, sep, rest = line.strip().partition(":")
            if depth == indent and sep and head.isidentifier():
                name, docs[head] = head, rest.strip()
            elif name is not None:
                docs[name] += " " + line.strip()
    return {k: v.rstrip(".") for k, v in docs.items()}


def help_requested(argv: list[str] | CommandLine, doc: str, schema: type) -> bool:
    """With ``--help`` / ``-h`` on the command line, print ``doc`` and every key of ``schema``
    (:func:`describe`) and return ``True``; a recipe's ``main`` then returns without running.

    Examples:
        >>> help_requested(["seed=1"], "doc", EnvConfig)
        False
    """
    if not (argv.help if isinstance(argv, CommandLine) else "--help" in argv or "-h" in argv):
        return False
    print(doc + "\nKeys (key, default, what it accepts, meaning):\n  " + "\n  ".join(describe(schema)))
    return True


class ConfigKey(typing.NamedTuple):
    """One leaf of a schema, as :func:`describe_rows` reports it."""

    key: str  #: dotted key, e.g. ``collector.total_frames``
    default: str  #: the default as written on a command line (``null``, ``false``, ...)
    allowed: str  #: what values are accepted
    help: str  #: what the key does


def describe_rows(schema: type, prefix: str = "") -> list[ConfigKey]:
    """Every leaf of ``schema`` with its default, what it accepts and its help, in schema order
    (the source of each recipe's ``--help`` and of the docs' configuration reference).

    Examples:
        >>> describe_rows(EnvConfig)[0].key, describe_rows(EnvConfig)[0].default
        ('task', 'merge')
    """
    rows = []
    hints = _hints(schema)
    for f in dataclasses.fields(schema):
        tp, key = hints[f.name], f"{prefix}{f.name}"
        if dataclasses.is_dataclass(tp):
            rows.extend(describe_rows(tp, prefix=f"{key}."))
            continue
        help_text = f.metadata.get("help") or attribute_docs(schema).get(f.name, "")
        rows.append(ConfigKey(key, _value_text(f.default), describe_allowed(tp, f.metadata), help_text))
    return rows


def describe(schema: type, prefix: str = "") -> list[str]:
    """``key = default  # what is allowed; help`` for every leaf (a recipe's ``--help``).

    Examples:
        >>> describe(EnvConfig)
        ['task = merge  # one of highway-fast, intersection, merge, roundabout; the driving scene (env.scenario: deprecated spelling)']
    """
    return [f"{r.key} = {r.default}  # {r.allowed}" + (f"; {r.help}" if r.help else "")
            for r in describe_rows(schema, prefix)]
