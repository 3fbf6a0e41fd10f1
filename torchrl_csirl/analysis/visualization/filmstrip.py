"""A still of an episode: a few of its pictures side by side, each captioned with its step (and, on a
locomotion task, the torso's x: its camera follows the body, so the picture alone cannot tell running
from standing still).

* :func:`filmstrip_steps`: the evenly spaced steps a strip of ``count`` pictures shows.
* :func:`caption_steps`: ``"step k"`` captions, with the torso's x where the task's observation has one.
* :func:`plot_filmstrip`: the pictures in one row, written as PNG.

:func:`~torchrl_csirl.analysis.visualization.video.film_test_episodes` (``filmstrip=N``) and
``recipes/watch.py --filmstrip N`` film the test episodes with these.
"""
from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from torchrl_csirl.analysis.visualization._figure import new_figure, save_png

__all__ = ["caption_steps", "filmstrip_steps", "plot_filmstrip"]

#: width of one picture of a strip, in pixels of the PNG
PANEL_PX = 220


def filmstrip_steps(max_steps: int, count: int) -> list[int]:
    """``count`` steps from the reset (step 0) to ``max_steps``, evenly spaced and rounded.

    Examples:
        >>> filmstrip_steps(1000, 6)
        [0, 200, 400, 600, 800, 1000]
        >>> filmstrip_steps(8, 4)
        [0, 3, 5, 8]
    """
    if count < 2:
        raise ValueError(f"a filmstrip shows at least 2 pictures (the reset and the last step), got {count}.")
    if max_steps < 1:
        raise ValueError(f"max_steps must be positive, got {max_steps}.")
    return sorted({int(round(s)) for s in np.linspace(0, max_steps, count)})


def caption_steps(rollout: Any, steps: Sequence[int], layout: dict[str, tuple[int, int]] | None = None) -> list[str]:
    """Captions of the pictures after ``steps`` of ``rollout`` (step 0: the reset): ``"step k"``, and
    ``"x 12.3 m"`` when ``layout`` (a task's ``observation_layout``) has an ``"x"`` entry.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> obs = torch.arange(4.0).unsqueeze(-1)  # x = 0, 1, 2, 3 before steps 1..4
        >>> rollout = TensorDict({"observation": obs, ("next", "observation"): obs + 1}, [4])
        >>> caption_steps(rollout, [0, 2, 4], {"x": (0, 1)})
        ['step 0, x 0.0 m', 'step 2, x 2.0 m', 'step 4, x 4.0 m']
    """
    x_at = (layout or {}).get("x", (None,))[0]
    captions = []
    for step in steps:
        caption = f"step {step}"
        if x_at is not None:
            observation = rollout["observation"][0] if step == 0 else rollout["next", "observation"][step - 1]
            caption += f", x {float(observation[x_at]):.1f} m"
        captions.append(caption)
    return captions


def plot_filmstrip(frames: Any, path: str | os.PathLike, *, captions: Sequence[str] | None = None,
                   title: str | None = None) -> Path:
    """Writes ``frames`` (``[K, H, W, 3]`` uint8) in one row as a PNG, each with its caption.

    Args:
        frames: the pictures, left to right.
        path: the ``.png`` to write (parent folders are created).
        captions: one per picture (None: none).
        title: above the row (None: none).

    Returns:
        The path written.

    Examples:
        >>> import tempfile
        >>> frames = np.zeros((3, 40, 60, 3), dtype=np.uint8)
        >>> out = plot_filmstrip(frames, os.path.join(tempfile.mkdtemp(), "strip.png"), captions=["a", "b", "c"])
        >>> from PIL import Image
        >>> Image.open(out).size
        (660, 177)
    """
    frames = np.asarray(frames)
    if frames.ndim != 4 or frames.shape[-1] != 3 or frames.shape[0] == 0:
        raise ValueError(f"expected frames of shape [K, H, W, 3] with K > 0, got {frames.shape}.")
    if captions is not None and len(captions) != len(frames):
        raise ValueError(f"{len(captions)} captions for {len(frames)} pictures.")
    count, height, width = frames.shape[:3]
    panel_h = int(round(PANEL_PX * height / width))
    caption_h, title_h, bottom = 20 * (captions is not None), 30 * bool(title), 10
    total_h = panel_h + caption_h + title_h + bottom
    fig = new_figure(PANEL_PX * count, total_h)
    if title:
        fig.suptitle(title, fontsize=10, y=1 - 8 / total_h, va="top")
    for i, frame in enumerate(frames):
        ax = fig.add_axes((i / count, bottom / total_h, 1 / count, panel_h / total_h))
        ax.imshow(frame)
        ax.set_axis_off()
        if captions is not None:
            ax.set_title(captions[i], fontsize=8)
    return save_png(fig, path)
