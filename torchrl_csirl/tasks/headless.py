"""Headless MuJoCo pictures: the OpenGL backend picked before an environment renders."""
from __future__ import annotations

import os

__all__ = ["ensure_headless_gl"]


def ensure_headless_gl(render_mode: str | None) -> None:
    """Pick MuJoCo's EGL backend for ``rgb_array`` pictures unless ``MUJOCO_GL`` is set (a machine
    without a display otherwise fails in GLFW).

    Examples:
        >>> ensure_headless_gl("rgb_array")
        >>> os.environ["MUJOCO_GL"] in ("egl", "osmesa", "glfw")
        True
    """
    if render_mode == "rgb_array":
        os.environ.setdefault("MUJOCO_GL", "egl")
