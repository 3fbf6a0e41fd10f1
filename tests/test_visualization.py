"""Tests of torchrl_csirl.analysis.visualization: PNGs written, sizes, headless scene and its pixel mapping."""
from __future__ import annotations

import matplotlib
import numpy as np
import pytest
import torch
from PIL import Image

from torchrl_csirl.analysis.visualization import (
    plot_learning_curve,
    plot_method_curves,
    plot_subgoal_curriculum,
    render_curriculum,
)
from torchrl_csirl.analysis.visualization.scene import (
    EGO_COLOR,
    ego_positions,
    render_scene,
    world_to_pixel,
)
from torchrl_csirl.curriculum import scan_subgoal
from torchrl_csirl.data import load_expert_demonstrations
from torchrl_csirl.tasks import SCENARIOS, make_gym_env


def _png_size(path) -> tuple[int, int]:
    assert path.exists() and path.stat().st_size > 0
    with Image.open(path) as image:
        assert image.format == "PNG"
        return image.size


def _curriculum(scenario: str) -> torch.Tensor:
    demos = load_expert_demonstrations(scenario, num_trajectories=1)
    return demos.trajectory_observations(0, include_final=True)


# ---------------------------------------------------------------- learning curve
def test_learning_curve_writes_png(tmp_path):
    evaluations = [
        {"frames": 10_000 * i, "accomplish_rate": 0.1 * i, "success_rate": 0.05 * i, "accomplish_rate_std": 0.02}
        for i in range(6)
    ]
    out = plot_learning_curve(evaluations, tmp_path / "sub" / "curve.png", title="merge", expert_accomplish_rate=0.9)
    assert out == tmp_path / "sub" / "curve.png"
    assert _png_size(out) == (600, 400)


@pytest.mark.parametrize("evaluations", [[], [{"frames": 1000, "accomplish_rate": 0.4}]], ids=["empty", "one"])
def test_learning_curve_empty_and_single_point(tmp_path, evaluations):
    out = plot_learning_curve(evaluations, tmp_path / "curve.png", expert_accomplish_rate=0.95)
    assert _png_size(out) == (600, 400)


def test_learning_curve_missing_key(tmp_path):
    with pytest.raises(KeyError, match="accomplish_rate"):
        plot_learning_curve([{"frames": 0}], tmp_path / "curve.png")


def test_learning_curve_leaves_the_backend_alone(tmp_path):
    backend = matplotlib.get_backend()
    plot_learning_curve([{"frames": 0, "accomplish_rate": 0.5}], tmp_path / "curve.png")
    assert matplotlib.get_backend() == backend


@pytest.mark.parametrize("with_curve", [True, False], ids=["curve", "references-only"])
def test_method_curves_frame_axis(tmp_path, monkeypatch, with_curve):
    """Reference lines alone (records without evaluation logs) get no frame axis to misread."""
    import torchrl_csirl.analysis.visualization.curves as curves_module

    figures = []
    save_png = curves_module.save_png
    monkeypatch.setattr(curves_module, "save_png", lambda fig, path: figures.append(fig) or save_png(fig, path))
    curves = {"sac": [([4000, 8000], [0.2, 0.5])]} if with_curve else {"sac": []}
    out = plot_method_curves(curves, tmp_path / "curves.png", references={"expert": 0.95, "random": 0.04})
    assert _png_size(out) == (860, 450)
    ax = figures[0].axes[0]
    if with_curve:
        assert ax.get_xlabel() == "environment frames" and len(ax.get_xticks()) > 0
    else:
        assert ax.get_xlabel() == "no evaluation curve recorded" and len(ax.get_xticks()) == 0
    assert [t.get_text() for t in ax.get_legend().get_texts()][-2:] == ["expert (0.95)", "random (0.04)"]


def test_return_curves_keep_their_values_and_references_in_view(tmp_path, monkeypatch):
    """``rate=False`` (returns): the axis follows the data, the reference lines included (a reference loop
    variable once shadowed ``rate`` and clipped every return figure with references to [0, 1])."""
    import torchrl_csirl.analysis.visualization.curves as curves_module

    figures = []
    save_png = curves_module.save_png
    monkeypatch.setattr(curves_module, "save_png", lambda fig, path: figures.append(fig) or save_png(fig, path))
    curves = {"csirl": [([20000, 40000], [-236.8, 263.4])]}
    plot_method_curves(curves, tmp_path / "curves.png", references={"expert": 6254.5, "random": -284.5}, rate=False)
    low, high = figures[0].axes[0].get_ylim()
    assert low < -284.5 and high > 6254.5


# ---------------------------------------------------------------- subgoal curriculum
def _selections(length: int, rounds: int) -> list[dict]:
    generator = torch.Generator().manual_seed(0)
    subgoal, selections = 2, []
    for r in range(rounds):
        profile = torch.rand(length, generator=generator, dtype=torch.float64) + 0.5
        profile[subgoal + 3 :] *= 10.0 ** (r + 1)  # a jump after the subgoal, growing: log scale
        subgoal, ratios = scan_subgoal(profile, subgoal, delta=5.0)
        selections.append(
            {"frames": 2000 * (r + 1), "subgoal": subgoal, "profile": profile.tolist(), "ratios": ratios.tolist()}
        )
    return selections


def test_subgoal_curriculum_with_ratios(tmp_path):
    selections = _selections(length=30, rounds=4)
    assert selections[-1]["subgoal"] > selections[0]["subgoal"]
    out = plot_subgoal_curriculum(selections, tmp_path / "subgoals.png", curriculum_length=30, delta=5.0)
    assert _png_size(out) == (700, 800)  # third panel: scan ratios


def test_subgoal_curriculum_short_ratios_and_no_ratios(tmp_path):
    selections = [
        {"frames": 100, "subgoal": 4, "profile": [1.0, 1.0, 1.0, 1.1, 9.0, 1.0], "ratios": [1.0, 1.1, 8.5]},
        {"frames": 200, "subgoal": 4, "profile": [1.0] * 6, "ratios": []},
    ]
    out = plot_subgoal_curriculum(selections, tmp_path / "a.png", curriculum_length=6, delta=5.0)
    assert _png_size(out) == (700, 800)
    no_ratios = [{k: v for k, v in s.items() if k != "ratios"} for s in selections]
    out = plot_subgoal_curriculum(no_ratios, tmp_path / "b.png", curriculum_length=6)
    assert _png_size(out) == (700, 600)


@pytest.mark.parametrize("count", [0, 1])
def test_subgoal_curriculum_empty_and_single(tmp_path, count):
    selections = [{"frames": 500, "subgoal": 0, "profile": [0.0, 2.0, 3.0]}][:count]
    out = plot_subgoal_curriculum(selections, tmp_path / "s.png", curriculum_length=3)
    assert _png_size(out) == (700, 600)


def test_subgoal_curriculum_rejects_bad_profile(tmp_path):
    with pytest.raises(ValueError, match="curriculum_length"):
        plot_subgoal_curriculum(
            [{"frames": 0, "subgoal": 0, "profile": [1.0, 2.0]}], tmp_path / "s.png", curriculum_length=3
        )
    with pytest.raises(ValueError, match="outside"):
        plot_subgoal_curriculum(
            [{"frames": 0, "subgoal": 3, "profile": [1.0, 2.0, 3.0]}], tmp_path / "s.png", curriculum_length=3
        )


# ---------------------------------------------------------------- scene
def test_ego_positions_inverts_the_normalisation():
    spec = SCENARIOS["roundabout"]
    env = make_gym_env("roundabout")
    obs, _ = env.reset(seed=3)
    position = ego_positions(spec, obs)[0]
    np.testing.assert_allclose(position, env.vehicle.position, atol=1e-3)


def test_world_to_pixel_matches_highway_env_pos2pix():
    env = make_gym_env("merge", render_mode="rgb_array", screen_width=500, screen_height=200, scaling=3.3)
    env.reset(seed=1)
    env.render()
    surface = env.viewer.sim_surface
    points = np.concatenate([env.vehicle.position[None], [[0.0, 0.0], [123.45, -6.7], [-3.2, 11.9]]])
    pixels = world_to_pixel(points, surface.origin, surface.scaling)
    for point, pixel in zip(points, pixels):
        assert tuple(int(v) for v in pixel) == surface.pos2pix(*point)
    env.viewer = None


@pytest.mark.parametrize("scenario", ["merge", "roundabout"])
def test_render_curriculum_puts_the_start_on_the_drawn_ego(tmp_path, scenario):
    observations = _curriculum(scenario)
    seed = load_expert_demonstrations(scenario, num_trajectories=1).metadata["episodes"][0]["seed"]
    route = ego_positions(scenario, observations)
    picture = render_scene(scenario, seed=seed, focus=route, max_pixels=1000)
    # the demonstration starts where the env, reset with its seed, puts (and draws) the ego
    np.testing.assert_allclose(route[0], picture.ego_position, atol=0.05)
    rows, cols = np.nonzero(np.all(picture.image == np.asarray(EGO_COLOR), axis=-1))
    assert rows.size > 20  # the ego is drawn, in its colour
    col, row = picture.world_to_pixel(route[0])
    # on the drawn vehicle, up to highway-env's own rounding of its sprite (~1-2 px)
    assert cols.min() - 2 <= col <= cols.max() + 3 and rows.min() - 2 <= row <= rows.max() + 3
    centroid = np.array([cols.mean() + 0.5, rows.mean() + 0.5])
    assert np.hypot(*(centroid - (col, row))) < 3.0
    # the whole route is in the frame
    pixels = picture.world_to_pixel(route)
    height, width = picture.image.shape[:2]
    assert (pixels >= 0).all() and (pixels[:, 0] < width).all() and (pixels[:, 1] < height).all()

    out = render_curriculum(scenario, observations, [1, 5, 5, len(observations) - 1], tmp_path / f"{scenario}.png",
                            seed=seed, max_pixels=1000)
    width_px, height_px = _png_size(out)
    assert width_px >= 720 and max(width_px, height_px) >= 1000 and min(width_px, height_px) > 100


def test_render_curriculum_without_subgoals_and_bad_index(tmp_path):
    observations = _curriculum("merge")[:1]  # a one-state curriculum
    out = render_curriculum("merge", observations.numpy(), [], tmp_path / "one.png", max_pixels=400)
    assert _png_size(out)[0] >= 400
    with pytest.raises(ValueError, match="outside the curriculum"):
        render_curriculum("merge", observations, [1], tmp_path / "bad.png", max_pixels=400)


def test_a_method_keeps_its_colour_from_figure_to_figure(tmp_path, monkeypatch):
    """With ``method_order`` a method's colour is its place in that order, whichever other methods a figure holds."""
    import torchrl_csirl.analysis.visualization.curves as curves_module

    figures = []
    save_png = curves_module.save_png
    monkeypatch.setattr(curves_module, "save_png", lambda fig, path: figures.append(fig) or save_png(fig, path))
    run = [([4000, 8000], [0.2, 0.5])]
    order = ("sac", "bc", "csirl")
    plot_method_curves({"sac": run, "csirl": run}, tmp_path / "a.png", method_order=order)
    plot_method_curves({"csirl": run, "mine": run}, tmp_path / "b.png", method_order=order)

    def colours(fig):
        return {line.get_label().split(" (")[0]: line.get_color() for line in fig.axes[0].get_lines()}

    first, second = colours(figures[0]), colours(figures[1])
    assert first["csirl"] == second["csirl"] and first["sac"] != first["csirl"]
    assert second["mine"] not in (first["sac"], first["csirl"])  # a method outside the order: a colour of its own
