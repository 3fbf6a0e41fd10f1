"""Videos: the writers (gif, mp4), filming a robotics task headless, and recipes/watch.py's input checks
(a driving run is filmed in tests/test_recipe.py, on its trained run)."""
from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
import torch
from omegaconf import OmegaConf
from PIL import Image

from torchrl_csirl.analysis.visualization import VideoError, write_video
from torchrl_csirl.analysis.visualization.filmstrip import PANEL_PX, filmstrip_steps
from torchrl_csirl.analysis.visualization.video import (
    frame_stride,
    make_render_env,
    video_format_available,
)
from torchrl_csirl.methods.csirl import CSIRL_RECIPE
from torchrl_csirl.modules import make_actor, save_policy
from torchrl_csirl.run.config import ConfigError
from torchrl_csirl.scripts import watch

RECIPES = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "recipes")


def _frames(n=4, h=7, w=9):
    frames = np.zeros((n, h, w, 3), dtype=np.uint8)
    for i in range(n):
        frames[i, :, : i + 1] = 255
    return frames


def test_gif_and_mp4_are_written_from_frames(tmp_path):
    gif = write_video(_frames(), tmp_path / "a.gif", fps=10)
    with Image.open(gif) as image:
        assert (image.n_frames, image.size) == (4, (9, 7))
        assert image.info["duration"] == 100
    if not video_format_available("mp4"):
        pytest.skip("imageio-ffmpeg is not installed (the video extra)")
    mp4 = write_video(list(_frames()), tmp_path / "sub" / "a.mp4", fps=10)  # odd sizes: padded
    with open(mp4, "rb") as f:
        assert f.read(12)[4:8] == b"ftyp"


def test_bad_frames_and_formats_are_refused(tmp_path):
    with pytest.raises(ValueError, match="unknown video format '.avi'"):
        write_video(_frames(), tmp_path / "a.avi")
    with pytest.raises(ValueError, match=r"\[T, H, W, 3\]"):
        write_video(np.zeros((2, 4, 4)), tmp_path / "a.gif")
    assert frame_stride(0.01) == 4 and frame_stride(1.0) == 1


def test_a_machine_that_cannot_render_says_what_to_install(monkeypatch):
    import torchrl_csirl.tasks as envs

    def no_gl(*args, **kwargs):
        raise AttributeError("'NoneType' object has no attribute 'eglQueryString'")

    monkeypatch.setattr(envs, "make_env", no_gl)
    with pytest.raises(VideoError, match="cannot render relocate headless here .*apt-get install libegl1"):
        make_render_env("relocate")


def _pendulum_without_render_mode(**overrides):
    """A user's env factory that takes no ``render_mode`` (what a plain ``gym.Env`` subclass often is)."""
    if overrides:
        raise TypeError(f"_pendulum_without_render_mode() got an unexpected keyword argument {next(iter(overrides))!r}")
    from torchrl_csirl.tasks import make_gymnasium_env

    return make_gymnasium_env("Pendulum-v1", "none")


def test_an_env_without_render_mode_is_named_as_the_cause_and_its_run_has_videos_off(tmp_path, capsys):
    from types import SimpleNamespace

    from torchrl_csirl.run.video import film_final_episode
    from torchrl_csirl.tasks import TaskSpec, register_task

    spec = TaskSpec(name="pendulum-no-render", obs_dim=3, action_dim=1, max_steps=200, finish_position=None,
                    ego_feature_indices=(0, 1, 2), position_feature_indices=(0, 1), matching_scale=1.0)
    register_task(spec, _pendulum_without_render_mode, replace=True)
    with pytest.raises(VideoError, match="takes no render_mode argument") as err:
        make_render_env(spec.name)
    assert "EGL" not in str(err.value) and "MuJoCo" not in str(err.value)
    run = SimpleNamespace(mirror=SimpleNamespace(sync=lambda: None, policy=make_actor(3, 1)), run_dir=str(tmp_path),
                          spec=spec, cfg=SimpleNamespace(eval=SimpleNamespace(seed=0)))
    assert film_final_episode(run) == []
    warning = capsys.readouterr().err.strip()
    assert warning.startswith("warning: videos are off for this run") and "takes no render_mode" in warning
    assert "\n" not in warning


def _run_dir(tmp_path, task="relocate", policy=True):
    """A run directory with the task's configuration and, with ``policy``, an untrained actor (seeded: the
    episode it films does not depend on the tests run before)."""
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    cfg = CSIRL_RECIPE.load_config([f"env.task={task}", "eval.seed=7"])
    OmegaConf.save(cfg, run_dir / "config.yaml")
    if policy:
        from torchrl_csirl.tasks import resolve_scenario

        spec = resolve_scenario(task)
        torch.manual_seed(0)
        save_policy(make_actor(spec.obs_dim, spec.action_dim), run_dir / "policy.pt", obs_dim=spec.obs_dim,
                    action_dim=spec.action_dim, scenario=task)
    return run_dir


@pytest.mark.parametrize("task, pictures, picture_ms", [
    ("relocate", 3, 40),  # 10 ms steps: the reset, step 4 and step 8 (25 pictures a second)
    ("antmaze-umaze", 9, 50),  # 50 ms steps: the reset and every step
    ("hopper", 3, 40),  # 8 ms steps: the reset, step 5 and the last (gymnasium's own env: EGL picked, no route)
])
def test_watch_films_a_robotics_run_headless(tmp_path, capsys, monkeypatch, task, pictures, picture_ms):
    """Counted by playing time: Pillow merges identical consecutive pictures into one of their summed duration
    (an untrained ant barely moving can give two, depending on the float rounding of its actions)."""
    from PIL import ImageSequence

    monkeypatch.delenv("MUJOCO_GL", raising=False)  # a fresh shell: the task picks EGL itself
    run_dir = _run_dir(tmp_path, task)
    paths = watch.main([str(run_dir), "--format", "gif", "--max-steps", "8"])
    assert paths == [str(run_dir / "videos" / "test-episode-0.gif")]
    with Image.open(paths[0]) as image:
        durations = [picture.info["duration"] for picture in ImageSequence.Iterator(image)]
    assert sum(durations) == pictures * picture_ms and len(durations) > 1
    assert f"{task}, seed 7: 8 steps" in capsys.readouterr().out


def test_watch_filmstrip_is_a_captioned_still_of_the_episode(tmp_path, capsys):
    """``--filmstrip 3`` on a hopper run cut at 8 steps: a PNG of the reset, step 4 and step 8 in one row,
    captioned with the torso's x; its title names the label."""
    run_dir = _run_dir(tmp_path, "hopper")
    paths = watch.main([str(run_dir), "--filmstrip", "3", "--max-steps", "8", "--label", "untrained"])
    assert paths == [str(run_dir / "videos" / "test-episode-0.png")]
    with Image.open(paths[0]) as image:
        assert image.size[0] == 3 * PANEL_PX
    assert "hopper, seed 7: 8 steps" in capsys.readouterr().out
    assert filmstrip_steps(8, 3) == [0, 4, 8]
    with pytest.raises(ConfigError, match="--filmstrip=1: a filmstrip shows at least 2 pictures"):
        watch.main([str(run_dir), "--filmstrip", "1"])
    with pytest.raises(ConfigError, match="give it or --format, not both"):
        watch.main([str(run_dir), "--filmstrip", "3", "--format", "gif"])


def test_locomotion_pictures_follow_the_body():
    """gymnasium's default free camera stays at the start; the locomotion tasks render through the
    model's ``track`` camera."""
    import mujoco

    from torchrl_csirl.tasks import make_env

    env = make_env("halfcheetah", render_mode="rgb_array")
    renderer = env._env.unwrapped.mujoco_renderer
    assert renderer.camera_id == mujoco.mj_name2id(renderer.model, mujoco.mjtObj.mjOBJ_CAMERA, "track") != -1
    env.close()


def test_watch_refuses_what_is_not_a_finished_run(tmp_path):
    with pytest.raises(ConfigError, match="no such directory"):
        watch.main([str(tmp_path / "nothing")])
    with pytest.raises(ConfigError, match=r"not a run directory \(no config.yaml\)"):
        watch.main([str(tmp_path)])
    run_dir = _run_dir(tmp_path, policy=False)
    with pytest.raises(ConfigError, match="no policy.pt; it is written when training finishes"):
        watch.main([str(run_dir)])
    with pytest.raises(ConfigError, match="--format=avi: must be one of mp4, gif"):
        watch.main([str(run_dir), "--format", "avi"])
    with pytest.raises(ConfigError, match="--episodes=0: must be positive"):
        watch.main([str(run_dir), "--episodes", "0"])


def test_watch_bad_input_is_one_error_line_and_exit_status_2(tmp_path):
    env = {**os.environ, "MPLBACKEND": "Agg"}
    proc = subprocess.run([sys.executable, os.path.join(RECIPES, "watch.py"), str(tmp_path)], capture_output=True,
                          text=True, env=env, timeout=300)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines()[-1] == f"error: {tmp_path}: not a run directory (no config.yaml)"


def test_headless_pictures_draw_without_an_sdl_error():
    """On a machine without a display, a driving picture is drawn and SDL prints nothing (no
    ``error: XDG_RUNTIME_DIR is invalid``): the package picks SDL's offscreen driver."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("DISPLAY", "WAYLAND_DISPLAY", "SDL_VIDEODRIVER", "XDG_RUNTIME_DIR")}
    code = ("from torchrl_csirl.tasks import make_env; "
            "env = make_env('merge', render_mode='rgb_array'); env.reset(); "
            "image = env.render(); print(image.shape, float(image.std()))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=False,
                          cwd=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    assert proc.returncode == 0, proc.stderr
    assert "XDG_RUNTIME_DIR" not in proc.stderr and "error" not in proc.stderr.lower(), proc.stderr
    _, std = proc.stdout.split(")")
    assert std and float(std) > 1.0  # a drawn scene, not a blank frame
