"""The module paths kept for one release (:mod:`torchrl_csirl._moved`): an old path imports, warns once with
:class:`FutureWarning` naming the new path, and gives the new module's objects."""
from __future__ import annotations

import importlib
import importlib.util
import pickle
import subprocess
import sys
import warnings

import pytest

from torchrl_csirl import _moved

#: ``old module, new module, a name defined there`` for a few old paths of each moved package
CASES = [
    ("torchrl_csirl.envs", "torchrl_csirl.tasks", "TASKS"),
    ("torchrl_csirl.envs.driving", "torchrl_csirl.tasks.driving.driving", "CSIRLMergeEnv"),
    ("torchrl_csirl.envs.scenarios", "torchrl_csirl.tasks.catalog", "SCENARIOS"),
    ("torchrl_csirl.envs.robotics.ant_goal", "torchrl_csirl.tasks.robotics.ant_goal", "ANT_GOAL_SPEC"),
    ("torchrl_csirl.benchmark.plan", "torchrl_csirl.sweep.plan", "METHOD_ORDER"),
    ("torchrl_csirl.diagnostics", "torchrl_csirl.analysis.diagnostics", "health_report"),
    ("torchrl_csirl.visualization.curves", "torchrl_csirl.analysis.visualization.curves", "plot_learning_curve"),
    ("torchrl_csirl.launch.verdicts", "torchrl_csirl.analysis.verdicts", "compare_family"),
    ("torchrl_csirl.launch", "torchrl_csirl.run", "recipe_for"),
    ("torchrl_csirl.launch.config", "torchrl_csirl.run.config", "option"),
    ("torchrl_csirl.launch.csirl", "torchrl_csirl.methods.csirl", "CSIRLTaskConfig"),
    ("torchrl_csirl.launch.imitation", "torchrl_csirl.methods.baselines", "IMITATION_RECIPE"),
    ("torchrl_csirl.launch.robotics", "torchrl_csirl.run.task_schemas", "schema_family"),
]


def _fresh(old: str) -> None:
    for name in [n for n in sys.modules if n == old or n.startswith(old + ".")]:
        del sys.modules[name]


@pytest.mark.parametrize("old, new, name", CASES, ids=[c[0] for c in CASES])
def test_an_old_path_warns_once_and_gives_the_new_object(old, new, name):
    _fresh(old)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        module = importlib.import_module(old)
        obj = getattr(module, name)
    moved = [w for w in caught if issubclass(w.category, FutureWarning)]
    assert len(moved) == 1, [str(w.message) for w in moved]
    assert new in str(moved[0].message) and not moved[0].filename.endswith("_moved.py")  # it points at the import
    assert obj is getattr(importlib.import_module(new), name)


def test_the_old_import_forms_work():
    code = ("import warnings; warnings.simplefilter('error', FutureWarning)\n"
            "try:\n    import torchrl_csirl.envs.driving as m\nexcept FutureWarning as w:\n    print(w)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert "torchrl_csirl.tasks.driving.driving" in out
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        import torchrl_csirl.envs.driving as m
        import torchrl_csirl.run.config
        import torchrl_csirl.tasks
        from torchrl_csirl.envs import driving as old_driving
        from torchrl_csirl.envs.spec import TaskSpec
        from torchrl_csirl.launch import csirl as old_csirl
        from torchrl_csirl.launch.config import ConfigError
        from torchrl_csirl.tasks import driving
    assert m.__name__ == "torchrl_csirl.tasks.driving.driving"
    assert TaskSpec is torchrl_csirl.tasks.TaskSpec
    assert ConfigError is torchrl_csirl.run.config.ConfigError
    assert old_driving.__name__ == "torchrl_csirl.tasks.driving.driving"  # the module, not the new package of that name
    assert old_csirl.__name__ == "torchrl_csirl.methods.csirl"
    assert driving.__name__ == "torchrl_csirl.tasks.driving"  # the old submodule shadows nothing of the new package


def test_a_pickle_by_an_old_name_loads():
    from torchrl_csirl.tasks.spec import TaskSpec

    data = pickle.dumps(TaskSpec, protocol=0).replace(b"torchrl_csirl.tasks.spec", b"torchrl_csirl.envs.spec")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        assert pickle.loads(data) is TaskSpec


def test_every_old_path_names_a_module_that_exists():
    missing = [new for new in sorted(set(_moved.MOVED.values())) if importlib.util.find_spec(new) is None]
    assert not missing
