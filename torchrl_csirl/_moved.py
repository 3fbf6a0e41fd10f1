"""Module paths kept for one release: each old dotted name in :data:`MOVED` imports its new module and
emits one :class:`FutureWarning` naming the new path.

One table, no per-file stubs: :func:`install` (called by ``torchrl_csirl/__init__.py``) puts a finder on
:data:`sys.meta_path` that answers for these names only. A leaf module's old name is the new module
object itself (``import torchrl_csirl.envs.driving as m`` gives ``torchrl_csirl.tasks.driving.driving``);
an old package's name is a small module that forwards its attributes to the new package (so its old
submodules bound on it never shadow the new package's own). Pickles written under an old name load:
:mod:`pickle` imports the old module name and reads the class from it.

Examples:
    >>> import warnings
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always")
    ...     import torchrl_csirl.tasks.spec as new
    ...     old = redirect("torchrl_csirl.envs.spec")
    >>> old is new
    True
"""
from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import types
import warnings

__all__ = ["MOVED", "install", "redirect"]

#: old dotted module name -> the module it now is
MOVED: dict[str, str] = {
    "torchrl_csirl.envs": "torchrl_csirl.tasks",
    "torchrl_csirl.envs.robotics": "torchrl_csirl.tasks.robotics",
    **{f"torchrl_csirl.envs.robotics.{m}": f"torchrl_csirl.tasks.robotics.{m}"
       for m in ("ant_goal", "expert", "point_maze_expert", "tasks")},
    **{f"torchrl_csirl.envs.{m}": f"torchrl_csirl.tasks.{m}"
       for m in ("spec", "registry", "torchrl_env", "gymnasium_env", "gymnasium_task", "gym_ids", "metrics", "info",
                 "parallel", "headless", "locomotion", "expert_rollout", "expert_policy")},
    "torchrl_csirl.envs.scenarios": "torchrl_csirl.tasks.catalog",
    "torchrl_csirl.envs.expert_registry": "torchrl_csirl.tasks.experts",
    **{f"torchrl_csirl.envs.{m}": f"torchrl_csirl.tasks.driving.{m}"
       for m in ("driving", "_road", "_vehicles", "road_clone", "route_follower", "_observation", "expert",
                 "expert_config", "expert_driver")},
    "torchrl_csirl.benchmark": "torchrl_csirl.sweep",
    **{f"torchrl_csirl.benchmark.{m}": f"torchrl_csirl.sweep.{m}"
       for m in ("curves", "plan", "published", "report", "results", "runner")},
    "torchrl_csirl.diagnostics": "torchrl_csirl.analysis.diagnostics",
    **{f"torchrl_csirl.diagnostics.{m}": f"torchrl_csirl.analysis.diagnostics.{m}"
       for m in ("calibration", "checks", "probe", "report")},
    "torchrl_csirl.visualization": "torchrl_csirl.analysis.visualization",
    **{f"torchrl_csirl.visualization.{m}": f"torchrl_csirl.analysis.visualization.{m}"
       for m in ("_figure", "curves", "filmstrip", "health", "robotics", "scene", "video")},
    "torchrl_csirl.launch": "torchrl_csirl.run",
    **{f"torchrl_csirl.launch.{m}": f"torchrl_csirl.run.{m}"
       for m in ("config", "recipes", "run", "lifecycle", "assembly", "builders", "collection", "experts", "final",
                 "processes", "provenance", "video")},
    "torchrl_csirl.launch.robotics": "torchrl_csirl.run.task_schemas",
    "torchrl_csirl.launch.csirl": "torchrl_csirl.methods.csirl",
    "torchrl_csirl.launch.imitation": "torchrl_csirl.methods.baselines",
    "torchrl_csirl.launch.expert_training": "torchrl_csirl.methods.expert",
    "torchrl_csirl.launch.ant_expert": "torchrl_csirl.methods.ant_expert",
    "torchrl_csirl.launch.summaries": "torchrl_csirl.analysis.summaries",
    "torchrl_csirl.launch.verdicts": "torchrl_csirl.analysis.verdicts",
}


def _warn(old: str, new: str, stacklevel: int) -> None:
    warnings.warn(f"{old} is now {new}; import it from there (the old path goes in the next release)",
                  FutureWarning, stacklevel=stacklevel + 1)


def _forwarding_package(old: str, new: types.ModuleType) -> types.ModuleType:
    """A module named ``old`` whose attributes are ``new``'s (its own submodules aside); the first
    attribute read from it warns (importing one of its old submodules warns for that submodule only)."""
    module = types.ModuleType(old, new.__doc__)
    module.__path__ = []  # a package: its old submodules are found by name, through :data:`MOVED`
    warned = []

    def forward(name: str):
        if f"{old}.{name}" in MOVED:  # ``from <old package> import <old submodule>``: that submodule, wherever it is now
            return importlib.import_module(f"{old}.{name}")
        if not warned:
            warned.append(name)
            _warn(old, new.__name__, 2)
        return getattr(new, name)

    module.__getattr__ = forward
    module.__dir__ = lambda: sorted(set(dir(new)) | set(module.__dict__))
    return module


def redirect(old: str, new: str | None = None, stacklevel: int = 1) -> types.ModuleType:
    """The module ``old`` stands for (``new``, by default :data:`MOVED`'s entry); ``sys.modules[old]`` is set to it.

    A module's old name warns here, once (:class:`FutureWarning`, naming the new path); a package's on its
    first attribute read."""
    new = new or MOVED[old]
    target = importlib.import_module(new)
    if hasattr(target, "__path__"):
        module = _forwarding_package(old, target)
    else:
        _warn(old, new, stacklevel + 1)
        module = target
    sys.modules[old] = module
    return module


class _Loader(importlib.abc.Loader):
    def create_module(self, spec):
        return None  # a placeholder: ``exec_module`` replaces it in ``sys.modules``

    def exec_module(self, module):
        redirect(module.__name__, stacklevel=2)  # the importing line (importlib's frames are skipped)


class _Finder(importlib.abc.MetaPathFinder):
    def find_spec(self, fullname, path=None, target=None):
        if fullname not in MOVED:
            return None
        return importlib.machinery.ModuleSpec(fullname, _Loader(), is_package=True)


def install() -> None:
    """Put the finder of :data:`MOVED`'s names first on :data:`sys.meta_path` (once)."""
    if not any(isinstance(finder, _Finder) for finder in sys.meta_path):
        sys.meta_path.insert(0, _Finder())
