"""Point sampling on meshes and point sets.

Farthest-point (Poisson-disc style) sampling of vertices, area-uniform random points on
a triangle surface, midpoint subdivision up to a vertex count, and the typical spacing
of ``n`` evenly spread samples on a surface of given area.

All lengths are in the units of the input coordinates.
"""

from __future__ import annotations

import numba as nb
import numpy as np

__all__ = [
    "area_uniform_points",
    "farthest_point_sampling",
    "spacing_for_count",
    "subdivide_to",
]


@nb.njit(cache=True, nogil=True)
def _fps_kernel(x: np.ndarray, y: np.ndarray, z: np.ndarray, start: int, n_max: int, min_sq: float) -> np.ndarray:
    """Greedy farthest-point selection.

    Parameters
    ----------
    x, y, z : (N,) float64
        Coordinates, one contiguous array per axis (vectorises the distance update).
    start : int
        Index of the first selected point.
    n_max : int
        Maximum number of points to select.
    min_sq : float
        Stop before adding a point whose squared distance to the selected set is below
        this value (0 disables the test).

    Returns
    -------
    (k,) int64
        Selected indices in selection order, ``k <= n_max``; ``k < n_max`` when the
        stop test fires or every point coincides with a selected one.
    """
    n_pts = x.shape[0]
    chosen = np.empty(n_max, dtype=np.int64)
    best = np.full(n_pts, np.inf)
    current = start
    count = 0
    while True:
        chosen[count] = current
        count += 1
        cx = x[current]
        cy = y[current]
        cz = z[current]
        for i in range(n_pts):
            dx = x[i] - cx
            dy = y[i] - cy
            dz = z[i] - cz
            best[i] = min(best[i], dx * dx + dy * dy + dz * dz)
        # np.argmax, written out: its implementation adds 0.5 s to the first run's compilation
        current = 0
        for i in range(1, n_pts):
            if best[i] > best[current]:
                current = i
        far_sq = best[current]
        if count == n_max or far_sq < min_sq or far_sq <= 0.0:
            return chosen[:count]


def farthest_point_sampling(
    points: np.ndarray,
    n: int | None = None,
    spacing: float | None = None,
    seed: int = 0,
) -> np.ndarray:
    """Farthest-point sample of a point set (Euclidean).

    Starts from a point drawn with ``np.random.default_rng(seed)`` and repeatedly adds
    the point farthest from the points chosen so far. Let ``r`` be the final covering
    distance (the largest distance from any input point to its nearest chosen point).
    Every chosen point was the farthest one when it was added, so any two chosen points
    are at least ``r`` apart, and every input point lies within ``r`` of a chosen one:
    the result is a maximal Poisson-disc set of radius ``r``.

    Parameters
    ----------
    points : (N, 3) float array
        Coordinates (typically mesh vertices).
    n : int, optional
        Number of points to select (``1 <= n <= N``).
    spacing : float, optional
        Select until the largest remaining distance to the chosen set falls below
        ``spacing`` (same units as ``points``). Then all chosen points are at least
        ``spacing`` apart and every point lies within ``spacing`` of a chosen one.
        Exactly one of ``n`` and ``spacing`` must be given.
    seed : int
        Seed of the start point; the result is deterministic for a given seed.

    Returns
    -------
    (k,) int64
        Indices into ``points`` in selection order (``k == n`` in count mode).

    Raises
    ------
    ValueError
        If not exactly one of ``n``/``spacing`` is given, ``n`` is out of range or larger
        than the number of distinct positions, or ``spacing`` is not positive.
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) == 0:
        raise ValueError(f"points must be a non-empty (N, 3) array, got shape {pts.shape}")
    if (n is None) == (spacing is None):
        raise ValueError("give exactly one of n (count) or spacing")
    n_pts = len(pts)
    if n is not None:
        if n < 1:
            raise ValueError(f"n must be >= 1, got {n}")
        if n > n_pts:
            raise ValueError(f"cannot select n={n} points from a set of only {n_pts} points")
        n_max, min_sq = int(n), 0.0
    else:
        if spacing is None or not spacing > 0:
            raise ValueError(f"spacing must be positive, got {spacing}")
        n_max, min_sq = n_pts, float(spacing) ** 2
    start = int(np.random.default_rng(seed).integers(n_pts))
    x, y, z = (np.ascontiguousarray(pts[:, k]) for k in range(3))
    chosen = _fps_kernel(x, y, z, start, n_max, min_sq)
    if n is not None and len(chosen) < n:
        raise ValueError(f"cannot select n={n} points: the set has only {len(chosen)} distinct positions")
    return chosen


def area_uniform_points(
    vertices: np.ndarray, faces: np.ndarray, n: int, seed: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random points distributed uniformly by area on a triangle surface.

    A triangle is drawn with probability proportional to its area, then a point uniform
    inside it (barycentric ``(1 - sqrt(u), sqrt(u) (1 - v), sqrt(u) v)`` for uniform
    ``u, v``).

    Parameters
    ----------
    vertices : (V, 3) float array
    faces : (F, 3) int array
    n : int
        Number of points.
    seed : int
        Seed of ``np.random.default_rng``; deterministic per seed.

    Returns
    -------
    points : (n, 3) float64
        Positions, same units as ``vertices``.
    face_index : (n,) int64
        Triangle containing each point.
    barycentric : (n, 3) float64
        Barycentric coordinates with respect to ``faces[face_index]`` (rows sum to 1).
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if n < 0:
        raise ValueError(f"n must be >= 0, got {n}")
    tri = v[f]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    total = area.sum()
    if not total > 0:
        raise ValueError("the mesh has zero area")
    rng = np.random.default_rng(seed)
    cdf = np.cumsum(area) / total
    face_index = np.searchsorted(cdf, rng.random(n) * cdf[-1], side="right")
    face_index = np.minimum(face_index, len(f) - 1).astype(np.int64)
    su = np.sqrt(rng.random(n))
    w = rng.random(n)
    bary = np.stack([1.0 - su, su * (1.0 - w), su * w], axis=1)
    points = np.einsum("nk,nkd->nd", bary, tri[face_index])
    return points, face_index, bary


def subdivide_to(vertices: np.ndarray, faces: np.ndarray, min_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """Midpoint-subdivide a triangle mesh until it has at least ``min_vertices`` vertices.

    Each round splits every triangle into four (``trimesh.remesh.subdivide``); the
    geometry is unchanged. Original vertices keep their indices ``0..V-1`` and the new
    edge midpoints follow them.

    Parameters
    ----------
    vertices : (V, 3) float array
    faces : (F, 3) int array
    min_vertices : int

    Returns
    -------
    vertices : (V', 3) float64
        ``V' >= min_vertices`` (or the input if it already has enough vertices).
    faces : (F', 3) int64
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if len(v) >= min_vertices:
        return v, f
    if len(f) == 0:
        raise ValueError("cannot subdivide a mesh without faces")
    import trimesh.remesh  # here, not at the top: importing trimesh costs 0.2 s

    while len(v) < min_vertices:
        n_before = len(v)
        v_new, f_new = trimesh.remesh.subdivide(v, f)
        v_new = np.asarray(v_new, dtype=np.float64)
        f_new = np.asarray(f_new, dtype=np.int64)
        # trimesh appends the midpoints after the original vertices; check, do not assume.
        if not np.array_equal(v_new[:n_before], v):
            raise RuntimeError("trimesh.remesh.subdivide reordered the original vertices")
        v, f = v_new, f_new
    return v, f


def spacing_for_count(area: float, n: int) -> float:
    """Typical spacing of ``n`` evenly spread samples on a surface of the given area.

    In a hexagonal packing with nearest-neighbour distance ``s`` each sample owns a
    hexagon of area ``sqrt(3) / 2 * s**2``, so ``s = sqrt(2 * area / (sqrt(3) * n))``.

    Parameters
    ----------
    area : float
        Surface area (length units squared).
    n : int
        Number of samples (> 0).

    Returns
    -------
    float
        Spacing in length units.
    """
    if n <= 0:
        raise ValueError(f"n must be positive, got {n}")
    if area < 0:
        raise ValueError(f"area must be non-negative, got {area}")
    return float(np.sqrt(2.0 * area / (np.sqrt(3.0) * n)))
