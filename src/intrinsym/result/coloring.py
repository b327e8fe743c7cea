"""Vertex colours that show a symmetry map at a glance, shared by the viewer, the figures
and the exports.

Three ways to colour a map ``m`` (the image vertex of every vertex, -1 for none):

* ``side``: the two sides of the symmetry in two colours (:data:`SIDE_COLORS`), the
  points it leaves in place (within :data:`FIXED` sqrt(area) of their image, straight
  distance) white, the points
  without a partner grey. The sides are the vertices nearer a seed ``a`` than its image
  ``m[a]`` and those nearer ``m[a]`` (geodesically on a mesh); of :data:`SEEDS` seeds
  among the quarter of vertices farthest from their images, the one whose split ``m``
  swaps most often, so a swap of the two halves shows as two colours;
* ``partner``: every point coloured like its partner: the mean of a smooth colouring
  of the shape (its normalised coordinates as RGB) at the point and at its image, each
  channel stretched to the full range, so symmetric points share a colour and the
  pairing shows as matching colours;
* ``confidence``: the map's per-vertex confidence on a heat scale (blue 0, red 1).
"""

from __future__ import annotations

import numpy as np

from ..geodesics import geodesics
from ..mesh.shape import Shape, surface_area

#: Colour modes of :func:`vertex_colors`.
MODES = ("side", "partner", "confidence")
#: The two sides of a symmetry, RGB in [0, 1].
SIDE_COLORS = ((0.90, 0.45, 0.15), (0.18, 0.45, 0.85))
#: A point the symmetry leaves in place.
FIXED_COLOR = (1.0, 1.0, 1.0)
#: A point without a partner (-1 in ``symmetry_map.npy``).
NONE_COLOR = (0.6, 0.6, 0.6)
#: Heat scale of the confidence, from 0 to 1.
HEAT = ((0.13, 0.25, 0.82), (0.25, 0.75, 0.94), (0.94, 0.94, 0.63), (0.94, 0.5, 0.19), (0.82, 0.06, 0.06))
#: Seeds tried for the two sides (:func:`sides`).
SEEDS = 8
#: Distance (sqrt(area) units) within which a point counts as left in place.
FIXED = 0.02


def legend(mode: str) -> list[tuple[str, tuple[float, float, float]]]:
    """(label, RGB) entries that explain the colours of ``mode``."""
    if mode == "side":
        return [
            ("one side", SIDE_COLORS[0]),
            ("its mirror side", SIDE_COLORS[1]),
            ("fixed (maps to itself)", FIXED_COLOR),
            ("no partner", NONE_COLOR),
        ]
    if mode == "partner":
        return [("same colour = symmetric partners", (0.5, 0.7, 0.5)), ("no partner", NONE_COLOR)]
    return [("confidence 0", HEAT[0]), ("0.5", HEAT[2]), ("1", HEAT[-1]), ("no partner", NONE_COLOR)]


def _distances(shape: Shape, sources: np.ndarray, unit: tuple | None) -> np.ndarray:
    """(len(sources), N) distances: geodesic on a mesh (``unit``: its
    :func:`intrinsym.geodesics.geodesics.unit_area_graph`), straight on a cloud (``unit`` None)."""
    v = np.asarray(shape.vertices, dtype=np.float64)
    if unit is None:
        return np.linalg.norm(v[None, :, :] - v[sources][:, None, :], axis=2)
    _, vmap, graph = unit
    return geodesics.distances_from(graph, vmap[sources])[:, vmap]


def sides(shape: Shape, symmetry_map: np.ndarray) -> np.ndarray:
    """(N,) int8: 0 / 1 for the two sides of the map, 2 for a point it leaves in place,
    -1 for a point without a partner."""
    m = np.asarray(symmetry_map, dtype=np.int64)
    out = np.full(len(m), -1, dtype=np.int8)
    has = np.flatnonzero(m >= 0)
    if not len(has):
        return out
    v = np.asarray(shape.vertices, dtype=np.float64)
    scale = np.sqrt(surface_area(shape)) if shape.faces is not None and len(shape.faces) else float(np.ptp(v))
    gap = np.linalg.norm(v[has] - v[m[has]], axis=1) / max(scale, 1e-12)
    far = has[gap >= np.quantile(gap, 0.75)]
    seeds = np.random.default_rng(0).choice(far, size=min(SEEDS, len(far)), replace=False)
    best, agree = np.zeros(len(has), dtype=np.int8), -1.0
    mesh = shape.faces is not None and len(shape.faces) > 0
    unit = geodesics.unit_area_graph(shape) if mesh else None
    for a in seeds:
        d = _distances(shape, np.array([a, m[a]]), unit)
        split = np.where(d[0] <= d[1], 0, 1).astype(np.int8)
        swapped = float(np.mean(split[has] != split[m[has]]))
        if swapped > agree:
            best, agree = split[has], swapped
    out[has] = best
    out[has[gap <= FIXED]] = 2
    return out


def side_colors(side: np.ndarray) -> np.ndarray:
    """(N, 3) RGB of :func:`sides`' labels."""
    return np.array([*SIDE_COLORS, FIXED_COLOR, NONE_COLOR])[np.asarray(side)]


def smooth_colors(vertices: np.ndarray) -> np.ndarray:
    """(N, 3) RGB of each vertex from its coordinates normalised to the bounding box."""
    v = np.asarray(vertices, dtype=np.float64)
    low, span = v.min(axis=0), np.maximum(np.ptp(v, axis=0), 1e-12)
    return 0.15 + 0.8 * (v - low) / span


def heat(values: np.ndarray) -> np.ndarray:
    """(N, 3) RGB of values in [0, 1] on the :data:`HEAT` scale."""
    x = np.clip(np.nan_to_num(np.asarray(values, dtype=np.float64)), 0.0, 1.0) * (len(HEAT) - 1)
    stops = np.asarray(HEAT)
    low = np.minimum(x.astype(np.int64), len(HEAT) - 2)
    t = (x - low)[:, None]
    return (1 - t) * stops[low] + t * stops[low + 1]


def _stretch(rgb: np.ndarray, least: float = 0.2) -> np.ndarray:
    """Each channel that spans at least ``least`` stretched to [0.15, 0.95]: the mean of a
    point's colour and its partner's varies little across the symmetry, so contrast is
    restored along it (the same map for every point keeps partners alike)."""
    out = np.array(rgb, dtype=np.float64)
    if not len(out):
        return out
    low, span = out.min(axis=0), np.ptp(out, axis=0)
    wide = span >= least
    out[:, wide] = 0.15 + 0.8 * (out[:, wide] - low[wide]) / span[wide]
    return out


def vertex_colors(
    shape: Shape, symmetry_map: np.ndarray, mode: str = "side", confidence: np.ndarray | None = None
) -> np.ndarray:
    """(N, 3) float RGB in [0, 1] of every vertex under ``mode`` (one of :data:`MODES`).

    Parameters
    ----------
    shape : Shape
        The input as loaded (``symmetry_map`` indexes its vertices).
    symmetry_map : (N,) int
        The image vertex of every vertex, -1 for none.
    mode : str
    confidence : (N,) float, optional
        Needed for ``confidence``.
    """
    if mode not in MODES:
        raise ValueError(f"colour mode {mode!r}: expected one of {', '.join(MODES)}")
    m = np.asarray(symmetry_map, dtype=np.int64)
    none = m < 0
    if mode == "side":
        return side_colors(sides(shape, m))
    if mode == "partner":
        base = smooth_colors(shape.vertices)
        rgb = 0.5 * (base + base[np.where(none, np.arange(len(m)), m)])
        rgb[~none] = _stretch(rgb[~none])
    else:
        if confidence is None:
            raise ValueError("the confidence colours need the confidence (symmetry_confidence.npy)")
        rgb = heat(confidence)
    rgb[none] = NONE_COLOR
    return rgb


def as_rgba8(rgb: np.ndarray) -> np.ndarray:
    """(N, 4) uint8 RGBA of (N, 3) RGB in [0, 1], opaque."""
    out = np.full((len(rgb), 4), 255, dtype=np.uint8)
    out[:, :3] = np.round(np.clip(rgb, 0.0, 1.0) * 255)
    return out


def hex_color(rgb: tuple[float, float, float]) -> str:
    """``#rrggbb`` of an RGB triple in [0, 1]."""
    return "#" + "".join(f"{round(255 * c):02x}" for c in rgb)
