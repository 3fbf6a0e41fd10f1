"""A picture of a scenario with the curriculum trajectory and its subgoals (cf. the paper's Fig. 9).

The scene is rendered headless by highway-env (``render_mode="rgb_array"``, offscreen) with the
viewer configured so that the whole route is in view, then the trajectory is drawn over it with
matplotlib. highway-env's viewer maps a world position ``(x, y)`` [m] to the pixel
``int((x - origin_x) * scaling), int((y - origin_y) * scaling)`` (``WorldSurface.pos2pix``,
y pointing down), where ``origin = ego_position - centering_position * (width, height) / scaling``
follows the ego vehicle; :func:`world_to_pixel` is the same map without the truncation.
"""
from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from torchrl_csirl.analysis.visualization._figure import as_int, new_figure, save_png
from torchrl_csirl.tasks.catalog import ScenarioSpec, make_gym_env, resolve_scenario

__all__ = ["ScenePicture", "ego_positions", "render_curriculum", "render_scene", "world_to_pixel"]

#: highway-env's ego colour (``VehicleGraphics.EGO_COLOR``), RGB; the ego is painted with it
EGO_COLOR = (50, 200, 0)
#: narrowest :func:`render_curriculum` figure [px]
MIN_FIGURE_WIDTH = 720


def ego_positions(scenario: str | ScenarioSpec, observations: Any) -> np.ndarray:
    """World positions ``(x, y)`` [m] of the ego vehicle from normalised observations.

    Inverts the Kinematics normalisation ``v = -1 + 2 (p - low) / (high - low)`` of the ego row
    (the first vehicle of the flattened observation) with the scenario's ``features_range``.
    Observations are clipped to ``[-1, 1]``, so positions outside the range come back at its edge.

    Args:
        scenario: scenario name, gym id or :class:`~torchrl_csirl.tasks.ScenarioSpec`.
        observations: ``[L, obs_dim]`` (or ``[obs_dim]``) array or tensor.

    Returns:
        np.ndarray: ``[L, 2]`` float64 positions.

    Examples:
        >>> import numpy as np
        >>> obs = np.zeros((1, 25)); obs[0, 1:3] = [0.06, 0.5]  # merge: x in [-500, 500], y in [-8, 8]
        >>> ego_positions("merge", obs).tolist()
        [[30.0, 4.0]]
    """
    spec = resolve_scenario(scenario)
    if hasattr(observations, "detach"):
        observations = observations.detach().cpu().numpy()
    obs = np.asarray(observations, dtype=np.float64)
    if obs.ndim == 1:
        obs = obs[None]
    if obs.ndim != 2 or obs.shape[-1] != spec.obs_dim:
        raise ValueError(f"expected observations of shape [L, {spec.obs_dim}] for {spec.name}, got {obs.shape}.")
    columns = []
    for name in ("x", "y"):
        low, high = spec.features_range[name]
        value = obs[:, spec.ego_feature_indices[spec.features.index(name)]]
        columns.append(low + (value + 1.0) * (high - low) / 2.0)
    return np.stack(columns, axis=-1)


def world_to_pixel(positions: Any, origin: Sequence[float], scaling: float) -> np.ndarray:
    """Maps world positions [m] to continuous pixel coordinates of a highway-env picture.

    ``(x - origin_x) * scaling, (y - origin_y) * scaling``: column and row (rows grow downward,
    like world y in highway-env). Truncating gives exactly ``WorldSurface.pos2pix``; pixel ``k``
    covers ``[k, k + 1)``, so draw over the image with ``extent=(0, width, height, 0)``.

    Examples:
        >>> world_to_pixel([[30.0, 4.0]], origin=(-2.5, -9.5), scaling=5.5).tolist()
        [[178.75, 74.25]]
    """
    points = np.asarray(positions, dtype=np.float64)
    origin = np.asarray(origin, dtype=np.float64).reshape(2)
    # same operation order as WorldSurface.pix(x - origin[0]), so int() of it matches pos2pix
    return (points - origin) * float(scaling)


@dataclasses.dataclass(frozen=True)
class ScenePicture:
    """A rendered highway-env frame and its world-to-pixel transform.

    Attributes:
        image (np.ndarray): ``[H, W, 3]`` uint8 RGB frame.
        origin (np.ndarray): world position [m] of the top-left corner (pixel ``(0, 0)``).
        scaling (float): pixels per metre.
        ego_position (np.ndarray): world position [m] of the ego vehicle in the frame.
    """

    image: np.ndarray
    origin: np.ndarray
    scaling: float
    ego_position: np.ndarray

    def world_to_pixel(self, positions: Any) -> np.ndarray:
        """:func:`world_to_pixel` with this picture's transform."""
        return world_to_pixel(positions, self.origin, self.scaling)


def _view_box(
    points: np.ndarray, margin: float, min_extent: float, min_aspect: float
) -> tuple[np.ndarray, np.ndarray]:
    """Bounding box of ``points`` padded by ``margin``, grown (centred) to at least ``min_extent``
    and to a shorter side of at least ``min_aspect`` times the longer one."""
    low = points.min(axis=0) - margin
    high = points.max(axis=0) + margin
    target = np.maximum(min_extent, min_aspect * float((high - low).max()))
    grow = np.maximum(target - (high - low), 0.0) / 2.0
    return low - grow, high + grow


def render_scene(
    scenario: str | ScenarioSpec,
    *,
    seed: int = 0,
    focus: Any = None,
    margin: float = 10.0,
    min_extent: float = 30.0,
    min_aspect: float | None = None,
    max_pixels: int = 1400,
    max_scaling: float = 12.0,
    env_config: Mapping[str, Any] | None = None,
) -> ScenePicture:
    """Renders a scenario after ``reset(seed=seed)``, framed to show the ``focus`` points.

    The viewer's ``scaling`` makes the padded bounding box of ``focus`` (plus the ego vehicle)
    fit in ``max_pixels`` on its longer side, and its ``centering_position`` puts that box's
    top-left corner at pixel ``(0, 0)``.

    Args:
        scenario: scenario name, gym id or spec.

    Keyword Args:
        seed (int): reset seed (traffic layout). Defaults to ``0``.
        focus: ``[N, 2]`` world positions [m] that must be visible. Defaults to the ego position.
        margin (float): padding [m] around the points. Defaults to ``10``.
        min_extent (float): smallest shown width and height [m]. Defaults to ``30``.
        min_aspect (float, optional): smallest ratio of the shorter to the longer shown side.
            Defaults to ``0.6`` for the 2-D scenes (roundabout, intersection: the junction
            stays in view) and ``0`` for the straight roads (highway-fast, merge).
        max_pixels (int): size of the longer image side. Defaults to ``1400``.
        max_scaling (float): largest pixels per metre. Defaults to ``12``.
        env_config (dict, optional): extra ``make_gym_env`` config overrides.

    Returns:
        ScenePicture: the frame and its transform.

    Examples:
        >>> pic = render_scene("intersection", max_pixels=300)
        >>> col, row = pic.world_to_pixel(pic.ego_position).astype(int)
        >>> tuple(int(c) for c in pic.image[row, col]) == EGO_COLOR
        True
    """
    spec = resolve_scenario(scenario)
    if min_aspect is None:
        min_aspect = 0.6 if "y" in spec.position_features else 0.0
    env = make_gym_env(spec.name, render_mode="rgb_array", **dict(env_config or {}))
    try:
        env.reset(seed=seed)
        # the CSIRL ego is a plain Vehicle, which highway-env paints yellow like an obstacle
        env.vehicle.color = EGO_COLOR
        ego = np.asarray(env.vehicle.position, dtype=np.float64).copy()
        points = ego[None] if focus is None else np.vstack([np.asarray(focus, dtype=np.float64).reshape(-1, 2), ego])
        low, high = _view_box(points, margin, min_extent, min_aspect)
        extent = high - low
        scaling = min(max_pixels / float(extent.max()), max_scaling)
        size = np.ceil(extent * scaling).astype(int)
        # the viewer puts the ego at centering * size / scaling from the top-left corner
        env.config.update(
            {
                "screen_width": int(size[0]),
                "screen_height": int(size[1]),
                "scaling": scaling,
                "centering_position": ((ego - low) * scaling / size).tolist(),
                "offscreen_rendering": True,
            }
        )
        image = np.ascontiguousarray(env.render())
        surface = env.viewer.sim_surface
        return ScenePicture(
            image=image,
            origin=np.asarray(surface.origin, dtype=np.float64).copy(),
            scaling=float(surface.scaling),
            ego_position=ego,
        )
    finally:
        # drop the viewer without env.close(): EnvViewer.close() calls pygame.quit(), which
        # would tear down pygame for any other renderer living in this process
        env.viewer = None


def _subgoal_list(subgoals: Any, length: int) -> list[int]:
    if hasattr(subgoals, "detach"):
        subgoals = subgoals.detach().cpu().reshape(-1).tolist()
    out = []
    for k, value in enumerate(np.asarray(subgoals, dtype=object).reshape(-1).tolist()):
        index = as_int(value, f"subgoals[{k}]")
        if not 0 <= index < length:
            raise ValueError(f"subgoals[{k}] = {index} is outside the curriculum [0, {length - 1}].")
        out.append(index)
    return out


def render_curriculum(
    scenario: str | ScenarioSpec,
    curriculum_observations: Any,
    subgoals: Sequence[int],
    path: str | os.PathLike,
    *,
    seed: int = 0,
    max_pixels: int = 1400,
    title: str | None = None,
) -> Path:
    """Draws the scenario with the curriculum trajectory and the selected subgoals.

    The scene (road, traffic after ``reset(seed=seed)``, ego in green) is rendered by
    highway-env framed on the trajectory and the finish (see :func:`render_scene`); the ego
    positions of the curriculum states (:func:`ego_positions`) are drawn as a line with dots,
    the subgoals as stars numbered by selection order (a state selected several times gets all
    its numbers), the curriculum start as a circle and the scenario's finish position as a cross.

    Args:
        scenario: scenario name, gym id or spec.
        curriculum_observations: ``[L, obs_dim]`` normalised observations (tensor or array).
        subgoals: selected curriculum indices in selection order (may be empty).
        path: where to write the PNG (parent folders are created).

    Keyword Args:
        seed (int): reset seed of the rendered scene. Defaults to ``0``.
        max_pixels (int): longer side of the rendered scene in pixels. Defaults to ``1400``.
        title (str, optional): figure title. Defaults to the scenario and counts.

    Returns:
        Path: ``path``; the PNG is the rendered scene at native resolution plus a title band
        and a legend band.

    Examples:
        >>> import tempfile, pathlib
        >>> from torchrl_csirl.data import load_expert_demonstrations
        >>> obs = load_expert_demonstrations("merge", num_trajectories=1).trajectory_observations(0, include_final=True)
        >>> out = pathlib.Path(tempfile.mkdtemp()) / "merge.png"
        >>> render_curriculum("merge", obs, [3, 10, 25], out, max_pixels=600) == out
        True
    """
    spec = resolve_scenario(scenario)
    route = ego_positions(spec, curriculum_observations)
    goals = _subgoal_list(subgoals, len(route))
    finish = np.asarray(spec.finish_position, dtype=np.float64)
    picture = render_scene(spec, seed=seed, focus=np.vstack([route, finish]), max_pixels=max_pixels)
    height, width = picture.image.shape[:2]
    title_px, legend_px = 34, 40
    fig_width = max(width, MIN_FIGURE_WIDTH)  # room for the title and the legend
    total = height + title_px + legend_px
    fig = new_figure(fig_width, total)
    left = (fig_width - width) / 2.0 / fig_width
    ax = fig.add_axes((left, legend_px / total, width / fig_width, height / total))
    ax.imshow(picture.image, extent=(0, width, height, 0), interpolation="nearest")
    _draw_route(ax, picture.world_to_pixel(route), goals, picture.world_to_pixel(finish[None])[0])
    ax.set_xlim(0, width)
    ax.set_ylim(height, 0)
    ax.set_axis_off()
    if title is None:
        count = len(set(goals))
        title = f"{spec.name}: curriculum trajectory ({len(route)} states), {count} subgoal{'' if count == 1 else 's'}"
    fig.text(0.5, 1.0 - 0.5 * title_px / total, title, ha="center", va="center", fontsize=11)
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="center", bbox_to_anchor=(0.5, 0.5 * legend_px / total),
               ncol=len(labels), fontsize=8, frameon=False, handletextpad=0.3, columnspacing=1.0)
    return save_png(fig, path)


def _draw_route(ax, route_px: np.ndarray, goals: list[int], finish_px: np.ndarray) -> None:
    ax.plot(route_px[:, 0], route_px[:, 1], "-", color="#ff2fd1", linewidth=1.6, zorder=3,
            label="curriculum trajectory")
    ax.plot(route_px[:, 0], route_px[:, 1], "o", color="#ff2fd1", markersize=2.5,
            markeredgecolor="black", markeredgewidth=0.3, zorder=4)
    ax.plot(*route_px[0], "o", color="white", markersize=8, markeredgecolor="black", zorder=5, label="start")
    ax.plot(*finish_px, "X", color="red", markersize=10, markeredgecolor="black", zorder=5, label="finish")
    order: dict[int, list[int]] = {}
    for number, index in enumerate(goals, start=1):
        order.setdefault(index, []).append(number)
    for k, (index, numbers) in enumerate(order.items()):
        x, y = route_px[index]
        ax.plot(x, y, "*", color="gold", markersize=15, markeredgecolor="black", markeredgewidth=0.8,
                zorder=6, label="subgoal (selection order)" if k == 0 else None)
        ax.annotate(",".join(map(str, numbers)), (x, y), xytext=(0, 9), textcoords="offset points",
                    ha="center", va="bottom", fontsize=8, fontweight="bold", zorder=7,
                    bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.8})
