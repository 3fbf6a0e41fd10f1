"""Which code, packages and machine a run ran on: ``provenance.json`` in the run directory, beside ``config.yaml``.

A new run writes it when its directory is made (a run killed before its summary keeps it too); a resumed run
appends the resuming process's own provenance to ``resumed`` (with the frames it resumed at), so a run continued
at other code says so. The file holds:

* ``code``: ``commit`` (``git rev-parse HEAD`` of the checkout holding the package that ran; None when the
  package is not a tracked file of a git checkout, e.g. an installed wheel, or git is missing), ``dirty``
  (tracked files differ from the commit), ``diff_sha256`` (sha256 of ``git diff HEAD`` when dirty),
  ``untracked`` (how many untracked, not ignored files the checkout holds: new modules a diff does not show);
* ``versions``: python and the installed distributions of :data:`DISTRIBUTIONS` (None when not installed);
* ``machine``: the CPU model, ``torch.get_num_threads()`` when the run started, the platform;
* ``configuration``: ``"config.yaml"``, the fully resolved configuration beside it (written by the same start;
  a resume that changes settings rewrites it and appends the change to ``resumes.jsonl``).

Collecting it takes a few git calls (tens of milliseconds) and never fails a run: what cannot be found is None.
Records made before runs wrote it have no ``provenance.json``: :func:`read_provenance` gives None and the tools say
``provenance: unknown``.

Examples:
    >>> provenance = collect_provenance()
    >>> sorted(provenance), provenance["versions"]["torch"] is not None
    (['code', 'configuration', 'machine', 'versions'], True)
"""
from __future__ import annotations

import hashlib
import importlib.metadata
import json
import os
import platform
import subprocess
from typing import Any

__all__ = ["CODE_FIELDS", "DISTRIBUTIONS", "MACHINE_FIELDS", "PROVENANCE_FILE", "code_fields", "code_state",
           "collect_provenance", "cpu_model", "installed_versions", "machine_fields", "processes", "read_provenance",
           "record_resume_provenance", "write_provenance"]

#: the file a run directory keeps it in
PROVENANCE_FILE = "provenance.json"
#: the distributions whose versions are recorded: the learning stack and every task's package
DISTRIBUTIONS = ("torchrl-csirl", "torch", "torchrl", "tensordict", "numpy", "gymnasium", "highway-env",
                 "gymnasium-robotics", "mujoco", "minari")
#: seconds a git call may take before its field is None
GIT_TIMEOUT_S = 5.0
UNKNOWN_CODE = {"commit": None, "dirty": None, "diff_sha256": None, "untracked": None}


def _git(checkout: str, *args: str) -> bytes | None:
    """``git -C checkout args`` 's stdout, or None when git is missing, fails or times out."""
    try:
        done = subprocess.run(["git", "-C", checkout, *args], capture_output=True, timeout=GIT_TIMEOUT_S, check=False)
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout if done.returncode == 0 else None


def code_state(package_dir: str | None = None) -> dict[str, Any]:
    """``commit``, ``dirty``, ``diff_sha256`` and ``untracked`` of the git checkout holding ``package_dir`` (this
    package's folder by default); every field None when the package is not a tracked file of a checkout.

    Examples:
        >>> import tempfile
        >>> code_state(tempfile.mkdtemp())
        {'commit': None, 'dirty': None, 'diff_sha256': None, 'untracked': None}
    """
    package_dir = os.path.abspath(package_dir or os.path.dirname(os.path.dirname(__file__)))
    tracked = _git(package_dir, "ls-files", "--error-unmatch", "--", "__init__.py")  # a tracked file of a checkout
    head = _git(package_dir, "rev-parse", "HEAD") if tracked else None
    if not head:  # not a checkout, or the package lies untracked in one (an installed wheel in a venv there)
        return dict(UNKNOWN_CODE)
    status = _git(package_dir, "status", "--porcelain", "-z", "--untracked-files=normal")
    entries = [e for e in (status or b"").split(b"\0") if e]
    untracked = sum(e.startswith(b"??") for e in entries) if status is not None else None
    dirty = any(not e.startswith(b"??") for e in entries) if status is not None else None
    diff = _git(package_dir, "diff", "HEAD", "--binary") if dirty else None
    return {"commit": head.decode().strip(), "dirty": dirty,
            "diff_sha256": hashlib.sha256(diff).hexdigest() if diff is not None else None, "untracked": untracked}


def installed_versions(distributions: tuple[str, ...] = DISTRIBUTIONS) -> dict[str, str | None]:
    """``python`` and each distribution's installed version (None when it is not installed).

    Examples:
        >>> installed_versions(("torch", "no-such-distribution"))["no-such-distribution"] is None
        True
    """
    versions: dict[str, str | None] = {"python": platform.python_version()}
    for name in distributions:
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            versions[name] = None
    return versions


def cpu_model() -> str | None:
    """The CPU's model name (``/proc/cpuinfo``'s ``model name``, else the platform's processor), None if unknown."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.partition(":")[2].strip() or None
    except OSError:
        pass
    return platform.processor() or platform.machine() or None


def _machine() -> dict[str, Any]:
    try:
        import torch

        threads: int | None = torch.get_num_threads()
    except Exception:  # noqa: BLE001 - provenance never fails a run
        threads = None
    return {"cpu": cpu_model(), "cpu_count": os.cpu_count(), "torch_threads": threads, "platform": platform.platform()}


def collect_provenance() -> dict[str, Any]:
    """This process's provenance: ``code``, ``versions``, ``machine`` and ``configuration`` (module docstring)."""
    try:
        code = code_state()
    except Exception:  # noqa: BLE001 - provenance never fails a run
        code = dict(UNKNOWN_CODE)
    return {"code": code, "versions": installed_versions(), "machine": _machine(), "configuration": "config.yaml"}


def write_provenance(run_dir: str) -> dict[str, Any] | None:
    """Writes a new run's ``provenance.json``; returns it (None, with a warning, when it cannot be written)."""
    provenance = collect_provenance()
    return provenance if _save(run_dir, provenance) else None


def record_resume_provenance(run_dir: str, frames: int) -> dict[str, Any] | None:
    """Appends this process's provenance, at ``frames``, to the run's ``resumed`` list (a run started before
    provenance existed gets a file with ``code: null`` at the top and this process in ``resumed``)."""
    provenance = read_provenance(run_dir) or {"code": None, "versions": None, "machine": None,
                                              "configuration": "config.yaml"}
    provenance.setdefault("resumed", []).append({"frames": int(frames), **collect_provenance()})
    return provenance if _save(run_dir, provenance) else None


def _save(run_dir: str, provenance: dict[str, Any]) -> bool:
    path = os.path.join(run_dir, PROVENANCE_FILE)
    try:
        with open(f"{path}.tmp", "w") as f:
            json.dump(provenance, f, indent=2)
        os.replace(f"{path}.tmp", path)
    except OSError as err:
        import warnings

        warnings.warn(f"{path}: provenance not written ({err})", stacklevel=2)
        return False
    return True


def read_provenance(run_dir: str) -> dict[str, Any] | None:
    """A run's (or record's) ``provenance.json``, None when it has none (made before runs wrote it) or it is not JSON."""
    try:
        with open(os.path.join(run_dir, PROVENANCE_FILE)) as f:
            return json.load(f)
    except (OSError, json.JSONDecodeError):
        return None


def processes(provenance: dict[str, Any]) -> list[dict[str, Any]]:
    """The provenance of each process that trained the run: the start, then each resume.

    Examples:
        >>> [p["code"]["commit"] for p in processes({"code": {"commit": "a"}, "resumed": [{"code": {"commit": "b"}}]})]
        ['a', 'b']
    """
    return [provenance, *provenance.get("resumed", [])]


#: the fields of a run's code: a difference in any is a difference in what ran
CODE_FIELDS = ("code.commit", "code.dirty", "code.diff_sha256")
#: the fields of a run's machine: shown beside a comparison, no change in what ran
MACHINE_FIELDS = ("machine.cpu", "machine.torch_threads")


def _field(process: dict[str, Any], dotted: str) -> Any:
    section, _, name = dotted.partition(".")
    return (process.get(section) or {}).get(name)


def _over_processes(provenance: dict[str, Any], dotted: str) -> Any:
    """``dotted``'s value over the run's processes: the one value, or ``"a -> b"`` where a resume changed it."""
    values = list(dict.fromkeys(json.dumps(_field(p, dotted)) for p in processes(provenance)))
    return json.loads(values[0]) if len(values) == 1 else " -> ".join(values)


def code_fields(provenance: dict[str, Any]) -> dict[str, Any]:
    """The run's code as flat fields: :data:`CODE_FIELDS` and ``versions.<distribution>`` (each ``"a -> b"``
    where a resume ran other code than the start).

    Examples:
        >>> prov = {"code": {"commit": "abc", "dirty": False}, "versions": {"torch": "2.14.1"},
        ...         "resumed": [{"code": {"commit": "def", "dirty": False}, "versions": {"torch": "2.14.1"}}]}
        >>> code_fields(prov)
        {'code.commit': '"abc" -> "def"', 'code.dirty': False, 'code.diff_sha256': None, 'versions.torch': '2.14.1'}
    """
    names = dict.fromkeys(n for p in processes(provenance) for n in (p.get("versions") or {}))
    return {dotted: _over_processes(provenance, dotted) for dotted in (*CODE_FIELDS, *(f"versions.{n}" for n in names))}


def machine_fields(provenance: dict[str, Any]) -> dict[str, Any]:
    """The run's machine as flat fields (:data:`MACHINE_FIELDS`)."""
    return {dotted: _over_processes(provenance, dotted) for dotted in MACHINE_FIELDS}
