"""Pictures of a CSIRL run: learning curve, subgoal curriculum and the scenario with its curriculum.

Every function draws on its own ``matplotlib.figure.Figure`` with an Agg canvas (no pyplot
state, the user's backend is left alone), writes a PNG and returns its :class:`pathlib.Path`.

* :func:`plot_learning_curve`: evaluation accomplish / success rate vs environment frames.
* :func:`plot_subgoal_curriculum`: subgoal index vs frames and the critics' uncertainty profiles.
* :func:`plot_health`: a run's health report in four panels (:mod:`torchrl_csirl.analysis.diagnostics`).
* :func:`render_curriculum`: the highway-env scene with the curriculum trajectory and subgoals.
* :func:`plot_robotics_curriculum`: a robotics task's curriculum (the maze from above, or the
  matching features along the trajectory) with the subgoals.
* :func:`write_video` / :func:`film_test_episodes`: videos (MP4 or GIF) of deterministic test episodes,
  or stills of them (:func:`plot_filmstrip`: a few captioned pictures in one row).
"""
from __future__ import annotations

from torchrl_csirl.analysis.visualization.curves import plot_learning_curve, plot_method_curves, plot_subgoal_curriculum
from torchrl_csirl.analysis.visualization.filmstrip import plot_filmstrip
from torchrl_csirl.analysis.visualization.health import plot_health
from torchrl_csirl.analysis.visualization.robotics import plot_robotics_curriculum
from torchrl_csirl.analysis.visualization.scene import render_curriculum
from torchrl_csirl.analysis.visualization.video import VIDEO_FORMATS, VideoError, film_test_episodes, write_video

__all__ = ["VIDEO_FORMATS", "VideoError", "film_test_episodes", "plot_filmstrip", "plot_health", "plot_learning_curve",
           "plot_method_curves", "plot_robotics_curriculum", "plot_subgoal_curriculum", "render_curriculum", "write_video"]
