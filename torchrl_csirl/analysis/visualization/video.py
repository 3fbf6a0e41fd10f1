"""Videos of a policy on its task: deterministic test episodes filmed headless, written as MP4 or GIF.

* :func:`write_video`: frames (``[T, H, W, 3]`` uint8) to ``.gif`` (Pillow) or ``.mp4`` (H.264 through
  ``imageio-ffmpeg``, whose wheel ships the ffmpeg binary: the ``video`` extra).
* :func:`make_render_env`: the task's TorchRL environment rendering ``rgb_array`` pictures headless
  (driving: highway-env's offscreen surface; robotics: MuJoCo through ``MUJOCO_GL``, EGL by default),
  checked once so that a machine that cannot render says so in one :class:`VideoError`.
* :func:`film_episode` / :func:`film_test_episodes`: the recipe's test episodes (episode ``i``
  seeded with ``seed + i``, the deterministic policy, stopped at the episode's end, as
  :func:`~torchrl_csirl.trainers.evaluate_policy` plays them), one picture per kept step.

TorchRL's own writers are not used: ``CSVLogger(video_format="mp4")`` needs ``torchcodec`` (and the
system's FFmpeg libraries), and a ``TransformedEnv`` with ``PixelRenderTransform`` seeds the
reset differently from the evaluation's plain environment, so it would not film the same episodes.
The frames are taken with ``env.rollout(callback=...)`` from the same environment instead.
"""
from __future__ import annotations

import math
import os
from collections.abc import Collection, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import torch

from torchrl_csirl.analysis.visualization.filmstrip import caption_steps, filmstrip_steps, plot_filmstrip

__all__ = [
    "VIDEO_FORMATS",
    "VideoError",
    "default_video_format",
    "describe_rollout",
    "film_episode",
    "film_test_episodes",
    "make_render_env",
    "render_failure_hint",
    "video_format_available",
    "write_video",
]

#: the formats :func:`write_video` writes (the file suffix picks one)
VIDEO_FORMATS = ("mp4", "gif")
#: fastest playback of a filmed episode; faster tasks keep every k-th step (:func:`frame_stride`)
MAX_FPS = 25
#: what installs the robotics tasks' headless rendering, for the error message
MUJOCO_GL_HELP = ("MuJoCo renders headless through EGL (MUJOCO_GL=egl, the default here): install the EGL "
                  "libraries (Debian/Ubuntu: apt-get install libegl1 libegl-mesa0), or use OSMesa "
                  "(apt-get install libosmesa6, then MUJOCO_GL=osmesa)")
MP4_HELP = ("writing .mp4 needs imageio-ffmpeg (pip install -e '.[video]', or pip install imageio-ffmpeg); "
            ".gif needs nothing more")


class VideoError(RuntimeError):
    """A video that cannot be made here: no headless rendering, or no writer for the format."""


def video_format_available(fmt: str) -> bool:
    """Whether :func:`write_video` can write ``fmt`` here (``gif``: always; ``mp4``: with ``imageio-ffmpeg``).

    Examples:
        >>> video_format_available("gif")
        True
    """
    if fmt == "gif":
        return True
    if fmt == "mp4":
        try:
            import imageio_ffmpeg  # noqa: F401
        except ImportError:
            return False
        return True
    return False


def default_video_format() -> str:
    """``mp4`` when it can be written here (much smaller files), else ``gif``."""
    return "mp4" if video_format_available("mp4") else "gif"


def _as_frames(frames: Any) -> np.ndarray:
    if isinstance(frames, torch.Tensor):
        frames = frames.detach().cpu().numpy()
    array = np.stack([np.asarray(f) for f in frames]) if isinstance(frames, (list, tuple)) else np.asarray(frames)
    if array.ndim != 4 or array.shape[-1] != 3 or array.shape[0] == 0:
        raise ValueError(f"expected frames of shape [T, H, W, 3] with T > 0, got {array.shape}.")
    if array.dtype != np.uint8:
        array = np.clip(array, 0, 255).astype(np.uint8)
    return array


def write_video(frames: Any, path: str | os.PathLike, *, fps: float = 10.0) -> Path:
    """Writes RGB frames as a video; the suffix of ``path`` (``.mp4`` or ``.gif``) picks the format.

    GIF goes through Pillow; MP4 (H.264, yuv420p; odd frame sizes padded by one edge pixel row or
    column) through ``imageio-ffmpeg``.

    Args:
        frames: ``[T, H, W, 3]`` array or tensor, or a sequence of ``[H, W, 3]`` pictures (uint8;
            other types are clipped to ``[0, 255]``).
        path: the file to write (parent folders are created).
        fps: frames per second of the playback.

    Returns:
        The path written.

    Raises:
        ValueError: an unknown suffix or frames of the wrong shape.
        VideoError: ``.mp4`` without ``imageio-ffmpeg`` installed.

    Examples:
        >>> import tempfile
        >>> frames = np.zeros((3, 8, 12, 3), dtype=np.uint8); frames[1, :, :6] = 255
        >>> out = write_video(frames, os.path.join(tempfile.mkdtemp(), "clip.gif"), fps=5)
        >>> from PIL import Image
        >>> with Image.open(out) as gif:
        ...     gif.n_frames, gif.size
        (3, (12, 8))
    """
    path = Path(path)
    fmt = path.suffix.lower().lstrip(".")
    if fmt not in VIDEO_FORMATS:
        raise ValueError(f"{str(path)!r}: unknown video format {path.suffix!r}; expected one of "
                         f"{', '.join('.' + f for f in VIDEO_FORMATS)}.")
    if fps <= 0:
        raise ValueError(f"fps must be positive, got {fps}.")
    array = _as_frames(frames)
    path.parent.mkdir(parents=True, exist_ok=True)
    if fmt == "gif":
        _write_gif(array, path, fps)
    else:
        _write_mp4(array, path, fps)
    return path


def _write_gif(array: np.ndarray, path: Path, fps: float) -> None:
    from PIL import Image

    images = [Image.fromarray(frame) for frame in array]
    duration = max(int(round(1000.0 / fps / 10.0)) * 10, 20)  # GIF delays are in 10 ms; < 20 ms plays slow
    images[0].save(path, format="GIF", save_all=True, append_images=images[1:], duration=duration, loop=0,
                   optimize=False)


def _write_mp4(array: np.ndarray, path: Path, fps: float) -> None:
    try:
        import imageio_ffmpeg
    except ImportError:
        raise VideoError(MP4_HELP) from None
    pad_h, pad_w = array.shape[1] % 2, array.shape[2] % 2  # yuv420p: even sizes
    if pad_h or pad_w:
        array = np.pad(array, ((0, 0), (0, pad_h), (0, pad_w), (0, 0)), mode="edge")
    writer = imageio_ffmpeg.write_frames(os.fspath(path), (array.shape[2], array.shape[1]), fps=fps,
                                         codec="libx264", macro_block_size=1, ffmpeg_log_level="error")
    writer.send(None)  # start ffmpeg
    try:
        for frame in array:
            writer.send(np.ascontiguousarray(frame))
    finally:
        writer.close()


# ---------------------------------------------------------------------------------------- filming
def _lighten_mujoco(env: Any) -> None:
    """Turns off shadows and reflections of a MuJoCo task's offscreen viewer (about 3x faster on a
    software renderer); a driving scene is left alone."""
    gym_env = getattr(env, "_env", None)
    inner = getattr(getattr(getattr(gym_env, "unwrapped", None), "_inner", None), "unwrapped", None)
    holder = getattr(inner, "ant_env", inner)  # AntMaze renders through its ant's MuJoCo env
    renderer = getattr(holder, "mujoco_renderer", None)
    if renderer is None:
        return
    import mujoco

    viewer = renderer._get_viewer("rgb_array")
    for flag in (mujoco.mjtRndFlag.mjRND_SHADOW, mujoco.mjtRndFlag.mjRND_REFLECTION):
        viewer.scn.flags[flag] = 0


def make_render_env(task: str) -> Any:
    """The task's TorchRL environment (:func:`~torchrl_csirl.tasks.make_env`) with headless ``rgb_array``
    rendering, checked with one picture.

    Raises:
        VideoError: when the task cannot be rendered here, saying why (:func:`render_failure_hint`):
            an environment that takes no ``render_mode``, no EGL for MuJoCo, ...
    """
    from torchrl_csirl.tasks import make_env, resolve_scenario

    spec = resolve_scenario(task)
    try:
        env = make_env(task, render_mode="rgb_array")
        env.reset()
        _lighten_mujoco(env)
        picture = env.render()
    except Exception as err:  # noqa: BLE001 - whatever the GL stack raises, said in one line
        what = " ".join(f"{type(err).__name__}: {err}".split())
        raise VideoError(f"cannot render {task} headless here ({what}). {render_failure_hint(err, spec.family)}.") from None
    if not isinstance(picture, np.ndarray) or picture.ndim != 3:
        raise VideoError(f"{task}: render() gave {type(picture).__name__}, not an RGB picture.")
    return env


#: words of an error raised by MuJoCo's OpenGL back-ends
_GL_WORDS = ("EGL", "OpenGL", "OSMesa", "GLFW", "MUJOCO_GL", "mujoco")


def render_failure_hint(error: BaseException, family: str) -> str:
    """What to do about an environment that could not render, from its error and its task family.

    Examples:
        >>> render_failure_hint(TypeError("__init__() got an unexpected keyword argument 'render_mode'"), "custom")[:55]
        "the task's environment takes no render_mode argument, s"
        >>> render_failure_hint(RuntimeError("cannot initialize EGL"), "gymnasium").startswith("MuJoCo renders headless")
        True
    """
    text = str(error)
    if isinstance(error, TypeError) and "render_mode" in text:
        return ("the task's environment takes no render_mode argument, so it cannot draw pictures: give its "
                "constructor a render_mode and make render() return an RGB array")
    if family == "driving":
        return "highway-env renders with pygame offscreen (SDL_VIDEODRIVER=dummy)"
    if family in ("robotics", "locomotion") or any(word in text for word in _GL_WORDS):
        return MUJOCO_GL_HELP
    return "the task's environment could not draw an rgb_array picture (its render() failed)"


def frame_stride(dt: float, max_fps: float = MAX_FPS) -> int:
    """Steps per filmed picture, so that real-time playback stays at most ``max_fps`` pictures a second.

    Examples:
        >>> frame_stride(0.2), frame_stride(0.05), frame_stride(0.01)
        (1, 1, 4)
    """
    return max(1, math.ceil((1.0 / dt) / max_fps - 1e-9))


@torch.no_grad()
def film_episode(env: Any, policy: Any, *, seed: int, max_steps: int, stride: int = 1,
                 steps: Collection[int] | None = None) -> tuple[Any, np.ndarray]:
    """Plays one seeded episode with the deterministic ``policy`` on a :func:`make_render_env` environment.

    The episode is the one :func:`~torchrl_csirl.trainers.evaluate_policy` plays with this seed
    (``env.set_seed(seed)``, reset, rollout stopped at the episode's end).

    Args:
        env: a :func:`make_render_env` environment.
        policy: the actor.
        seed: the episode's seed.
        max_steps: the episode's limit.
        stride: keep the picture after every ``stride``-th step.
        steps: keep the pictures after these steps only (``stride`` is then ignored).

    Returns:
        The rollout and its pictures ``[K, H, W, 3]``: after the reset, then after every ``stride``-th
        step (or each of ``steps``), and after the last step.
    """
    from torchrl.envs import ExplorationType, set_exploration_type

    frames: list[np.ndarray] = []
    done = [0]

    def take(e: Any, _td: Any) -> None:
        done[0] += 1
        if (done[0] in steps) if steps is not None else (done[0] % stride == 0):
            frames.append(e.render())

    with set_exploration_type(ExplorationType.DETERMINISTIC):
        env.set_seed(seed)
        start = env.reset()
        frames.append(env.render())
        rollout = env.rollout(max_steps, policy, auto_reset=False, tensordict=start, break_when_any_done=True,
                              callback=take)
    frames.append(env.render())  # rollout's callback does not run after the last step
    return rollout, np.stack(frames)


def film_test_episodes(policy: Any, task: str, directory: str | os.PathLike, *, episodes: int = 1,
                       seed: int = 1_000_000, fmt: str | None = None, max_steps: int | None = None,
                       prefix: str = "test-episode", filmstrip: int | None = None,
                       label: str | None = None) -> Iterator[tuple[Path, Any]]:
    """Films the recipe's test episodes of ``task`` into ``directory``, one file each.

    Episode ``i`` is seeded with ``seed + i``; files are ``<prefix>-<i>.<fmt>``, played in real time
    (at most :data:`MAX_FPS` pictures a second: faster tasks keep every k-th step), or, with
    ``filmstrip=N``, ``<prefix>-<i>.png``: N pictures from the reset to the episode's end in one row
    (:mod:`~torchrl_csirl.analysis.visualization.filmstrip`).

    Args:
        policy: the actor (e.g. :func:`~torchrl_csirl.modules.load_policy`).
        task: the task name.
        directory: where the files go.
        episodes: how many test episodes.
        seed: seed of the first episode (the recipe's ``eval.seed``).
        fmt: ``mp4`` or ``gif`` (None: :func:`default_video_format`).
        max_steps: episode limit (None: the task's).
        prefix: file name prefix.
        filmstrip: write a still of this many pictures (at least 2) instead of a video.
        label: what the still's title names first (e.g. the run), before the task, seed and return.

    Yields:
        ``(path, rollout)`` per episode, as each file is written.

    Raises:
        VideoError: no headless rendering or no writer for ``fmt`` here.
    """
    from torchrl_csirl.tasks import resolve_scenario

    spec = resolve_scenario(task)
    limit = max_steps or spec.max_steps
    if filmstrip is not None:
        shown = filmstrip_steps(limit, filmstrip)  # checks the count before anything renders
    else:
        fmt = fmt or default_video_format()
        if fmt not in VIDEO_FORMATS:
            raise ValueError(f"unknown video format {fmt!r}; expected one of {VIDEO_FORMATS}.")
        if not video_format_available(fmt):
            raise VideoError(MP4_HELP)
    stride = frame_stride(spec.dt)
    env = make_render_env(task)
    try:
        for i in range(episodes):
            if filmstrip is None:
                rollout, frames = film_episode(env, policy, seed=seed + i, max_steps=limit, stride=stride)
                path = write_video(frames, Path(directory) / f"{prefix}-{i}.{fmt}", fps=1.0 / (spec.dt * stride))
            else:
                rollout, frames = film_episode(env, policy, seed=seed + i, max_steps=limit, steps=set(shown))
                path = _write_still(rollout, frames, shown, Path(directory) / f"{prefix}-{i}.png", spec,
                                    f"{label + ': ' if label else ''}{task}, seed {seed + i}")
            yield path, rollout
    finally:
        env.close()


def _write_still(rollout: Any, frames: np.ndarray, shown: list[int], path: Path, spec: Any, title: str) -> Path:
    """The filmstrip of one filmed episode: the pictures after the reset, the ``shown`` steps it lived
    through and its last step, captioned; the title ends with the episode's return."""
    length = int(rollout.shape[-1])
    steps = [0, *(s for s in shown if 0 < s < length), length]
    outcome = describe_rollout(rollout)
    if outcome["return"] is not None:
        title += f", return {outcome['return']:.0f} in {length} steps"
    return plot_filmstrip(frames, path, captions=caption_steps(rollout, steps, dict(getattr(spec, "observation_layout", {}))),
                          title=title)


def describe_rollout(rollout: Any) -> dict[str, Any]:
    """Steps, return, outcome flags and progress of a filmed episode (for a one-line report; the accomplish
    rate is ``None`` for a task without a route, e.g. locomotion)."""
    from torchrl_csirl.tasks import accomplish_rate_from_rollout, success_from_rollout

    keys = rollout.keys(True)
    has_distance = "distance_to_finish" in keys and ("next", "distance_to_finish") in keys  # none in locomotion
    return {
        "steps": int(rollout.shape[-1]),
        "return": round(float(rollout["next", "reward"].sum()), 1) if ("next", "reward") in keys else None,
        "accomplish_rate": round(float(accomplish_rate_from_rollout(rollout)), 3) if has_distance else None,
        "success": bool(success_from_rollout(rollout)),
        "crashed": bool(rollout["next", "crashed"].any()) if ("next", "crashed") in keys else False,
    }
