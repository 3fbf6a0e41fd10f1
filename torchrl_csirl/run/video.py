"""The video of a run's final evaluation (``eval.video``): its first test episode filmed into
``<run dir>/videos`` and sent to W&B; ``recipes/watch.py`` films more episodes of a finished run."""
from __future__ import annotations

import os
import sys
from typing import Any

__all__ = ["film_final_episode"]


def film_final_episode(run: Any) -> list[str]:
    """Films the final evaluation's first episode (seed ``eval.seed``, deterministic) with the run's
    policy, logs it and returns its path; a machine that cannot render or write it gets a warning
    line instead (the run's results are kept)."""
    from torchrl_csirl.analysis.visualization.video import VideoError, film_test_episodes

    run.mirror.sync()
    directory = os.path.join(run.run_dir, "videos")
    try:
        paths = [os.fspath(path) for path, _ in film_test_episodes(run.mirror.policy, run.spec.name, directory,
                                                                    episodes=1, seed=run.cfg.eval.seed)]
    except VideoError as err:
        print(f"warning: videos are off for this run (its results are kept): {err}", file=sys.stderr)
        return []
    for path in paths:
        run.logger.log_video(path, step=run.trainer.frames)
    return paths
