"""How far a vertex map is from an isometry, with no ground truth needed.

The distortion of a pair of vertices (x, y) under a map T is ``|d(T x, T y) - d(x, y)|``,
graph geodesics in units of sqrt(area). Applied to a ground-truth symmetry it tells how
near to an isometry a pose keeps its symmetry, the premise of the model; applied to a
found map, how isometric that map is.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import geodesics
from ._dijkstra import ball_pairs, csr_arrays
from .shape import Shape

__all__ = ["DISTORTION_RADIUS", "THRESHOLDS", "DistortionScores", "map_distortion"]

#: Distortion thresholds of :class:`DistortionScores`, in units of sqrt(area).
THRESHOLDS = np.linspace(0.0, 0.25, 51)
#: Pairs of :func:`map_distortion` lie within this geodesic distance (sqrt(area) units).
DISTORTION_RADIUS = 0.5


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
    image_in = np.asarray(vertex_map, dtype=np.int64)
    if image_in.shape != (len(shape.vertices),):
        raise ValueError(f"vertex_map has shape {image_in.shape}, expected ({len(shape.vertices)},)")
    # every cleaned vertex takes the image of the first input vertex it represents
    first = np.empty(len(cleaned.vertices), dtype=np.int64)
    first[vmap[::-1]] = np.arange(len(vmap))[::-1]
    image = np.where(image_in[first] >= 0, vmap[np.maximum(image_in[first], 0)], -1)
    mapped = np.flatnonzero(image >= 0)
    thresholds = np.asarray(thresholds, dtype=np.float64)
    if len(mapped) == 0:
        return DistortionScores(thresholds, np.full(len(thresholds), np.nan), float("nan"), radius, 0)
    x = np.random.default_rng(seed).choice(mapped, size=min(n_sources, len(mapped)), replace=False)
    top = float(thresholds.max())
    arrays = csr_arrays(graph)
    rows, ys, d = ball_pairs(arrays, x, radius)
    keep = (image[ys] >= 0) & (ys != x[rows])
    rows, ys, d = rows[keep], ys[keep], d[keep]
    # d(T x, T y) up to radius + top: a pair beyond changes by at least top
    image_rows, image_cols, image_d = ball_pairs(arrays, image[x], radius + top)
    d_image = np.full((len(x), len(image)), radius + top)
    d_image[image_rows, image_cols] = image_d
    change = np.minimum(np.abs(d_image[rows, image[ys]] - d), top)
    fraction = 1.0 - np.searchsorted(np.sort(change), thresholds, side="right") / max(len(change), 1)
    mean = float(change.mean()) if len(change) else float("nan")
    return DistortionScores(thresholds, fraction, mean, radius, len(change))
