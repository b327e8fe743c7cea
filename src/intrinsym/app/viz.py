"""Paper-style figures of a saved result, rendered headless (matplotlib Agg, no GPU).

Three kinds of figure, each a row of views of the shaded mesh:

- the continuous marginal of one source sample (paper Eq. 9) as a heat map, blue 0 to
  red 1, the source sample marked (paper Fig. 3, 5-9);
- the sampled points with the source graph (paper Fig. 1);
- one image per extracted symmetry: its source part coloured by position, and its image
  part coloured like the points that map there.

Figures are plain ``matplotlib.figure.Figure`` objects saved through the Agg canvas:
no pyplot, no display, no global backend switch. Shading is Lambert lighting per face
under a light fixed to the camera; faces are
depth-sorted and drawn as one ``PolyCollection`` (painter's algorithm), which keeps a
100k-face mesh to about a second per view.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import cKDTree

from ..errors import InputError, ParameterError
from ..evaluation.evaluate import load_symmetry_map
from ..extract.records import part_vertices
from ..extras import require
from ..files import atomic_write
from ..mesh.io import load
from ..mesh.shape import Shape
from ..result import coloring
from ..result.result import Result

if TYPE_CHECKING:  # matplotlib is imported where a figure is drawn: the CLI starts 0.6 s sooner
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

HEAT = ("#2040d0", "#40c0f0", "#f0f0a0", "#f08030", "#d01010")
"""Blue (0) to red (1), the paper's colouring of a marginal."""

BASE = np.array([0.78, 0.78, 0.76])

# Directions to the light and the share of ambient light, in view coordinates (x right,
# y up, z towards the viewer).
LIGHT = np.array([-0.35, 0.55, 1.0]) / np.linalg.norm([-0.35, 0.55, 1.0])
AMBIENT = 0.3

# World axis that becomes "up" in the views, as a rotation of the world frame.
UP_FRAMES = {
    "x": np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]),
    "y": np.eye(3),
    "z": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]),
}


@dataclass(frozen=True)
class FigureParams:
    """How figures look.

    Attributes
    ----------
    up : {"x", "y", "z"}
        World axis drawn upwards (OBJ files are usually y-up, TOSCA and KIDS z-up).
    views : sequence of (elevation, azimuth) in degrees
        One panel per view; azimuth turns about the up axis, elevation tilts towards it.
    size : float
        Height of one panel in inches (width equal).
    dpi : int
    sigma : float or None
        Width of the Gaussians of Eq. 9 in input length units; None = the median
        spacing of the target samples.
    """

    up: str = "y"
    views: Sequence[tuple[float, float]] = ((15.0, 35.0), (15.0, 215.0), (60.0, 125.0))
    size: float = 3.2
    dpi: int = 80
    sigma: float | None = None

    def __post_init__(self) -> None:
        if self.up not in UP_FRAMES:
            raise ValueError(f"up must be one of {sorted(UP_FRAMES)}, got {self.up!r}")
        if len(self.views) == 0:
            raise ValueError("give at least one view")


def view_rotation(elevation: float, azimuth: float, up: str = "y") -> np.ndarray:
    """(3, 3) rotation from world to view coordinates (x right, y up, z to the viewer).

    Parameters
    ----------
    elevation, azimuth : float
        Degrees.
    up : {"x", "y", "z"}
        World axis that points up on screen at zero elevation.
    """
    a, e = np.radians(azimuth), np.radians(elevation)
    spin = np.array([[np.cos(a), 0.0, np.sin(a)], [0.0, 1.0, 0.0], [-np.sin(a), 0.0, np.cos(a)]])
    tilt = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(e), -np.sin(e)], [0.0, np.sin(e), np.cos(e)]])
    return tilt @ spin @ UP_FRAMES[up]


def shade_faces(
    vertices: np.ndarray, faces: np.ndarray, vertex_rgb: np.ndarray, rotation: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Project, light and depth-sort the faces of a mesh (orthographic camera).

    Parameters
    ----------
    vertices : (N, 3) float
    faces : (F, 3) int
    vertex_rgb : (N, 3) float in [0, 1]
        Colour of every vertex; a face takes the mean of its corners.
    rotation : (3, 3) float
        World to view, as from :func:`view_rotation`.

    Returns
    -------
    polygons : (F, 3, 2) float
        Screen coordinates of the corners, farthest face first.
    colors : (F, 3) float
        Lit face colours in the same order.
    """
    view = (vertices - vertices.mean(axis=0)) @ rotation.T
    corners = view[faces]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    length = np.linalg.norm(normal, axis=1)
    normal /= np.where(length > 0, length, 1.0)[:, None]
    # Two-sided Lambert: the winding of real meshes is not always consistent.
    light = AMBIENT + (1.0 - AMBIENT) * np.abs(normal @ LIGHT)
    colors = vertex_rgb[faces].mean(axis=1) * light[:, None]
    order = np.argsort(corners[:, :, 2].mean(axis=1), kind="stable")
    return corners[order, :, :2], np.clip(colors[order], 0.0, 1.0)


def visible(points: np.ndarray, vertices: np.ndarray, rotation: np.ndarray, cells: int = 300) -> np.ndarray:
    """(n,) bool: which points on the surface are not hidden by the surface.

    A coarse depth buffer of the mesh vertices (``cells`` x ``cells``, the nearest
    vertex depth of each cell and its 8 neighbours) stands in for the rendered depth;
    a point is visible when it lies within two cells of that depth.
    """
    centre = vertices.mean(axis=0)
    v = (vertices - centre) @ rotation.T
    p = (points - centre) @ rotation.T
    lo, hi = v[:, :2].min(axis=0), v[:, :2].max(axis=0)
    cell = float((hi - lo).max()) / (cells - 1) or 1.0

    def pixel(xy: np.ndarray) -> np.ndarray:
        ij = np.clip(((xy - lo) / cell).astype(np.int64), 0, cells - 1)
        return ij[:, 0] * cells + ij[:, 1]

    depth = np.full(cells * cells, -np.inf)
    np.maximum.at(depth, pixel(v[:, :2]), v[:, 2])
    grid = depth.reshape(cells, cells)
    padded = np.pad(grid, 1, constant_values=-np.inf)
    nearest = np.max(
        [padded[1 + di : 1 + di + cells, 1 + dj : 1 + dj + cells] for di in (-1, 0, 1) for dj in (-1, 0, 1)], axis=0
    ).ravel()
    return p[:, 2] >= nearest[pixel(p[:, :2])] - 2 * cell


def gaussian_weights(
    points: np.ndarray, targets: np.ndarray, sigma: float, k: int = 16
) -> tuple[np.ndarray, np.ndarray]:
    """Weights exp(-|t_j - x|^2 / sigma^2) of Eq. 9 from each point to its k nearest targets.

    Parameters
    ----------
    points : (N, 3) float
    targets : (T, 3) float
    sigma : float
        Gaussian width, same length unit as the points.
    k : int
        Targets kept per point; farther ones are below exp(-(r_k / sigma)^2).

    Returns
    -------
    index : (N, k') int64
        Target indices, k' = min(k, T).
    weight : (N, k') float64
    """
    k = min(k, len(targets))
    dist, index = cKDTree(targets).query(points, k=k)
    dist, index = dist.reshape(len(points), k), index.reshape(len(points), k)
    return index.astype(np.int64), np.exp(-((dist / sigma) ** 2))


def target_spacing(targets: np.ndarray) -> float:
    """Median distance from a target sample to its nearest other target sample."""
    dist, _ = cKDTree(targets).query(targets, k=2)
    return float(np.median(dist[:, 1]))


def continuous_marginal(index: np.ndarray, weight: np.ndarray, row: np.ndarray) -> np.ndarray:
    """Paper Eq. 9 at every point: sum_j lambda_j exp(-|t_j - x|^2 / sigma^2), max 1.

    Parameters
    ----------
    index, weight : (N, k) arrays
        From :func:`gaussian_weights`.
    row : (T,) float
        Marginal lambda of one source sample over the target samples.

    Returns
    -------
    (N,) float64 in [0, 1]
    """
    value = (np.asarray(row, dtype=np.float64)[index] * weight).sum(axis=1)
    top = value.max()
    return value / top if top > 0 else value


def default_source(result: Result) -> int:
    """The source sample whose marginal best shows a symmetry.

    Self-matching: the sample with the highest marginal peak (relative to its own
    maximum) at a target farther than a quarter of sqrt(area) from itself, so that
    the figure shows a non-trivial image. Two-shape matching: the most peaked marginal.
    """
    m = result.mixed_marginals()
    m = m / np.maximum(m.max(axis=1, keepdims=True), np.finfo(float).tiny)
    if result.info.mode == "detect":
        far = 0.25 * float(result.info.resolved.scale)
        dist = np.linalg.norm(result.source_points[:, None, :] - result.target_points[None, :, :], axis=2)
        m = np.where(dist > far, m, 0.0)
        return int(np.argmax(m.max(axis=1)))
    return int(np.argmax(m.max(axis=1) / np.maximum(m.mean(axis=1), np.finfo(float).tiny)))


def _panels(n: int, p: FigureParams) -> tuple[Figure, list[Axes]]:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(p.size * n, p.size), dpi=p.dpi)
    axes = fig.subplots(1, n, squeeze=False)
    fig.subplots_adjust(left=0.01, right=0.99, top=0.90, bottom=0.01, wspace=0.02)
    for ax in axes[0]:
        ax.set_axis_off()
        ax.set_aspect("equal")
    return fig, list(axes[0])


def _draw_mesh(ax: Axes, vertices: np.ndarray, faces: np.ndarray | None, rgb: np.ndarray, rotation: np.ndarray) -> None:
    if faces is None:
        raise ParameterError("figures need a triangle mesh, not a point cloud")
    from matplotlib.collections import PolyCollection

    polygons, colors = shade_faces(vertices, faces, rgb, rotation)
    ax.add_collection(PolyCollection(list(polygons), facecolors=colors, edgecolors="none", antialiased=False))
    ax.set_xlim(polygons[..., 0].min(), polygons[..., 0].max())
    ax.set_ylim(polygons[..., 1].min(), polygons[..., 1].max())


def _screen(points: np.ndarray, vertices: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    return ((points - vertices.mean(axis=0)) @ rotation.T)[:, :2]


def _save(fig: Figure, path: Path) -> Path:
    atomic_write(path, lambda f: fig.savefig(f, format="png"), binary=True)
    return path


def marginal_figure(
    shape: Shape,
    result: Result,
    source: int,
    path: str | Path,
    params: FigureParams = FigureParams(),
    source_shape: Shape | None = None,
) -> Path:
    """PNG of the continuous marginal (Eq. 9) of one source sample on the target shape:
    :meth:`~intrinsym.result.result.Result.mixed_marginals`, so that a match shows both
    its modes.

    Parameters
    ----------
    shape : Shape
        The target shape, in the coordinates of ``result.target_points``.
    result : Result
    source : int
        Source sample index.
    path : path of the PNG
    params : FigureParams
    source_shape : Shape, optional
        Two-shape matching: the source shape, drawn in a first panel with the sample.
    """
    sigma = params.sigma or target_spacing(result.target_points)
    index, weight = gaussian_weights(shape.vertices, result.target_points, sigma)
    value = continuous_marginal(index, weight, result.mixed_marginals()[source])
    from matplotlib.colors import LinearSegmentedColormap

    rgb = LinearSegmentedColormap.from_list("heat", HEAT)(value)[:, :3]
    panels = [(shape, rgb)] * len(params.views)
    if source_shape is not None:
        panels = [(source_shape, np.broadcast_to(BASE, source_shape.vertices.shape))] + panels
    fig, axes = _panels(len(panels), params)
    views = list(params.views)
    for k, (ax, (s, colors)) in enumerate(zip(axes, panels)):
        rot = view_rotation(*views[max(k - (len(panels) - len(views)), 0)], params.up)
        _draw_mesh(ax, s.vertices, s.faces, colors, rot)
        if source_shape is None or s is source_shape:
            point = result.source_points[source][None]
            xy = _screen(point, s.vertices, rot)
            seen = visible(point, s.vertices, rot)[0]
            ax.plot(*xy.T, marker="o", ms=9, mfc="white" if seen else "none", mec="black", mew=2, ls="none")
    fig.suptitle(f"marginal of source sample {source} (Eq. 9, blue 0 to red 1)", fontsize=10)
    return _save(fig, Path(path))


def graph_figure(shape: Shape, result: Result, path: str | Path, params: FigureParams = FigureParams()) -> Path:
    """PNG of the source samples (red), their graph and the target samples (blue), paper Fig. 1.

    Only points and edges not hidden by the surface are drawn.
    """
    from matplotlib.collections import LineCollection

    fig, axes = _panels(len(params.views), params)
    rgb = np.broadcast_to(BASE, shape.vertices.shape)
    targets_on_shape = result.info.mode == "detect"
    for ax, view in zip(axes, params.views):
        rot = view_rotation(*view, params.up)
        _draw_mesh(ax, shape.vertices, shape.faces, rgb, rot)
        if targets_on_shape:
            t_seen = visible(result.target_points, shape.vertices, rot)
            t_xy = _screen(result.target_points[t_seen], shape.vertices, rot)
            ax.plot(*t_xy.T, marker=".", ms=1.5, color="#1f4fbf", ls="none")
        seen = visible(result.source_points, shape.vertices, rot)
        xy = _screen(result.source_points, shape.vertices, rot)
        both = seen[result.edges].all(axis=1)
        ax.add_collection(LineCollection(xy[result.edges[both]], colors="black", linewidths=0.7))
        ax.plot(*xy[seen].T, marker="o", ms=3.5, color="#d01010", ls="none")
    title = f"|Ps| = {len(result.source_points)} with the source graph ({len(result.edges)} edges)"
    if targets_on_shape:
        title += f", |Pt| = {len(result.target_points)}"
    fig.suptitle(title, fontsize=10)
    return _save(fig, Path(path))


def correspondence_colors(vertices: np.ndarray, record: dict) -> tuple[np.ndarray, np.ndarray]:
    """Colours that show a symmetry's point map: (N, 3) for the source part, (N, 3) for the image.

    A source-part vertex is coloured by its position (x, y, z scaled to the bounding box
    as red, green, blue); an image-part vertex takes the colour of the source sample
    whose image lies nearest to it, so matching places share a colour. Vertices outside
    the part are grey.

    Parameters
    ----------
    vertices : (N, 3) float
    record : dict
        A ``symmetries.json`` entry: ``source_vertex_index``, ``target_vertex_index`` and
        ``pairs`` ([source vertex, target vertex] per sample pair), input vertex indices.
    """
    lo, span = vertices.min(axis=0), np.ptp(vertices, axis=0)
    position = 0.15 + 0.8 * (vertices - lo) / np.where(span > 0, span, 1.0)
    src, tgt = np.tile(BASE, (len(vertices), 1)), np.tile(BASE, (len(vertices), 1))
    part, image = part_vertices(record)
    src[part] = position[part]
    pairs = np.asarray(record["pairs"], dtype=np.int64).reshape(-1, 2)
    if len(pairs) and len(image):
        _, nearest = cKDTree(vertices[pairs[:, 1]]).query(vertices[image])
        tgt[image] = position[pairs[nearest, 0]]
    return src, tgt


def symmetry_figure(
    shape: Shape, record: dict, number: int, path: str | Path, params: FigureParams = FigureParams()
) -> Path:
    """PNG of one extracted symmetry (a ``symmetries.json`` entry).

    Two rows of views: the source part coloured by position, and the image part
    coloured like the source points that map there (:func:`correspondence_colors`).
    """
    from matplotlib.figure import Figure

    rows = correspondence_colors(shape.vertices, record)
    n = len(params.views)
    fig = Figure(figsize=(params.size * n, 2 * params.size), dpi=params.dpi)
    axes = fig.subplots(2, n, squeeze=False)
    fig.subplots_adjust(left=0.01, right=0.99, top=0.93, bottom=0.01, wspace=0.02, hspace=0.08)
    for row, (rgb, label) in enumerate(zip(rows, ("source part", "image (same colour = mapped)"))):
        for ax, view in zip(axes[row], params.views):
            ax.set_axis_off()
            ax.set_aspect("equal")
            _draw_mesh(ax, shape.vertices, shape.faces, rgb, view_rotation(*view, params.up))
        axes[row][0].set_title(label, fontsize=9, loc="left")
    fig.suptitle(
        f"symmetry {number}: {record.get('kind', '?')}, score {record.get('score', float('nan')):.3f}, "
        f"{len(record.get('pairs', []))} sample pairs",
        fontsize=10,
    )
    return _save(fig, Path(path))


def symmetry_map_figure(
    shape: Shape, symmetry_map: np.ndarray, path: str | Path, params: FigureParams = FigureParams()
) -> Path:
    """PNG of the global symmetry map (``symmetry_map.npy``) at a glance, with a legend.

    Two rows of views: the two sides in two colours (fixed points white, points without a
    partner grey) and every point coloured like its partner
    (:func:`intrinsym.result.coloring.vertex_colors`).
    """
    from matplotlib.figure import Figure
    from matplotlib.patches import Patch

    n = len(params.views)
    fig = Figure(figsize=(params.size * n, 2 * params.size + 0.5), dpi=params.dpi)
    axes = fig.subplots(2, n, squeeze=False)
    fig.subplots_adjust(left=0.01, right=0.99, top=0.92, bottom=0.1, wspace=0.02, hspace=0.08)
    titles = {"side": "its two sides", "partner": "each point coloured like its partner"}
    for row, mode in enumerate(("side", "partner")):
        rgb = coloring.vertex_colors(shape, symmetry_map, mode)
        for ax, view in zip(axes[row], params.views):
            ax.set_axis_off()
            ax.set_aspect("equal")
            _draw_mesh(ax, shape.vertices, shape.faces, rgb, view_rotation(*view, params.up))
        axes[row][0].set_title(titles[mode], fontsize=9, loc="left")
    entries = coloring.legend("side")
    handles = [Patch(facecolor=rgb, edgecolor="0.4", label=label) for label, rgb in entries]
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=8, frameon=False)
    none = int(np.count_nonzero(np.asarray(symmetry_map) < 0))
    fig.suptitle(f"global symmetry map ({none} of {len(symmetry_map)} vertices without a partner)", fontsize=10)
    return _save(fig, Path(path))


def load_symmetries(out_dir: str | Path) -> list[dict]:
    """Entries of ``out_dir/symmetries.json``; an empty list when the file is absent."""
    path = Path(out_dir) / "symmetries.json"
    if not path.is_file():
        return []
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as err:
        raise InputError(f"{path}: not a symmetries file ({err})") from None
    return data if isinstance(data, list) else data.get("symmetries", [])


def load_shapes(result: Result, mesh_path: str | Path | None = None) -> tuple[Shape, Shape | None]:
    """The target shape of a result and, for two-shape matching, its source shape.

    Parameters
    ----------
    result : Result
    mesh_path : path, optional
        Replaces the input named in ``run.json`` (self-matching) or the target input
        (two-shape matching).
    """
    if result.info.mode == "match":
        target = load(mesh_path or result.info.target_input or "")
        return target, load(result.info.input)
    return load(mesh_path or result.info.input), None


def render(
    out_dir: str | Path,
    source: int | None = None,
    params: FigureParams = FigureParams(),
    mesh_path: str | Path | None = None,
    figures_dir: str | Path | None = None,
    max_symmetries: int = 6,
) -> list[Path]:
    """Write every figure of a saved result; returns the PNG paths.

    Parameters
    ----------
    out_dir : path
        Directory written by ``Result.save``.
    source : int, optional
        Source sample of the marginal figure (default: :func:`default_source`).
    params : FigureParams
    mesh_path : path, optional
        See :func:`load_shapes`.
    figures_dir : path, optional
        Where the PNGs go (default: ``out_dir/figures``).
    max_symmetries : int
        Figures for the best this many symmetries of ``symmetries.json`` (ranked).

    Returns
    -------
    list of Path
        ``marginal.png``, ``graph.png``, ``global_symmetry.png`` (with ``symmetry_map.npy``:
        :func:`symmetry_map_figure`) and ``symmetry_<k>.png`` per extracted symmetry.
    """
    require("viz", "intrinsym.app.viz.render")
    result = Result.load(out_dir)
    target, source_shape = load_shapes(result, mesh_path)
    if target.is_cloud or (source_shape is not None and source_shape.is_cloud):
        raise InputError(f"{target.path}: figures need a triangle mesh, not a point cloud")
    n_source = len(result.source_points)
    if source is None:
        source = default_source(result)
    elif not 0 <= source < n_source:
        raise ParameterError(f"source sample must lie in [0, {n_source - 1}], got {source}")
    symmetries = load_symmetries(out_dir)
    folder = Path(figures_dir) if figures_dir is not None else Path(out_dir) / "figures"
    folder.mkdir(parents=True, exist_ok=True)
    paths = [marginal_figure(target, result, source, folder / "marginal.png", params, source_shape)]
    paths.append(graph_figure(source_shape or target, result, folder / "graph.png", params))
    map_path = Path(out_dir) / "symmetry_map.npy"
    if source_shape is None and map_path.is_file():
        found = load_symmetry_map(map_path, len(target.vertices), allow_missing=True)
        paths.append(symmetry_map_figure(target, found, folder / "global_symmetry.png", params))
    if source_shape is None:
        for k, record in enumerate(symmetries[:max_symmetries], start=1):
            paths.append(symmetry_figure(target, record, k, folder / f"symmetry_{k}.png", params))
    return paths
