"""Where the package's shipped files lie; a leaf every subpackage may import (it imports nothing
of the package), so that reading a shipped file does not tie one subpackage to another.

Examples:
    >>> import os
    >>> os.path.isdir(os.path.join(EXPERTS_DIR, "antmaze-umaze"))
    True
"""
from __future__ import annotations

import os

__all__ = ["EXPERTS_DIR"]

EXPERTS_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "experts")
"""Folder of the shipped expert files: demonstrations (``<task>/<curriculum>_25.npz``,
:mod:`torchrl_csirl.data.shipped`) and the robotics experts' weights (``relocate/``,
``antmaze-umaze/``, :mod:`torchrl_csirl.tasks.robotics`)."""
