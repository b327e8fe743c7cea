"""How far a vertex map is from an isometry, with no ground truth needed.

The distortion of a pair of vertices (x, y) under a map T is ``|d(T x, T y) - d(x, y)|``,
graph geodesics in units of sqrt(area). Applied to a ground-truth symmetry it tells how
near to an isometry a pose keeps its symmetry, the premise of the model; applied to a
found map, how isometric that map is.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..geodesics import geodesics
from ..geodesics._dijkstra import ball_pairs, csr_arrays
from ..mesh.sampling import farthest_point_sampling
from ..mesh.shape import Shape, surface_area

__all__ = [
    "DISTORTION_RADIUS",
    "LOCAL_RADIUS",
    "LOCAL_SPACING",
    "THRESHOLDS",
    "DistortionScores",
    "local_distortion",
    "graph_map_distortion",
    "local_distortion_on_graph",
    "map_distortion",
]

#: Distortion thresholds of :class:`DistortionScores`, in units of sqrt(area).
THRESHOLDS = np.linspace(0.0, 0.25, 51)
#: Pairs of :func:`map_distortion` lie within this geodesic distance (sqrt(area) units).
DISTORTION_RADIUS = 0.5
#: Pairs of :func:`local_distortion` lie within this geodesic distance (sqrt(area) units):
#: about a finger's length on a TOSCA human.
LOCAL_RADIUS = 0.1
#: Spacing of the vertices :func:`local_distortion` measures from (sqrt(area) units).
LOCAL_SPACING = 0.04


@dataclass(frozen=True)
class DistortionScores:
    """How far a vertex map is from an isometry, with no ground truth needed.

    The distortion of a pair of vertices (x, y) is ``|d(T x, T y) - d(x, y)|``, graph
    geodesics in units of sqrt(area), over pairs with ``d(x, y) <= radius``; it is
    computed up to the largest threshold and clipped there, so ``fraction`` is exact and
    ``mean`` a lower bound.

    Attributes
    ----------
    thresholds : (K,) float64
        Distortion thresholds t.
    fraction : (K,) float64
        Fraction of the pairs whose distortion exceeds t.
    mean : float
        Mean (clipped) distortion.
    radius : float
        Largest ``d(x, y)`` of a pair.
    n_pairs : int
        Pairs measured.
    """

    thresholds: np.ndarray
    fraction: np.ndarray
    mean: float
    radius: float
    n_pairs: int

    def above(self, t: float) -> float:
        """Fraction of pairs whose distortion exceeds ``t`` (the curve at its nearest
        threshold <= t)."""
        return float(self.fraction[np.searchsorted(self.thresholds, t + 1e-12) - 1])

    def as_dict(self) -> dict:
        return {
            "above_0.05": self.above(0.05),
            "above_0.10": self.above(0.10),
            "mean": self.mean,
            "radius": self.radius,
            "n_pairs": self.n_pairs,
        }


def map_distortion(
    vertex_map: np.ndarray,
    shape: Shape,
    radius: float = DISTORTION_RADIUS,
    n_sources: int = 200,
    seed: int = 0,
    thresholds: np.ndarray = THRESHOLDS,
    unit: tuple | None = None,
) -> DistortionScores:
    """How much a vertex map changes geodesic distances (:class:`DistortionScores`).

    Applied to a ground-truth symmetry it tells how near to an isometry the pose keeps
    its symmetry, the premise of the model; applied to a found map, how isometric that
    map is, without ground truth.

    Parameters
    ----------
    vertex_map : (N,) int
        Image input vertex of every input vertex, -1 for none (such vertices are left out).
    shape : Shape
        The input mesh or point cloud as loaded (normalised to unit area here).
    radius : float
        Pairs lie within this distance (sqrt(area) units).
    n_sources : int
        Vertices x, drawn at random (``seed``) among those with an image; every y within
        ``radius`` of one is paired with it.
    seed : int
    thresholds : (K,) float
        Distortion thresholds (sqrt(area) units).
    unit : tuple, optional
        ``geodesics.unit_area_graph(shape)``, when the caller has it already.

    Returns
    -------
    DistortionScores
    """
    cleaned, vmap, graph = unit if unit is not None else geodesics.unit_area_graph(shape)
    image = _cleaned_image(vertex_map, shape, vmap, len(cleaned.vertices))
    return graph_map_distortion(image, graph, graph, radius, n_sources, seed, thresholds)


def graph_map_distortion(
    image: np.ndarray,
    graph: sp.spmatrix,
    target_graph: sp.spmatrix,
    radius: float = DISTORTION_RADIUS,
    n_sources: int = 200,
    seed: int = 0,
    thresholds: np.ndarray = THRESHOLDS,
    balls: Callable[[np.ndarray, float], tuple[np.ndarray, np.ndarray, np.ndarray]] | None = None,
) -> DistortionScores:
    """:func:`map_distortion` of a map between the vertices of two geodesic graphs (one
    graph twice for a self-map), distances in the graphs' own unit.

    Parameters
    ----------
    image : (N,) int
        Vertex of ``target_graph`` of every vertex of ``graph``, -1 for none (left out).
    graph : (N, N) scipy.sparse matrix
        Geodesic graph of the map's domain.
    target_graph : (M, M) scipy.sparse matrix
        Of its codomain, in the same unit.
    radius, n_sources, seed, thresholds
        As for :func:`map_distortion`.
    balls : callable, optional
        ``balls(sources, limit)``: ``graph``'s balls as :func:`ball_pairs` gives them, when
        the caller keeps them (:meth:`intrinsym.surface.Surface.balls`).

    Returns
    -------
    DistortionScores
    """
    image = np.asarray(image, dtype=np.int64)
    mapped = np.flatnonzero(image >= 0)
    thresholds = np.asarray(thresholds, dtype=np.float64)
    if len(mapped) == 0:
        return DistortionScores(thresholds, np.full(len(thresholds), np.nan), float("nan"), radius, 0)
    x = np.random.default_rng(seed).choice(mapped, size=min(n_sources, len(mapped)), replace=False)
    top = float(thresholds.max())
    rows, ys, d = ball_pairs(csr_arrays(graph), x, radius) if balls is None else balls(x, radius)
    keep = (image[ys] >= 0) & (ys != x[rows])
    rows, ys, d = rows[keep], ys[keep], d[keep]
    # d(T x, T y) up to radius + top: a pair beyond changes by at least top
    image_rows, image_cols, image_d = ball_pairs(csr_arrays(target_graph), image[x], radius + top)
    d_image = np.full((len(x), target_graph.shape[0]), radius + top)
    d_image[image_rows, image_cols] = image_d
    change = np.minimum(np.abs(d_image[rows, image[ys]] - d), top)
    fraction = 1.0 - np.searchsorted(np.sort(change), thresholds, side="right") / max(len(change), 1)
    mean = float(change.mean()) if len(change) else float("nan")
    return DistortionScores(thresholds, fraction, mean, radius, len(change))


def _cleaned_image(vertex_map: np.ndarray, shape: Shape, vmap: np.ndarray, n_cleaned: int) -> np.ndarray:
    """Image cleaned vertex of every cleaned vertex (the first input vertex it represents
    decides), -1 for none."""
    image_in = np.asarray(vertex_map, dtype=np.int64)
    if image_in.shape != (len(shape.vertices),):
        raise ValueError(f"vertex_map has shape {image_in.shape}, expected ({len(shape.vertices)},)")
    first = np.empty(n_cleaned, dtype=np.int64)
    first[vmap[::-1]] = np.arange(len(vmap))[::-1]
    return np.where(image_in[first] >= 0, vmap[np.maximum(image_in[first], 0)], -1)


def local_distortion_on_graph(
    graph: sp.spmatrix,
    points: np.ndarray,
    image: np.ndarray,
    radius: float = LOCAL_RADIUS,
    spacing: float = LOCAL_SPACING,
    clip: float = LOCAL_RADIUS,
    target_graph: sp.spmatrix | None = None,
) -> np.ndarray:
    """:func:`local_distortion` of a map between the vertices of one geodesic graph, or
    from one graph's vertices to another's.

    Parameters
    ----------
    graph : (N, N) sparse
        Geodesic graph (:func:`intrinsym.geodesics.geodesics.surface_graph`), sqrt(area) units.
    points : (N, 3) float array
        Vertex positions in the same units (for the farthest-point sample).
    image : (N,) int
        Image vertex of every vertex, -1 for none.
    radius, spacing, clip : float
        As in :func:`local_distortion`.
    target_graph : (M, M) sparse, optional
        The codomain's geodesic graph, in the same unit (default ``graph``: a self-map).

    Returns
    -------
    (N,) float64
        NaN where the vertex has no image or its cell no mapped pair.
    """
    image = np.asarray(image, dtype=np.int64)
    n = len(image)
    mapped = np.flatnonzero(image >= 0)
    out = np.full(n, np.nan)
    if len(mapped) == 0:
        return out
    seeds = np.sort(mapped[farthest_point_sampling(np.asarray(points)[mapped], spacing=spacing, seed=0)])
    rows, ys, d = ball_pairs(csr_arrays(graph), seeds, radius)
    keep = (image[ys] >= 0) & (ys != seeds[rows])
    rows, ys, d = rows[keep], ys[keep], d[keep]
    # d(T x, T y) up to radius + clip: a pair beyond changes by at least clip
    beyond = radius + clip
    pairs = np.column_stack([image[seeds[rows]], image[ys]])
    codomain = graph if target_graph is None else target_graph
    d_image = np.minimum(geodesics.pair_distances(codomain, pairs, beyond), beyond)
    change = np.minimum(np.abs(d_image - d), clip)
    count = np.bincount(rows, minlength=len(seeds))
    total = np.bincount(rows, weights=change, minlength=len(seeds))
    per_seed = np.where(count > 0, total / np.maximum(count, 1), np.nan)
    cell = geodesics.voronoi_cells(graph, seeds)
    out[mapped] = np.where(cell[mapped] >= 0, per_seed[np.maximum(cell[mapped], 0)], np.nan)
    return out


def local_distortion(
    vertex_map: np.ndarray,
    shape: Shape,
    radius: float = LOCAL_RADIUS,
    spacing: float = LOCAL_SPACING,
    clip: float = LOCAL_RADIUS,
    unit: tuple | None = None,
) -> np.ndarray:
    """Per vertex, how much a vertex map changes the geodesic distances around it.

    Mapped vertices ``spacing`` apart (farthest-point sample) are paired with every mapped
    vertex within ``radius``; each vertex gets the mean distortion ``|d(T x, T y) - d(x,
    y)|`` of the pairs of its nearest such vertex (geodesic Voronoi cell). Applied to a
    found map it tells, with no ground truth, where the map is not locally an isometry,
    which is where it tends to be wrong (the confidence's tables,
    :func:`intrinsym.globalmap.confidence.calibrated`); applied to a ground-truth symmetry, where
    the truth itself is not one (a hand whose fingers the symmetry file does not match
    isometrically), where no isometry-based method can be asked to find it.

    Parameters
    ----------
    vertex_map : (N,) int
        Image input vertex of every input vertex, -1 for none (such pairs are left out).
    shape : Shape
        The input mesh as loaded (normalised to unit area here).
    radius : float
        Pairs lie within this distance (sqrt(area) units).
    spacing : float
        Spacing of the measured vertices (sqrt(area) units).
    clip : float
        Distortions are computed up to this and clipped there (sqrt(area) units).
    unit : tuple, optional
        ``geodesics.unit_area_graph(shape)``, when the caller has it already.

    Returns
    -------
    (N,) float64
        Mean clipped distortion (sqrt(area) units); NaN where the vertex has no image or
        its cell no mapped pair.
    """
    cleaned, vmap, graph = unit if unit is not None else geodesics.unit_area_graph(shape)
    image = _cleaned_image(vertex_map, shape, vmap, len(cleaned.vertices))
    points = cleaned.vertices / np.sqrt(surface_area(cleaned))
    per_vertex = local_distortion_on_graph(graph, points, image, radius, spacing, clip)[vmap]
    return np.where(np.asarray(vertex_map) >= 0, per_vertex, np.nan)
