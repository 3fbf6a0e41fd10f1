"""Watch a trained agent: ``python recipes/watch.py <run dir> [--episodes N] [--format mp4|gif | --filmstrip K]``.

Films the run's policy (``policy.pt``) on the recipe's test episodes: episode ``i`` seeded with the
run's ``eval.seed + i``, deterministic actions, stopped at the episode's end, exactly as the final
evaluation plays them (:func:`~torchrl_csirl.analysis.visualization.film_test_episodes`). Works for a driving
run (``csirl_highway.py``, ``imitation_highway.py``), a robotics or locomotion run (``csirl_robotics.py``,
``imitation_robotics.py``, ``train_expert.py``; MuJoCo renders headless through EGL). Writes
``<run dir>/videos/test-episode-<i>.<format>`` (``--out`` elsewhere) and prints one line per episode.

Formats: ``mp4`` (needs ``imageio-ffmpeg``, the ``video`` extra; the default when installed) or
``gif`` (Pillow). ``--filmstrip K`` writes a still instead, ``test-episode-<i>.png``: K pictures from
the reset to the episode's end in one row, captioned with the step (and a locomotion task's torso x,
which its following camera hides). Bad input (not a run directory, no ``policy.pt``, an unknown format) is one
``error:`` line and exit status 2.
"""
from __future__ import annotations

import argparse
import os

from torchrl_csirl.analysis.visualization.video import (
    VIDEO_FORMATS,
    VideoError,
    default_video_format,
)
from torchrl_csirl.run.config import ConfigError
from torchrl_csirl.run.run import run_script

__all__ = ["main", "read_run"]


def read_run(run_dir: str) -> tuple[object, str, int]:
    """The policy of a finished run, its task and its ``eval.seed``.

    Raises:
        ConfigError: not a run directory, or no ``policy.pt`` (saying why there may be none).
    """
    from omegaconf import OmegaConf

    from torchrl_csirl.modules import load_policy

    run_dir = os.path.abspath(os.path.expanduser(run_dir))
    if not os.path.isdir(run_dir):
        raise ConfigError(f"{run_dir}: no such directory (give a run directory, e.g. runs/merge-csirl-s0-...)")
    config_file = os.path.join(run_dir, "config.yaml")
    if not os.path.isfile(config_file):
        raise ConfigError(f"{run_dir}: not a run directory (no config.yaml)")
    if not os.path.isfile(os.path.join(run_dir, "policy.pt")):
        raise ConfigError(
            f"{run_dir}: no policy.pt; it is written when training finishes (an interrupted run: finish it "
            "with checkpoint.resume=<run dir>; the random and expert reference rows have none)")
    cfg = OmegaConf.load(config_file)
    try:
        policy = load_policy(run_dir)
    except ValueError as err:
        raise ConfigError(str(err)) from None
    task = policy.metadata.get("scenario") or cfg.env.task
    seed = int(OmegaConf.select(cfg, "eval.seed", default=1_000_000))
    return policy, task, seed


def main(argv: list[str] | None = None) -> list[str]:
    """Films the episodes; returns the paths written."""
    import torch

    from torchrl_csirl.analysis.visualization import film_test_episodes
    from torchrl_csirl.analysis.visualization.video import describe_rollout

    parser = argparse.ArgumentParser(description="Videos of a trained run's deterministic test episodes.")
    parser.add_argument("run_dir", help="a run directory (with config.yaml and policy.pt)")
    parser.add_argument("--episodes", type=int, default=1, help="test episodes to film (default 1)")
    parser.add_argument("--format", default=None,
                        help=f"{' | '.join(VIDEO_FORMATS)} (default: {default_video_format()} here)")
    parser.add_argument("--seed", type=int, default=None, help="seed of the first episode (default: the run's eval.seed)")
    parser.add_argument("--max-steps", type=int, default=None, help="cut episodes (default: the task's limit)")
    parser.add_argument("--out", default=None, help="where the videos go (default: <run dir>/videos)")
    parser.add_argument("--filmstrip", type=int, default=None, metavar="K",
                        help="write a PNG of K pictures of each episode instead of a video")
    parser.add_argument("--label", default=None, help="the filmstrip's title names this first (default: the run "
                                                      "directory's name)")
    args = parser.parse_args(argv)
    if args.episodes <= 0:
        raise ConfigError(f"--episodes={args.episodes}: must be positive")
    if args.max_steps is not None and args.max_steps <= 0:
        raise ConfigError(f"--max-steps={args.max_steps}: must be positive")
    if args.filmstrip is not None and args.filmstrip < 2:
        raise ConfigError(f"--filmstrip={args.filmstrip}: a filmstrip shows at least 2 pictures")
    if args.filmstrip is not None and args.format is not None:
        raise ConfigError("--filmstrip writes a PNG: give it or --format, not both")
    fmt = args.format or default_video_format()
    if fmt not in VIDEO_FORMATS:
        raise ConfigError(f"--format={fmt}: must be one of {', '.join(VIDEO_FORMATS)}")
    policy, task, seed = read_run(args.run_dir)
    seed = seed if args.seed is None else args.seed
    out = args.out or os.path.join(os.path.abspath(args.run_dir), "videos")
    torch.set_num_threads(1)  # one observation at a time
    paths = []
    films = film_test_episodes(policy, task, out, episodes=args.episodes, seed=seed, fmt=fmt,
                               max_steps=args.max_steps, filmstrip=args.filmstrip,
                               label=args.label or os.path.basename(os.path.abspath(args.run_dir)))
    for i, (path, rollout) in enumerate(films):
        outcome = describe_rollout(rollout)
        rate = "" if outcome["accomplish_rate"] is None else f"accomplish rate {outcome['accomplish_rate']:.3f}, "
        print(f"{path}  ({task}, seed {seed + i}: {outcome['steps']} steps, return {outcome['return']}, {rate}"
              f"success {outcome['success']}, crashed {outcome['crashed']})")
        paths.append(os.fspath(path))
    return paths


if __name__ == "__main__":
    run_script(main, known_errors=(VideoError,))
