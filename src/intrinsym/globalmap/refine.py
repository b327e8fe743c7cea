"""A dense map refined by geodesic trilateration to the marginals' sample images, then
smoothed in the eigenfunctions.

Beyond the paper. On strongly posed shapes a spectral map (seeded ZoomOut) drifts by
0.05-0.1 sqrt(area) between the source samples, while BP's marginals place each sample's
image to within about the target spacing. Every vertex x is moved to the vertex y that
best keeps its geodesic distances to its ``k`` nearest source samples s_i when they are
measured from the samples' images a_i instead:

    y = argmin_y  sum_i (d(y, a_i) - d(x, s_i))^2,

found by steepest descent over the geodesic graph's neighbours, starting from x's
current image, so that y stays in the basin the map already chose (a thin part such as
an arm has a second, mirrored basin). A vertex whose current image already keeps the
distances to within ``tolerance`` (root mean square), and the distance to its nearest
anchor too, keeps it: there the spectral map is as precise as the anchors (a densely
meshed, little posed head), and trilateration would only add the anchors' own noise. The
nearest anchor is what catches the tip of a limb turned about the limb: that turn keeps
the distances to the anchors up the limb, which hold the mean down.

The anchors are the marginals' argmax targets; a sample whose argmax lies farther than
``agree`` from the map's own image of it is used only where the argmax keeps the
geodesic distances to the agreeing anchors better than the map's image does and the map
turned that sample the wrong way round, or moved it beyond the trivial radius of itself
(:func:`consistent_anchors`): there the spectral map flipped or slid a part (a densely
meshed head turned about the wrong axis) that the marginals place right. Elsewhere, the
marginals refine the map only where they agree with the symmetry it chose.

Trilateration moves each vertex on its own, so neighbouring images scatter by a vertex
or two. :func:`spectral_descent` then projects the map once onto the Laplace-Beltrami
eigenfunctions (a least-squares functional map, which keeps only its smooth part) and
moves every image, again by steepest descent over the graph from where it is, to the
vertex nearest its projection.
"""

from __future__ import annotations

import numba as nb
import numpy as np
import scipy.sparse as sp

from .._threads import map_ranges
from ..extract.reflection import reversed_turns
from ..geodesics._dijkstra import ball_pairs, csr_arrays
from ..geodesics.geodesics import distances_to, pair_distances

__all__ = ["agreeing_anchors", "consistent_anchors", "spectral_descent", "trilaterate"]

#: Steepest-descent steps at most per vertex (each moves to a graph neighbour).
MAX_STEPS = 200


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


def consistent_anchors(
    graph: sp.spmatrix,
    samples: np.ndarray,
    anchors: np.ndarray,
    images: np.ndarray,
    agree: float,
    k: int,
    reach: float,
    orientation: tuple[np.ndarray, np.ndarray, np.ndarray],
    trivial: float = np.inf,
) -> np.ndarray:
    """:func:`agreeing_anchors`, plus the disagreeing anchors that keep the geodesic
    distances better, where the marginals can be trusted over the map.

    For a sample s whose anchor a lies farther than ``agree`` from the map's image m, a
    is kept when

    - a turns s the way the map turns most samples (a reflection reverses the order of
      a sample's neighbours, :func:`intrinsym.extract.reflection.reversed_turns`; a rotation
      keeps it), and either the map does not (it flipped the part s lies on: a densely
      meshed head turned about the wrong axis) or m lies farther than ``trivial`` from
      s (the map moved s to the wrong place on a part it turned the right way);
    - with s_i its (at most ``k``) nearest samples within ``reach`` whose anchors a_i
      agree, ``rms_i (d(a, a_i) - d(s, s_i)) < rms_i (d(m, a_i) - d(s, s_i))``, image
      distances beyond ``reach + 2 agree`` counting as that far: the argmax of a sample
      whose marginal holds another symmetry (another limb) keeps them far worse.

    Where the map turns a sample the right way and keeps it within ``trivial`` of
    itself, a disagreeing marginal is not trusted: on the midline of a reflection the
    true image lies within the trivial radius the model removed, so the marginal's
    argmax is pushed off it (TOSCA centaur3's head: 85 % of the mass 0.12 from the true
    image), and keeps the distances as well.

    Parameters
    ----------
    graph : (N, N) sparse, symmetric
        Geodesic graph of the working shape.
    samples, anchors, images : (S,) int
        Working vertices: each source sample, its anchor (the marginals' image of it)
        and the map's image of it.
    agree : float
        Tolerance of :func:`agreeing_anchors` (graph length units).
    k : int
        Agreeing samples each disagreeing anchor is judged against.
    reach : float
        Agreeing samples farther than this from the sample are not used (graph length
        units).
    orientation : ((E, 2) int, (N, 3) float, (N, 3) float)
        Source-graph edges (rows of ``samples``), and the working shape's vertex
        positions and outward unit normals.
    trivial : float
        The radius of the trivial match the model weakened (graph length units); ``inf``
        (the default): only the samples the map turned the wrong way round.

    Returns
    -------
    (S,) bool
    """
    keep = agreeing_anchors(graph, anchors, images, agree)
    if keep.all() or not keep.any():
        return keep
    samples = np.asarray(samples, dtype=np.int64)
    anchors = np.asarray(anchors, dtype=np.int64)
    images = np.asarray(images, dtype=np.int64)
    edges, points, normals = orientation
    by_map, by_anchor = (
        reversed_turns(image, edges, points[samples], points, normals[samples], normals) for image in (images, anchors)
    )
    usual = 2 * np.count_nonzero(by_map) >= len(by_map)
    doubt = ~keep & (by_anchor == usual)
    map_wrong = by_map != usual
    unturned = np.flatnonzero(doubt & ~map_wrong)
    if np.isfinite(trivial) and len(unturned):
        pairs = np.column_stack([samples[unturned], images[unturned]])
        map_wrong[unturned] = ~np.isfinite(pair_distances(graph, pairs, trivial))
    doubt = np.flatnonzero(doubt & map_wrong)
    if len(doubt) == 0:
        return keep
    good = np.flatnonzero(keep)
    horizon = reach + 2.0 * agree
    source = distances_to(graph, samples[doubt], samples[good], reach)
    # two samples may share an anchor: the distances to each distinct one, then spread
    targets, spread = np.unique(anchors[good], return_inverse=True)
    ends = np.concatenate([anchors[doubt], images[doubt]])
    image = np.minimum(distances_to(graph, ends, targets, horizon), horizon)[:, spread]
    for row, s in enumerate(doubt):
        near = np.flatnonzero(np.isfinite(source[row]))
        near = near[np.argsort(source[row, near], kind="stable")[:k]]
        if len(near) == 0:
            continue
        wanted = source[row, near]
        from_anchor = np.mean((image[row, near] - wanted) ** 2)
        from_map = np.mean((image[len(doubt) + row, near] - wanted) ** 2)
        keep[s] = from_anchor < from_map
    return keep


@nb.njit(cache=True, nogil=True)
def _descend(lo, hi, start, ptr, cols, targets, embedding, indptr, indices, tolerance2, out):  # pragma: no cover
    """Steepest descent of the queries ``lo:hi`` over the graph's neighbours, from ``start[q]``, to a
    local minimum of ``sum_k (embedding[y, cols[k]] - targets[k])^2`` over k in
    ``ptr[q]:ptr[q + 1]``; a query with no terms, or whose start costs at most
    ``tolerance2`` per term and at most ``tolerance2`` in the term of its smallest target
    (the nearest anchor, where the targets are distances), keeps its start. The images go
    to ``out``, which holds the starts."""
    for q in range(lo, hi):
        a0 = ptr[q]
        a1 = ptr[q + 1]
        if a1 == a0:
            continue
        y = start[q]
        best = 0.0
        nearest = a0
        for k in range(a0, a1):
            r = embedding[y, cols[k]] - targets[k]
            best += r * r
            if targets[k] < targets[nearest]:
                nearest = k
        r = embedding[y, cols[nearest]] - targets[nearest]
        if best <= tolerance2 * (a1 - a0) and r * r <= tolerance2:
            continue
        for _ in range(MAX_STEPS):
            move = -1
            for e in range(indptr[y], indptr[y + 1]):
                z = indices[e]
                c = 0.0
                for k in range(a0, a1):
                    r = embedding[z, cols[k]] - targets[k]
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


def _descent(
    start: np.ndarray,
    ptr: np.ndarray,
    cols: np.ndarray,
    targets: np.ndarray,
    embedding: np.ndarray,
    indptr: np.ndarray,
    indices: np.ndarray,
    tolerance2: float,
) -> np.ndarray:
    """:func:`_descend` of every query, over threads; returns the images."""
    out = start.copy()
    map_ranges(_descend, len(start), start, ptr, cols, targets, embedding, indptr, indices, tolerance2, out)
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
        Geodesic graph of the working shape (:func:`intrinsym.geodesics.geodesics.surface_graph`);
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
        with fewer within ``reach`` (an extremity such as a paw) uses those it has. The
        descent starts from the current image and only moves downhill, so anchors that
        all lie on one side correct the image along the limb without turning it about
        the limb into the mirrored basin.
    tolerance : float
        A query whose current image keeps the distances to this root mean square residual,
        and the distance to its nearest sample's anchor to this residual, keeps it (graph
        length units).
    reach : float
        Samples farther than this from a query are not its anchors; distances from an
        anchor are computed up to ``reach`` plus twice the tolerance further, and count
        as that far beyond it (graph length units).

    Returns
    -------
    (n,) int64
        Refined images; ``start`` where no sample is within ``reach`` or the current
        image is within ``tolerance`` (in the mean and at the nearest anchor).
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
    near = ball_pairs(arrays, np.asarray(samples, dtype=np.int64), reach)
    ptr, sample, distance = _nearest_sources(*near, n, queries, k)
    horizon = reach + 2.0 * tolerance
    rows, cols, dists = ball_pairs(arrays, np.asarray(anchors, dtype=np.int64), horizon)
    image_distance = np.full((n, len(anchors)), 2.0 * horizon, dtype=np.float32)
    image_distance[cols, rows] = dists
    indptr, indices, _ = arrays
    return _descent(start, ptr, sample, distance, image_distance, indptr, indices, tolerance**2)


def spectral_descent(graph: sp.spmatrix, points: np.ndarray, start: np.ndarray, evecs: np.ndarray) -> np.ndarray:
    """A vertex map projected once onto the eigenfunctions, each image moved from where it
    is to the vertex nearest its projection.

    The functional map ``C`` is the least-squares fit of ``evecs[start] ~ evecs[points] C``
    over all the pairs (a low-pass filter of the point map: the step of ZoomOut that turns
    a point map into a functional map); each point's image then moves by steepest descent
    over the graph's neighbours, from ``start``, to a vertex y where ``|evecs[y] -
    evecs[x] C|`` is locally least. Unlike ZoomOut's nearest-neighbour search over the
    whole shape, the descent keeps every image in the basin the map chose (a thin part
    such as an arm has a second, mirrored one), and costs a few neighbourhoods per point.

    Parameters
    ----------
    graph : (N, N) sparse, symmetric
        Geodesic graph of the shape (:func:`intrinsym.geodesics.geodesics.surface_graph`); its
        neighbours are the descent's steps.
    points : (n,) int
        Vertices whose images are moved, n >= K.
    start : (n,) int
        Their images.
    evecs : (N, K) float array
        Eigenfunctions of the shape, constant first.

    Returns
    -------
    (n,) int64
        The moved images.
    """
    points = np.asarray(points, dtype=np.int64)
    start = np.asarray(start, dtype=np.int64)
    if len(points) != len(start):
        raise ValueError(f"points and start differ in length: {len(points)} and {len(start)}")
    embedding = np.ascontiguousarray(evecs, dtype=np.float64)
    if len(points) < embedding.shape[1]:
        raise ValueError(f"{len(points)} points cannot fit a functional map of {embedding.shape[1]} eigenfunctions")
    basis = embedding[points]
    # the normal equations: the eigenfunctions are nearly orthogonal at any dense vertex
    # set, and this is 7x faster than an SVD-based lstsq (the same C to 1e-14 on michael1)
    C = np.linalg.solve(basis.T @ basis, basis.T @ embedding[start])
    indptr, indices, _ = csr_arrays(graph)
    n, k = basis.shape
    # every point's cost runs over all k columns of the embedding
    ptr = np.arange(0, (n + 1) * k, k, dtype=np.int64)
    cols = np.tile(np.arange(k, dtype=np.int64), n)
    return _descent(start, ptr, cols, (basis @ C).ravel(), embedding, indptr, indices, -1.0)
