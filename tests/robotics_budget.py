"""The tiny budget of the robotics recipes' end-to-end tests: one worker with one environment,
200-frame batches (one Relocate episode), one evaluation episode, no logger."""
from __future__ import annotations

TINY_ROBOTICS_RUN = [
    "collector.total_frames=400",
    "collector.frames_per_batch=200",
    "collector.cut_episodes=true",  # shorter than the episode limits
    "collector.num_workers=1",
    "collector.envs_per_worker=1",
    "collector.init_random_frames=200",
    "collector.main_threads=1",
    "replay_buffer.warmup_frames=200",
    "optim.utd_ratio=0.1",
    "eval.episodes=1",
    "eval.final_episodes=1",
    "eval.video=false",  # MuJoCo on a software renderer: ~0.1-0.4 s a frame (tests/test_video.py films some)
    "logger.backend=none",
    "logger.progress_bar=false",
]
