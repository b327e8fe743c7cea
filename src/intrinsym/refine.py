"""A dense map refined by geodesic trilateration to the marginals' sample images.

Beyond the paper. On strongly posed shapes a spectral map (seeded ZoomOut) drifts by
0.05-0.1 sqrt(area) between the source samples, while BP's marginals place each sample's
image to within about the target spacing. Every vertex x is moved to the vertex y that
best keeps its geodesic distances to its ``k`` nearest source samples s_i when they are
measured from the samples' images a_i instead:

    y = argmin_y  sum_i (d(y, a_i) - d(x, s_i))^2,

found by steepest descent over the geodesic graph's neighbours, starting from x's
current image, so that y stays in the basin the map already chose (a thin part such as
an arm has a second, mirrored basin). A vertex whose current image already keeps the
distances to within ``tolerance`` (root mean square) keeps it: there the spectral map is
as precise as the anchors (a densely meshed, little posed head), and trilateration
would only add the anchors' own noise.

The anchors are the marginals' argmax targets; a sample whose argmax lies farther than
``agree`` from the map's own image of it is not used, so the marginals refine the map
only where they agree with the symmetry it chose.
"""

from __future__ import annotations

import numba as nb
import numpy as np
import scipy.sparse as sp

from ._dijkstra import balls, csr_arrays
from .geodesics import pair_distances

__all__ = ["agreeing_anchors", "trilaterate"]

#: Steepest-descent steps at most per vertex (each moves to a graph neighbour).
MAX_STEPS = 200


def _balls(
    graph: tuple[np.ndarray, np.ndarray, np.ndarray], sources: np.ndarray, limit: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Graph-geodesic distances from ``sources`` up to ``limit``, as sparse rows
    (:func:`intrinsym._dijkstra.balls`: radius-limited Dijkstra on Numba's threads;
    SciPy's ``dijkstra`` holds the GIL and fills every row to the graph's size).

    Returns
    -------
    rows, cols, dists : (nnz,) int64, int64, float64
        Source index, vertex and distance of every vertex within ``limit`` of a source.
    """
    counts, cols, dists = balls(*graph, sources, np.arange(len(graph[0]) - 1, dtype=np.int64), limit)
    return np.repeat(np.arange(len(sources)), counts), cols, dists


@nb.njit(cache=True)
def _nearest_sources(rows, cols, dists, n_vertices, queries, k):  # pragma: no cover
    """The ``k`` nearest sources of every query vertex (all of them where fewer are
    within reach), in ascending source order: CSR ``(ptr, source, distance)``."""
    start = np.zeros(n_vertices + 1, dtype=np.int64)
    for c in cols:
        start[c + 1] += 1
    for v in range(n_vertices):
        start[v + 1] += start[v]
    fill = start.copy()
    source = np.empty(len(cols), dtype=np.int64)
    distance = np.empty(len(cols))
    for e in range(len(cols)):  # rows ascend, so every vertex's list is in source order
        v = cols[e]
        source[fill[v]] = rows[e]
        distance[fill[v]] = dists[e]
        fill[v] += 1
    ptr = np.zeros(len(queries) + 1, dtype=np.int64)
    for q in range(len(queries)):
        v = queries[q]
        ptr[q + 1] = ptr[q] + min(k, start[v + 1] - start[v])
    out_source = np.empty(ptr[-1], dtype=np.int64)
    out_distance = np.empty(ptr[-1])
    for q in range(len(queries)):
        a = start[queries[q]]
        b = start[queries[q] + 1]
        taken = np.zeros(b - a, dtype=np.bool_)
        if b - a <= k:
            taken[:] = True
        else:
            for _ in range(k):
                best = -1
                for i in range(b - a):
                    if not taken[i] and (best < 0 or distance[a + i] < distance[a + best]):
                        best = i
                taken[best] = True
        j = ptr[q]
        for i in range(b - a):
            if taken[i]:
                out_source[j] = source[a + i]
                out_distance[j] = distance[a + i]
                j += 1
    return ptr, out_source, out_distance


def agreeing_anchors(graph: sp.spmatrix, anchors: np.ndarray, images: np.ndarray, agree: float) -> np.ndarray:
    """Which anchors lie within ``agree`` (graph geodesic) of the map's image of their sample.

    Parameters
    ----------
    graph : (N, N) sparse
        Geodesic graph of the working shape.
    anchors, images : (S,) int
        Working vertices: the marginals' image of each source sample, and the map's.
    agree : float
        Tolerance, in the graph's length units.

    Returns
    -------
    (S,) bool
    """
    pairs = np.stack([np.asarray(anchors, dtype=np.int64), np.asarray(images, dtype=np.int64)], axis=1)
    return pair_distances(graph, pairs, limit=agree) <= agree


@nb.njit(parallel=True, cache=True)
def _descend(start, ptr, sample, distance, image_distance, indptr, indices, need, tolerance2):  # pragma: no cover
    out = start.copy()
    for q in nb.prange(len(start)):
        a0 = ptr[q]
        a1 = ptr[q + 1]
        if a1 - a0 < need:
            continue
        y = start[q]
        best = 0.0
        for k in range(a0, a1):
            r = image_distance[y, sample[k]] - distance[k]
            best += r * r
        if best <= tolerance2 * (a1 - a0):
            continue
        for _ in range(MAX_STEPS):
            move = -1
            for e in range(indptr[y], indptr[y + 1]):
                z = indices[e]
                c = 0.0
                for k in range(a0, a1):
                    r = image_distance[z, sample[k]] - distance[k]
                    c += r * r
                    if c >= best:
                        break
                if c < best:
                    best = c
                    move = z
            if move < 0:
                break
            y = move
        out[q] = y
    return out


def trilaterate(
    graph: sp.spmatrix,
    queries: np.ndarray,
    start: np.ndarray,
    samples: np.ndarray,
    anchors: np.ndarray,
    k: int,
    tolerance: float,
    reach: float,
) -> np.ndarray:
    """Move each query vertex's image to where its geodesic distances to its ``k`` nearest
    samples are best kept from the samples' anchors.

    Parameters
    ----------
    graph : (N, N) sparse, symmetric
        Geodesic graph of the working shape (:func:`intrinsym.geodesics.surface_graph`);
        its neighbours are the descent's steps.
    queries : (n,) int
        Working vertices whose images are refined.
    start : (n,) int
        Their current images (working vertices).
    samples : (S,) int
        Working vertices of the source samples used as anchors.
    anchors : (S,) int
        Working vertex of each sample's image.
    k : int
        Nearest samples (by graph geodesic) each query is trilaterated against; a query
        with fewer within ``reach`` (an extremity such as a foot, whose anchors all lie
        on one side and leave it free to turn about the limb) keeps its image.
    tolerance : float
        A query whose current image keeps the distances to this root mean square residual
        keeps it (graph length units).
    reach : float
        Samples farther than this from a query are not its anchors; distances from an
        anchor are computed up to ``reach`` plus twice the tolerance further, and count
        as that far beyond it (graph length units).

    Returns
    -------
    (n,) int64
        Refined images; ``start`` where fewer than ``k`` samples are within ``reach`` or
        the current image is within ``tolerance``.
    """
    queries = np.asarray(queries, dtype=np.int64)
    start = np.asarray(start, dtype=np.int64)
    if len(queries) != len(start):
        raise ValueError(f"queries and start differ in length: {len(queries)} and {len(start)}")
    if len(samples) != len(anchors):
        raise ValueError(f"samples and anchors differ in length: {len(samples)} and {len(anchors)}")
    if k < 1 or len(samples) == 0:
        return start.copy()
    arrays = csr_arrays(graph)
    n = len(arrays[0]) - 1
    k = min(k, len(samples))
    ptr, sample, distance = _nearest_sources(*_balls(arrays, np.asarray(samples, dtype=np.int64), reach), n, queries, k)
    horizon = reach + 2.0 * tolerance
    rows, cols, dists = _balls(arrays, np.asarray(anchors, dtype=np.int64), horizon)
    image_distance = np.full((n, len(anchors)), 2.0 * horizon, dtype=np.float32)
    image_distance[cols, rows] = dists
    indptr, indices, _ = arrays
    return _descend(
        start,
        ptr,
        sample,
        distance,
        image_distance,
        indptr,
        indices,
        k,
        tolerance**2,
    )
